"""A patch of floor the network called an object is floor; objects standing on it stay."""

from __future__ import annotations

import dataclasses

import numpy as np
import numpy.typing as npt
from helpers_refine import grid_patch, labelled

from capture.recording import Label
from process.refine import RefineConfig, refine
from process.refine.flat import flat_on_floor
from process.refine.job import refinement_metrics

TABLE, CHAIR, CLUTTER, FLOOR = Label.TABLE, Label.CHAIR, Label.CLUTTER, Label.FLOOR
UP = np.array([0.0, 0.0, 1.0])


def _box(x: float, y: float, size: float, height: float) -> npt.NDArray[np.float32]:
    """The four sides and the top of a box standing on the floor, at 1 cm spacing."""
    face = grid_patch((0.0, size), (0.0, height), step=0.01)
    front, side = face[:, [0, 2, 1]], face[:, [2, 0, 1]]
    top = grid_patch((0.0, size), (0.0, size), z=height, step=0.01)
    dy, dx = np.array([0.0, size, 0.0], np.float32), np.array([size, 0.0, 0.0], np.float32)
    sides = [front, front + dy, side, side + dx, top]
    return (np.concatenate(sides) + np.array([x, y, 0.0], np.float32)).astype(np.float32)


def test_an_object_flat_in_the_floor_band_becomes_floor_what_stands_on_it_stays() -> None:
    """On a floor plane at z = 0 (its normal pointing down, as RANSAC may give it): a 50 x 45 cm
    patch 5 mm up called table (cluster 1) is floor; a 40 cm box whose foot lies in the band
    (2) and a 6 cm flat box, half its points in the band (3), stay."""
    patch = grid_patch((0.0, 0.5), (0.0, 0.45), z=0.005, step=0.01)
    tall, low = _box(1.0, 0.0, 0.4, 0.4), _box(2.0, 0.0, 0.3, 0.06)
    points = np.concatenate([patch, tall, low]).astype(np.float32)
    labels = np.repeat(
        np.array([TABLE, CHAIR, CLUTTER], np.uint8), [len(patch), len(tall), len(low)]
    )
    clusters = np.repeat(np.array([1, 2, 3], np.int32), [len(patch), len(tall), len(low)])
    floor = np.array([0.0, 0.0, -1.0, 0.0])
    out, ids, changed = flat_on_floor(points, labels, clusters, floor, UP)
    on_patch = np.arange(len(patch))
    assert (out[on_patch] == FLOOR).all() and (ids[on_patch] == 0).all()
    assert np.array_equal(changed, on_patch)
    assert (out[len(patch) :] == labels[len(patch) :]).all()
    assert (labels[on_patch] == TABLE).all()  # the input is not changed in place
    assert len(flat_on_floor(points, labels, clusters, None, UP)[2]) == 0  # no floor: no rule
    raised = floor - np.array([0.0, 0.0, 0.0, 0.05])  # the floor 5 cm lower: nothing flat on it
    assert len(flat_on_floor(points, labels, clusters, raised, UP)[2]) == 0


def test_the_refinement_gives_a_floor_patch_called_table_back_to_the_floor() -> None:
    """The whole refinement on a 4 x 4 m floor the network labels floor but for a 50 x 50 cm
    patch it calls table, beside a desk on legs: the plane step keeps the patch for the objects
    (a wide object-labelled region), DBSCAN keeps it a table; only the flat rule makes it floor
    (counted in metrics.json, shown with the votes). Without it (as in `paper()`) it stays."""
    rng = np.random.default_rng(0)
    floor = grid_patch((-2.0, 2.0), (-2.0, 2.0), step=0.02)
    patch = (np.abs(floor[:, 0] - 1.0) < 0.25) & (np.abs(floor[:, 1] - 1.0) < 0.25)
    desk = grid_patch((-1.5, -0.3), (-1.5, -0.7), z=0.73, step=0.01)
    legs = [
        grid_patch((x, x + 0.04), (0.0, 0.72), step=0.01)[:, [0, 2, 1]] + [0.0, y, 0.0]
        for x in (-1.48, -0.36)
        for y in (-1.48, -0.76)
    ]
    points = np.concatenate([floor, desk, *legs])
    n_desk = len(points) - len(floor)
    labels = np.concatenate([np.where(patch, TABLE, FLOOR), np.full(n_desk, TABLE)])
    cloud = labelled(points + rng.normal(0.0, 0.002, points.shape).astype(np.float32), labels)
    on_patch = np.flatnonzero(patch)
    result = refine(cloud, RefineConfig(), up=UP)
    kept = on_patch[result.labels_ii[on_patch] == TABLE]  # DBSCAN keeps it a table ...
    assert len(kept) >= 0.8 * len(on_patch)  # all but its rim, which the plane took
    assert (result.labels_iii[on_patch] == FLOOR).all()  # ... the flat rule makes it floor
    assert np.isin(kept, result.flat).all()
    desk_points = np.arange(len(floor), len(points))
    assert (result.labels_iii[desk_points] == TABLE).mean() > 0.95
    points_section = refinement_metrics(result, gt_cloud=None)["points"]
    assert points_section["flat_on_floor"] == len(result.flat)
    shown = {tuple(p) for p in result.seam_cloud().points.tolist()}  # the .rrd's votes entity
    assert {tuple(p) for p in cloud.points[kept].tolist()} <= shown
    off = refine(cloud, dataclasses.replace(RefineConfig(), flat_floor=False), up=UP)
    assert (off.labels_iii[kept] == TABLE).all() and len(off.flat) == 0
    assert not RefineConfig.paper().flat_floor
