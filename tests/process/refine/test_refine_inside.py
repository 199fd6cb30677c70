"""Structure segments inside objects: a chair's back the network called wall is the chair's."""

from __future__ import annotations

import dataclasses

import numpy as np
import numpy.typing as npt
from helpers_refine import grid_patch, labelled

from capture.recording import Label
from process.refine import RefineConfig, refine
from process.refine.inside import structure_inside_objects
from process.refine.job import refinement_metrics

CHAIR, WALL, FLOOR = Label.CHAIR, Label.WALL, Label.FLOOR
STEP = 0.01

Points = npt.NDArray[np.float32]


def _chair(at: tuple[float, float], step: float = STEP) -> tuple[Points, Points]:
    """A chair's seat (45 x 45 cm at 45 cm) and its back on the seat's edge (46-90 cm)."""
    seat = grid_patch((0.0, 0.45), (0.0, 0.45), z=0.45, step=step)
    plate = grid_patch((0.45 + step, 0.9), (0.0, 0.45), step=step)
    back = np.column_stack([np.zeros(len(plate)), plate[:, 1], plate[:, 0]])
    shift = np.array([at[0], at[1], 0.0], np.float32)
    return seat + shift, (back + shift).astype(np.float32)


def _upright(x: tuple[float, float], z: tuple[float, float], y: float, step: float) -> Points:
    """A vertical sheet in the plane y = `y`."""
    sheet = grid_patch(x, z, step=step)
    return np.column_stack([sheet[:, 0], np.full(len(sheet), y), sheet[:, 1]]).astype(np.float32)


def test_a_wall_cluster_among_object_points_is_opened_a_wall_piece_beside_a_wall_is_not() -> None:
    seat, back = _chair((1.0, 1.0))
    wall = _upright((0.0, 3.0), (0.0, 2.5), 0.0, 0.02)  # a wall plane's points: cluster 0
    piece = _upright((2.0, 2.4), (0.5, 1.0), 0.03, 0.01)  # 3 cm before it, off its plane
    alone = _upright((0.0, 0.3), (0.5, 0.8), 2.5, 0.01)  # nothing near it
    points = np.concatenate([seat, back, wall, piece, alone])
    parts = [(seat, CHAIR, 1), (back, WALL, 2), (wall, WALL, 0), (piece, WALL, 3), (alone, WALL, 4)]
    labels = np.concatenate([np.full(len(p), lab, np.uint8) for p, lab, _ in parts])
    clusters = np.concatenate([np.full(len(p), c, np.int32) for p, _, c in parts])
    opened = structure_inside_objects(points, labels, clusters, share=0.6, link=3.0)
    back_rows = np.arange(len(seat), len(seat) + len(back))
    assert np.array_equal(opened, back_rows)
    # the back's neighbourhood is all seat: any share up to 1 opens it, none past it
    assert len(structure_inside_objects(points, labels, clusters, share=1.0, link=3.0)) == len(back)
    # out of reach of the seat (a link shorter than the 1 cm gap) the back has no neighbours
    assert len(structure_inside_objects(points, labels, clusters, share=0.6, link=0.5)) == 0
    # a ceiling cluster amid object points stays: the ceiling over a tall object
    ceiling = labels.copy()
    ceiling[back_rows] = Label.CEILING
    assert len(structure_inside_objects(points, ceiling, clusters, share=0.6, link=3.0)) == 0


def _room_with_chair() -> tuple[Points, Points, Points, Points]:
    """The floor and a wall at 2 cm spacing, a chair with legs 1 m from the wall whose back is
    bent 6 cm (no plane): (floor, wall, seat and legs, back)."""
    floor = grid_patch((0.0, 3.0), (0.0, 3.0), step=0.02)
    wall = _upright((0.0, 3.0), (0.0, 2.5), 0.0, 0.02)
    seat, back = _chair((1.2, 1.0), step=0.02)
    across = (back[:, 1] - 1.225) / 0.225
    back[:, 0] -= 0.06 * (1.0 - across**2)
    legs = np.concatenate(
        [
            np.column_stack([np.full(22, x), np.full(22, y), np.arange(0.02, 0.45, 0.02)])
            for x in (1.22, 1.63)
            for y in (1.02, 1.43)
        ]
    ).astype(np.float32)
    return floor, wall, np.concatenate([seat, legs]), back


