"""The network's "floor" just over the floor plane's band: a chair's feet, regrown as chair."""

from __future__ import annotations

import dataclasses

import numpy as np
from helpers_refine import grid_patch, labelled

from capture.recording import Label
from process.refine import RefineConfig, refine
from process.refine.job import refinement_metrics
from process.refine.walls import floor_said_low

UP = np.array([0.0, 0.0, 1.0])


def _scene() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A 3 x 3 m floor at 2 cm, a chair (seat at 45 cm, four legs down to the floor) whose legs'
    lowest 4-8 cm the network calls floor, and a floor-called mat 4 cm up, 1.5 m from the chair.
    Returns (points, labels, the feet's rows, the mat's rows)."""
    floor = grid_patch((0.0, 3.0), (0.0, 3.0), step=0.02)
    seat = grid_patch((1.0, 1.45), (1.0, 1.45), z=0.45, step=0.02)
    legs = np.array(
        [(x, y, z) for x in (1.0, 1.44) for y in (1.0, 1.44) for z in np.arange(0.04, 0.45, 0.02)],
        np.float32,
    )
    mat = grid_patch((2.4, 2.7), (2.4, 2.7), z=0.04, step=0.02)
    points = np.concatenate([floor, seat, legs, mat])
    labels = np.repeat(
        np.array([Label.FLOOR, Label.CHAIR, Label.CHAIR, Label.FLOOR], np.uint8),
        [len(floor), len(seat), len(legs), len(mat)],
    )
    start = len(floor) + len(seat)
    feet = start + np.flatnonzero(legs[:, 2] < 0.09)  # 4, 6 and 8 cm: 12 points
    labels[feet] = Label.FLOOR
    noisy = points + np.random.default_rng(0).normal(0.0, 0.002, points.shape)
    return noisy.astype(np.float32), labels, feet, np.arange(len(points) - len(mat), len(points))


def test_floor_said_low_is_the_band_over_the_floor_plane_up_to_floor_label_max() -> None:
    points, labels, feet, mat = _scene()
    result = refine(labelled(points, labels), RefineConfig(), up=UP)
    off = ~result.planes.structural
    low = np.zeros(len(points), bool)
    low[off] = floor_said_low(points[off], result.planes.planes, UP, labels[off], RefineConfig())
    assert np.array_equal(np.flatnonzero(low), np.sort(np.concatenate([feet, mat])))
    higher = dataclasses.replace(RefineConfig(), plane_distance_m=0.05)
    assert not floor_said_low(points, result.planes.planes, UP, labels, higher)[mat].any()
    assert not floor_said_low(points, result.planes.planes, None, labels, RefineConfig()).any()


def test_a_chairs_feet_called_floor_are_regrown_as_chair_a_mat_stays_floor() -> None:
    points, labels, feet, mat = _scene()
    cloud = labelled(points, labels)
    result = refine(cloud, RefineConfig(), up=UP)
    assert not result.planes.structural[feet].any()  # over the floor plane's band
    assert (result.labels_iii[feet] == Label.CHAIR).all()
    assert np.array_equal(result.floor_band, feet)
    assert refinement_metrics(result, gt_cloud=None)["points"]["floor_band_regrown"] == len(feet)
    assert (result.labels_iii[mat] == result.labels_ii[mat]).all()  # no object reaches it
    assert (result.labels_iii[mat] != Label.CHAIR).all()
    off = refine(cloud, dataclasses.replace(RefineConfig(), floor_band_regrows=False), up=UP)
    assert not (off.labels_iii[feet] == Label.CHAIR).any()
    assert len(off.floor_band) == 0
