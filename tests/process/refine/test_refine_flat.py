"""A patch of floor (or wall) the network called an object is floor (wall); objects stay."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from helpers_refine import UP, box_on_floor, counted_shown_and_switched_off, grid_patch, labelled

from capture.recording import Label
from process.refine import RefineConfig, refine
from process.refine.flat import flat_on_floor, flat_on_walls

TABLE, CHAIR, CLUTTER, FLOOR = Label.TABLE, Label.CHAIR, Label.CLUTTER, Label.FLOOR
WALL, MONITOR = Label.WALL, Label.TV_MONITOR


def test_an_object_flat_in_the_floor_band_becomes_floor_what_stands_on_it_stays() -> None:
    """On a floor plane at z = 0 (its normal pointing down, as RANSAC may give it): a 50 x 45 cm
    patch 5 mm up called table (cluster 1) is floor; a 40 cm box whose foot lies in the band
    (2) and a 6 cm flat box, half its points in the band (3), stay."""
    patch = grid_patch((0.0, 0.5), (0.0, 0.45), z=0.005, step=0.01)
    tall, low = box_on_floor(1.0, 0.0, 0.4, 0.4), box_on_floor(2.0, 0.0, 0.3, 0.06)
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
    counted_shown_and_switched_off(cloud, result, kept, "flat", "flat_on_floor", "flat_floor")


def _on_wall(
    y: tuple[float, float], z: tuple[float, float], x: float, step: float = 0.01
) -> npt.NDArray[np.float32]:
    """An upright patch facing along x, x metres out from the wall x = 0."""
    patch = grid_patch(y, z, step=step)
    return np.column_stack([np.full(len(patch), x), patch[:, 0], patch[:, 1]]).astype(np.float32)


def test_a_standing_class_patch_flat_on_a_wall_apart_and_off_the_floor_becomes_wall() -> None:
    """A wall at x = 0 facing +x (band 2 cm in front), the floor at z = 0. A 20 x 20 cm patch
    called chair in the wall's face (5 mm out), 0.24-0.44 m up and 10 cm from any object
    (cluster 1), is wall; the same patch called monitor (2, what hangs on walls), a chair's frame
    flat on the wall down to the floor (3), a patch touching a chair's back 3 cm before it (4
    and 5: the face of what stands there) and a patch 1.5 cm proud of the wall (7: a screen's
    edge before it) stay. A chair 30 cm out (6) is in no band."""
    bled = _on_wall((0.0, 0.2), (0.24, 0.44), 0.005)
    screen = _on_wall((1.0, 1.4), (1.2, 1.5), 0.01)
    frame = _on_wall((2.0, 2.3), (0.0, 0.3), 0.005)
    face = _on_wall((3.0, 3.2), (0.3, 0.5), 0.01)
    back = _on_wall((3.0, 3.2), (0.3, 0.7), 0.04)
    chair = _on_wall((0.3, 0.6), (0.0, 0.9), 0.3)
    proud = _on_wall((4.0, 4.2), (0.9, 1.1), 0.015)
    parts = [bled, screen, frame, face, back, chair, proud]
    points = np.concatenate(parts).astype(np.float32)
    sizes = [len(p) for p in parts]
    labels = np.repeat(np.array([CHAIR, MONITOR, *[CHAIR] * 5], np.uint8), sizes)
    clusters = np.repeat(np.arange(1, 8, dtype=np.int32), sizes)
    wall = (np.array([1.0, 0.0, 0.0, 0.0]), 0.02)
    floor = np.array([0.0, 0.0, 1.0, 0.0])
    out, ids, changed = flat_on_walls(points, labels, clusters, [wall], floor, UP)
    on_patch = np.arange(len(bled))
    assert np.array_equal(changed, on_patch)
    assert (out[on_patch] == WALL).all() and (ids[on_patch] == 0).all()
    assert (out[len(bled) :] == labels[len(bled) :]).all()
    assert (labels[on_patch] == CHAIR).all()  # the input is not changed in place
    assert len(flat_on_walls(points, labels, clusters, [wall], None, UP)[2]) == 0  # no floor
    assert len(flat_on_walls(points, labels, clusters, [], floor, UP)[2]) == 0  # no wall
    out_of_band = (np.array([1.0, 0.0, 0.0, 0.0]), 0.004)  # a band of 4 mm: the patch is out
    assert len(flat_on_walls(points, labels, clusters, [out_of_band], floor, UP)[2]) == 0
    behind = points - np.array([0.04, 0.0, 0.0], np.float32)  # all 4 cm back: 1 and 7 in the face
    on_proud = np.flatnonzero(clusters == 7)
    changed = flat_on_walls(behind, labels, clusters, [wall], floor, UP)[2]
    assert np.array_equal(changed, np.concatenate([on_patch, on_proud]))


def test_the_refinement_gives_a_wall_patch_called_chair_apart_from_the_chair_back_to_the_wall() -> (
    None
):
    """The whole refinement on a room corner: a 4 x 4 m floor, a wall at x = 0 the network calls
    wall but for a 30 x 30 cm patch 0.25-0.55 m up it calls chair, and a chair (a box, its
    back 10 cm from the patch) standing before the wall. The plane step keeps the patch for the
    objects (a wide object-labelled region), DBSCAN keeps it a chair of its own; only the wall
    rule makes it wall (counted in metrics.json, shown with the votes). The chair stays a chair;
    without the rule (as in `paper()`) the patch stays chair."""
    rng = np.random.default_rng(0)
    floor = grid_patch((0.0, 4.0), (-2.0, 2.0), step=0.02)
    wall = _on_wall((-2.0, 2.0), (0.0, 2.5), 0.0, step=0.02)
    patch = (np.abs(wall[:, 1] - 0.15) < 0.15) & (np.abs(wall[:, 2] - 0.4) < 0.15)
    chair = box_on_floor(0.1, 0.4, 0.45, 0.9)
    points = np.concatenate([floor, wall, chair])
    labels = np.concatenate(
        [np.full(len(floor), FLOOR), np.where(patch, CHAIR, WALL), np.full(len(chair), CHAIR)]
    )
    cloud = labelled(points + rng.normal(0.0, 0.002, points.shape).astype(np.float32), labels)
    on_patch = len(floor) + np.flatnonzero(patch)
    result = refine(cloud, RefineConfig(), up=UP)
    kept = on_patch[result.labels_ii[on_patch] == CHAIR]  # DBSCAN keeps it a chair ...
    assert len(kept) >= 0.8 * len(on_patch)
    assert (result.labels_iii[on_patch] == WALL).all()  # ... the wall rule makes it wall
    assert np.isin(kept, result.flat_walls).all()
    chair_points = np.arange(len(floor) + len(wall), len(points))
    assert (result.labels_iii[chair_points] == CHAIR).mean() > 0.95
    counted_shown_and_switched_off(cloud, result, kept, "flat_walls", "flat_on_walls", "flat_walls")