def test_a_chairs_back_called_wall_in_the_middle_of_a_room_is_regrown_as_chair() -> None:
    """The chair's back the network calls wall: a cluster of 500 points DBSCAN keeps as wall;
    opened, regrowth gives it to the chair."""
    floor, wall, seat, back = _room_with_chair()
    points = np.concatenate([floor, wall, seat, back])
    sizes = [len(floor), len(wall), len(seat), len(back)]
    labels = np.repeat(np.array([FLOOR, WALL, CHAIR, WALL], np.uint8), sizes)
    cloud = labelled(points + np.random.default_rng(0).normal(0, 0.002, points.shape), labels)
    up = np.array([0.0, 0.0, 1.0])
    back_rows = slice(len(points) - len(back), None)
    result = refine(cloud, RefineConfig(), up=up)
    assert not result.planes.structural[back_rows].any()  # off every plane
    assert (result.labels_ii[back_rows] == WALL).all()  # DBSCAN keeps it: a wall cluster
    assert (result.labels_iii[back_rows] == CHAIR).mean() > 0.99
    opened = refinement_metrics(result, gt_cloud=None)["points"]["structure_inside_objects"]
    assert opened == len(back) == len(result.opened)
    assert (result.labels_iii[: len(floor)] == FLOOR).mean() > 0.99
    off = refine(cloud, dataclasses.replace(RefineConfig(), inside_objects_share=0.0), up=up)
    assert (off.labels_iii[back_rows] == WALL).all()


def test_wall_points_dbscan_dropped_are_opened_as_segments_amid_objects_only() -> None:
    """Unlabelled after DBSCAN but called wall by the network: the back's top rows, amid the
    chair, are opened; a strip as small just before a wall plane is not; nor without `network`."""
    seat, back = _chair((1.0, 1.0))
    wall = _upright((0.0, 3.0), (0.0, 2.5), 0.0, 0.02)
    strip = _upright((2.0, 2.1), (0.5, 0.52), 0.03, 0.01)  # 3 cm before the wall, 33 points
    points = np.concatenate([seat, back, wall, strip])
    top = len(seat) + np.flatnonzero(back[:, 2] > 0.87)  # the back's top rows, 138 points
    n = len(points)
    labels = np.repeat(
        np.array([CHAIR, CHAIR, WALL, 0], np.uint8), [len(seat), len(back), len(wall), len(strip)]
    )
    clusters = np.repeat(
        np.array([1, 1, 0, 0], np.int32), [len(seat), len(back), len(wall), len(strip)]
    )
    labels[top], clusters[top] = 0, 0  # dropped by DBSCAN
    for said in (WALL, FLOOR):  # either structure label the network may give them
        network = labels.copy()
        network[top] = said
        network[n - len(strip) :] = said
        opened = structure_inside_objects(
            points, labels, clusters, share=0.6, link=3.0, network=network
        )
        assert np.array_equal(opened, top)
    assert len(structure_inside_objects(points, labels, clusters, share=0.6, link=3.0)) == 0


def test_wall_speckle_on_a_chair_that_dbscan_drops_is_regrown_as_chair() -> None:
    """Twenty points of the chair's back, 10 cm apart, called wall: DBSCAN drops them as noise,
    regrowth would keep out of them (the network's structure) but for this step."""
    floor, wall, seat, back = _room_with_chair()
    points = np.concatenate([floor, wall, seat, back])
    row = np.round((back[:, 1:] - back[:, 1:].min(axis=0)) / 0.02).astype(int)
    speckle = len(points) - len(back) + np.flatnonzero((row % 5 == 2).all(axis=1))
    sizes = [len(floor), len(wall), len(seat), len(back)]
    labels = np.repeat(np.array([FLOOR, WALL, CHAIR, CHAIR], np.uint8), sizes)
    labels[speckle] = WALL
    cloud = labelled(points + np.random.default_rng(0).normal(0, 0.002, points.shape), labels)
    result = refine(cloud, RefineConfig(), up=np.array([0.0, 0.0, 1.0]))
    assert len(speckle) == 20
    assert (result.labels_ii[speckle] == 0).all()  # DBSCAN's noise
    assert (result.labels_iii[speckle] == CHAIR).all()
    assert np.array_equal(result.opened, speckle)
