"""Structure told by the network's labels: gravity among plane normals, floors seen from above,
flat objects on walls, and the cap on eps for sparse classes."""

from __future__ import annotations

import numpy as np
import pytest
from helpers_refine import grid_patch

from capture.recording import Label
from process.refine import RefineConfig
from process.refine.cells import attached_clusters, sparse_inside_others
from process.refine.dbscan import estimate_parameters
from process.refine.plane_grid import over_footprint, wide_object_regions
from process.refine.planes import segment_planes

CFG = RefineConfig(plane_min_points=2000, plane_max_remaining=100)


def _room() -> tuple[np.ndarray, np.ndarray]:
    """A 4 x 3 m floor at z = 0 labelled floor, two 2.5 m walls labelled wall, a desk top."""
    floor = grid_patch((0.0, 4.0), (0.0, 3.0), step=0.04)
    wall_x = grid_patch((0.0, 4.0), (0.0, 2.5), step=0.04)[:, [0, 2, 1]]  # the plane y = 0
    wall_y = grid_patch((0.0, 3.0), (0.0, 2.5), step=0.04)[:, [2, 0, 1]]  # the plane x = 0
    desk = grid_patch((1.0, 2.2), (1.0, 1.8), z=0.75, step=0.02)
    points = np.concatenate([floor, wall_x, wall_y, desk])
    labels = np.concatenate(
        [
            np.full(len(floor), Label.FLOOR),
            np.full(len(wall_x) + len(wall_y), Label.WALL),
            np.full(len(desk), Label.TABLE),
        ]
    ).astype(np.uint8)
    return points, labels


def _tilted(degrees: float, towards: np.ndarray) -> np.ndarray:
    angle = float(np.radians(degrees))
    tilted: np.ndarray = np.array([0.0, 0.0, np.cos(angle)]) + np.sin(angle) * towards
    return tilted


def test_gravity_52_degrees_off_is_found_from_the_labelled_planes() -> None:
    """TUM fr1_rpy: the first camera's up lies 48 deg from gravity, 36 from a wall's normal."""
    points, labels = _room()
    hint = _tilted(52.0, np.array([0.0, 1.0, 0.0]))  # 38 deg from the wall y = 0's normal
    seg = segment_planes(points, CFG, up=hint, labels=labels)
    assert seg.up_source == "labelled planes"
    assert seg.up is not None and seg.up @ [0.0, 0.0, 1.0] == pytest.approx(1.0, abs=1e-3)
    floor = seg.labels[:7500]
    assert (floor == Label.FLOOR).mean() > 0.99
    assert (seg.labels[points[:, 2] == np.float32(0.75)] == 0).all()  # the desk stays an object
    blind = segment_planes(points, CFG, up=hint, labels=None)  # no labels: snap to the nearest
    assert blind.up_source == "argument snapped to plane"
    assert blind.up is not None and abs(blind.up[2]) < 0.1  # ... which is the wall: wrong


def test_without_a_hint_the_labelled_floor_outvotes_shelves_lining_one_wall() -> None:
    """A room whose furniture stands along one wall (two tall shelves, 2.2 m): the objects lie
    at one end of the room's depth and in the middle of its height. Where the network labels
    structure, the floor-labelled largest plane is level; without those labels the objects'
    lopsidedness turns the room on its side (generator recordings refined from a map file)."""
    points, labels = _room()
    shelf = grid_patch((0.5, 1.7), (0.0, 2.2), step=0.03)[:, [0, 2, 1]]  # upright, 1.2 m wide
    shelves = np.concatenate([shelf + np.array([x, 0.3, 0.0], np.float32) for x in (0.0, 2.0)])
    points = np.concatenate([points, shelves]).astype(np.float32)
    labels = np.r_[labels, np.full(len(shelves), Label.CLUTTER)].astype(np.uint8)
    seg = segment_planes(points, CFG, up=None, labels=labels)
    assert seg.up_source == "labelled planes"
    assert seg.up is not None and seg.up @ [0.0, 0.0, 1.0] == pytest.approx(1.0, abs=1e-3)
    assert (seg.labels[:7500] == Label.FLOOR).mean() > 0.99
    objects_only = np.where(labels >= Label.TABLE, labels, 0).astype(np.uint8)
    blind = segment_planes(points, CFG, up=None, labels=objects_only)
    assert blind.up_source == "plane with the objects at one end"
    assert blind.up is not None and abs(blind.up[1]) > 0.99  # the wall's normal: on its side
    flipped = segment_planes(points * np.float32(-1.0), CFG, up=None, labels=labels)
    assert flipped.up is not None and flipped.up @ [0.0, 0.0, -1.0] == pytest.approx(1.0, abs=1e-3)
    # turned upside down with its floor called ceiling: a ceiling alone says up too (away
    # from the rest of the room)
    hung = np.where(labels == Label.FLOOR, Label.CEILING, labels).astype(np.uint8)
    above = segment_planes(points * np.float32(-1.0), CFG, up=None, labels=hung)
    assert above.up_source == "labelled planes"
    assert above.up is not None and above.up @ [0.0, 0.0, 1.0] == pytest.approx(1.0, abs=1e-3)


def test_a_floor_seen_from_above_with_no_wall_is_floor_when_the_network_says_so() -> None:
    floor = grid_patch((0.0, 3.0), (0.0, 2.0), step=0.03)
    chair = grid_patch((1.0, 1.45), (1.0, 1.45), z=0.45, step=0.02)
    points = np.concatenate([floor, chair])
    labels = np.r_[np.full(len(floor), Label.FLOOR), np.full(len(chair), Label.CHAIR)]
    up = np.array([0.0, 0.0, 1.0])
    seg = segment_planes(points, RefineConfig(), up=up, labels=labels.astype(np.uint8))
    assert (seg.labels[: len(floor)] == Label.FLOOR).all()
    assert (seg.labels[len(floor) :] == 0).all()
    unlabelled = segment_planes(points, RefineConfig(), up=up, labels=None)
    assert (unlabelled.labels == 0).all()  # nothing rises a room's height: could be a table


def test_a_flat_screen_on_a_wall_stays_an_object_and_bleed_goes_with_the_wall() -> None:
    wall = grid_patch((0.0, 3.0), (0.0, 2.5), step=0.02)  # in its own plane's (u, v)
    uv = wall[:, :2]
    labels = np.zeros(len(wall), np.uint8)
    screen = (np.abs(uv[:, 0] - 1.0) < 0.3) & (np.abs(uv[:, 1] - 1.5) < 0.2)  # 60 x 40 cm
    bleed = (uv[:, 1] < 0.05) & (uv[:, 0] < 1.5)  # 5 cm band along a sofa's foot
    labels[screen] = Label.TV_MONITOR
    labels[bleed] = Label.SOFA
    labels[screen & (np.arange(len(wall)) % 3 == 0)] = 0  # the network missed a third
    kept = wide_object_regions(uv, labels, width_m=0.25)
    assert kept[screen].mean() > 0.9  # labelled and missed points alike
    assert not kept[bleed].any()
    outside = kept & ~screen  # only the screen's border cells reach past it: < one cell
    gap = np.maximum(np.abs(uv[outside] - (1.0, 1.5)) - (0.3, 0.2), 0.0).max(axis=1)
    assert (gap < 0.25 / 3).all()


def test_eps_stops_at_the_cap_for_a_class_of_scattered_specks() -> None:
    rng = np.random.default_rng(0)
    centres = rng.uniform(0.0, 4.0, (12, 3))
    specks = (centres[:, None, :] + rng.normal(0.0, 0.01, (12, 8, 3))).reshape(-1, 3)
    _, curves, choice = estimate_parameters(specks, k_max=30, rule="plateau", min_size=30)
    assert choice.eps_m > 0.5  # uncapped: the 30th neighbour is another speck metres away
    _, curves, choice = estimate_parameters(
        specks, k_max=30, rule="plateau", min_size=30, max_eps_m=0.15
    )
    assert choice.eps_m <= 0.15 and curves.eps_m.max() <= 0.15
    assert "eps_K beyond is over 0.15 m" in choice.note


def test_a_small_cluster_near_a_big_one_of_its_class_is_kept_a_far_one_is_not() -> None:
    seat = grid_patch((0.0, 0.45), (0.0, 0.45), z=0.45, step=0.03)
    leg = np.array([[0.02, 0.02, z] for z in np.arange(0.32, 0.40, 0.03)])  # 5 cm below it
    far = leg + np.array([2.0, 0.0, 0.0])
    cells = np.concatenate([seat, leg, far]).astype(np.float32)
    cluster_of = np.r_[np.zeros(len(seat)), np.ones(len(leg)), np.full(len(far), 2)]
    big = np.array([True, False, False])
    kept = attached_clusters(cells, cluster_of.astype(np.int64), big, 0.15)
    assert kept.tolist() == [False, True, False]


def test_a_sparse_cluster_inside_another_class_object_gives_way_one_on_its_own_stays() -> None:
    table = grid_patch((0.0, 1.2), (0.0, 0.6), z=0.75)
    edge = grid_patch((1.0, 1.2), (0.0, 0.2), z=0.75)  # the table's corner, called "chair"
    alone = grid_patch((3.0, 3.4), (0.0, 0.4), z=0.45)  # a chair seen rarely, on its own
    points = np.concatenate([table, edge, alone]).astype(np.float32)
    labels = np.r_[np.full(len(table), 4), np.full(len(edge) + len(alone), 5)].astype(np.uint8)
    clusters = np.r_[np.full(len(table), 1), np.full(len(edge), 2), np.full(len(alone), 3)]
    sparse = np.array([2, 3])  # no point dense enough at the paper's MinPts
    drop = sparse_inside_others(points, labels, clusters.astype(np.int32), sparse)
    assert drop.tolist() == [2]


def test_a_sparse_cluster_gives_way_only_to_a_cluster_at_least_its_size() -> None:
    """A chair's seat (sparse) inside the box of a blob of plant labels spread over the chair
    (dense at its class's wide eps, fewer points): the seat stays; a larger blob takes it."""
    seat = grid_patch((0.0, 0.45), (0.0, 0.45), z=0.45, step=0.05)  # 81 points
    blob = np.concatenate(  # 72 points in two layers, 5 cm below and above it
        [grid_patch((-0.05, 0.5), (-0.05, 0.5), z=z, step=0.1) for z in (0.4, 0.5)]
    )
    points = np.concatenate([seat, blob]).astype(np.float32)
    labels = np.r_[np.full(len(seat), 5), np.full(len(blob), 7)].astype(np.uint8)
    clusters = np.r_[np.full(len(seat), 1), np.full(len(blob), 2)].astype(np.int32)
    assert sparse_inside_others(points, labels, clusters, np.array([1])).tolist() == []
    dense_blob = np.concatenate(  # 392 points
        [grid_patch((-0.05, 0.5), (-0.05, 0.5), z=z, step=0.04) for z in (0.4, 0.5)]
    )
    points = np.concatenate([seat, dense_blob]).astype(np.float32)
    labels = np.r_[np.full(len(seat), 5), np.full(len(dense_blob), 7)].astype(np.uint8)
    clusters = np.r_[np.full(len(seat), 1), np.full(len(dense_blob), 2)].astype(np.int32)
    assert sparse_inside_others(points, labels, clusters, np.array([1])).tolist() == [1]


def test_a_sparse_object_standing_on_a_table_stays_though_specks_stretch_the_table() -> None:
    """A box on a table touches the table's box at its foot; three table specks on its top
    would stretch the table's box over it: the box is taken between percentiles 1 and 99."""
    table = grid_patch((0.0, 1.2), (0.0, 0.6), z=0.75)
    box = np.concatenate(
        [grid_patch((0.4, 0.6), (0.2, 0.4), z=z, step=0.03) for z in np.arange(0.76, 0.95, 0.03)]
    )  # 0.2 x 0.2 x 0.2 m, clutter
    specks = np.array([[0.45, 0.25, 0.96], [0.5, 0.3, 0.96], [0.55, 0.35, 0.96]])  # "table"
    points = np.concatenate([table, specks, box]).astype(np.float32)
    n_table = len(table) + len(specks)
    labels = np.r_[np.full(n_table, 4), np.full(len(box), 10)].astype(np.uint8)
    clusters = np.r_[np.full(n_table, 1), np.full(len(box), 2)].astype(np.int32)
    assert sparse_inside_others(points, labels, clusters, np.array([2])).tolist() == []


def test_over_footprint_takes_the_cells_of_the_points_and_their_neighbours() -> None:
    """Own points fill the 10 cm cell [0, 0.1)^2; a point in the cell beside it is over the
    footprint, one in the cell at its corner only with diagonals, one two cells away never."""
    own = np.array([[0.01, 0.01], [0.09, 0.09]], np.float32)
    probe = np.array([[0.05, 0.05], [0.15, 0.05], [0.15, 0.15], [0.25, 0.05]], np.float32)
    assert over_footprint(own, probe, 0.1).tolist() == [True, True, False, False]
    assert over_footprint(own, probe, 0.1, diagonal=True).tolist() == [True, True, True, False]
    assert over_footprint(own, probe[:0], 0.1).shape == (0,)


def test_over_footprint_grows_by_as_many_cells_as_asked() -> None:
    """Grown by two cells the footprint takes the point two cells away (and with diagonals the
    one two cells off on both axes), not three; grown by none, its own cell only."""
    own = np.array([[0.01, 0.01], [0.09, 0.09]], np.float32)
    probe = np.array([[0.25, 0.05], [0.25, 0.25], [0.35, 0.05], [0.15, 0.05]], np.float32)
    grown = over_footprint(own, probe, 0.1, diagonal=True, grow=2)
    assert grown.tolist() == [True, True, False, True]
    assert over_footprint(own, probe, 0.1, grow=2).tolist() == [True, False, False, True]
    assert over_footprint(own, probe, 0.1, grow=0).tolist() == [False, False, False, False]
