"""Orphans: a segment the network saw, unlabelled after phase II, joins the class it touches;
one that touches no object becomes an object of its own."""

from __future__ import annotations

import dataclasses

import numpy as np
import numpy.typing as npt
import pytest
from helpers_refine import grid_patch, labelled

from capture.recording import Label
from process.refine import RefineConfig, refine, steps
from process.refine.job import refinement_metrics
from process.refine.orphans import adopt_orphans, lone_objects

CHAIR, PERSON, TABLE, FLOOR = Label.CHAIR, Label.PERSON, Label.TABLE, Label.FLOOR
STEP = 0.01

Points = npt.NDArray[np.float64]


def _chair(seed: int = 0) -> tuple[Points, npt.NDArray[np.bool_]]:
    """A chair's seat (45 x 45 cm at 45 cm) and its back standing on the seat's edge (x = 0,
    46-90 cm), 1 cm apart; returns the points and the mask of the back."""
    seat = grid_patch((0.0, 0.45), (0.0, 0.45), z=0.45, step=STEP).astype(np.float64)
    plate = grid_patch((0.46, 0.9), (0.0, 0.45), step=STEP).astype(np.float64)
    back = np.column_stack([np.zeros(len(plate)), plate[:, 1], plate[:, 0]])
    points = np.vstack([seat, back])
    points += np.random.default_rng(seed).normal(0.0, 0.002, points.shape)
    return points, np.r_[np.zeros(len(seat), bool), np.ones(len(back), bool)]


def _phase_ii(
    back: npt.NDArray[np.bool_], seat_label: int = CHAIR
) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.int32]]:
    """The seat an object (cluster 1), the back unlabelled: what phase II left."""
    labels = np.where(back, 0, seat_label).astype(np.uint8)
    return labels, np.where(back, 0, 1).astype(np.int32)


def test_a_chairs_back_the_network_called_floor_joins_the_chair() -> None:
    points, back = _chair()
    labels, clusters = _phase_ii(back)
    said = np.where(back, FLOOR, CHAIR).astype(np.uint8)  # the network: floor, 0.5 m up
    out, ids, adopted = adopt_orphans(points, labels, clusters, np.arange(len(points)), said)
    assert (out[back] == CHAIR).all() and (ids[back] == 1).all()
    assert (out[~back] == CHAIR).all()
    assert np.array_equal(adopted, np.flatnonzero(back))
    assert (labels[back] == 0).all()  # the input is not changed in place


def test_a_segment_the_network_left_unlabelled_stays_unlabelled() -> None:
    """Furniture the network has no class for (a cabinet beside a chair) is no chair."""
    points, back = _chair()
    labels, clusters = _phase_ii(back)
    said = np.where(back, 0, CHAIR).astype(np.uint8)
    out, _, adopted = adopt_orphans(points, labels, clusters, np.arange(len(points)), said)
    assert (out[back] == 0).all() and len(adopted) == 0
    # only the rows handed in may join: none of the back's
    said[back] = FLOOR
    rows = np.flatnonzero(~back)
    out, _, adopted = adopt_orphans(points, labels, clusters, rows, said)
    assert (out[back] == 0).all() and len(adopted) == 0


def test_a_back_touching_at_a_corner_joins_only_the_class_the_network_said() -> None:
    """A back (46 x 45 cm) 2 cm over the seat and shifted so only its corner comes within
    reach: 3-9 contacts, all chair. Called chair by the network it joins the chair (rec seed
    66: a chair's back, 7 contacts); called floor, with so few contacts, it stays unlabelled."""
    seat = grid_patch((0.0, 0.45), (0.0, 0.45), z=0.45, step=STEP).astype(np.float64)
    plate = grid_patch((0.47, 0.92), (0.43, 0.88), step=STEP).astype(np.float64)
    back = np.column_stack([np.zeros(len(plate)), plate[:, 1], plate[:, 0]])
    points = np.vstack([seat, back])
    is_back = np.r_[np.zeros(len(seat), bool), np.ones(len(back), bool)]
    labels, clusters = _phase_ii(is_back)
    near = np.linalg.norm(back[:, None, :] - seat[None, :, :], axis=2).min(axis=1)
    assert 3 <= (near < 2.5 * STEP).sum() < 10  # the corner only
    rows = np.arange(len(points))
    said = np.full(len(points), CHAIR, np.uint8)
    said[np.flatnonzero(is_back)[::3]] = FLOOR  # a third of it floor: still most of it chair
    out, ids, adopted = adopt_orphans(points, labels, clusters, rows, said)
    assert (out[is_back] == CHAIR).all() and (ids[is_back] == 1).all()
    assert np.array_equal(adopted, np.flatnonzero(is_back))
    said[is_back] = FLOOR
    out, _, adopted = adopt_orphans(points, labels, clusters, rows, said)
    assert (out[is_back] == 0).all() and len(adopted) == 0


@pytest.mark.parametrize(("y0", "contacts"), [(0.44, 2), (0.45, 1)])
def test_a_back_touching_at_one_or_two_points_joins_the_class_the_network_said(
    y0: float, contacts: int
) -> None:
    """A back whose corner comes within reach of the seat at 1-2 points: too few to be an
    orphan of 3-9 contacts, too many to be a lone object; called chair it joins the chair
    (fresh recordings 68, 69, 86, 88: four such pieces, 106 points, all chair). Its "floor"
    above the floor counts as seen, as for lone objects: 4 in 5 of its labels floor and the
    rest chair, it joins the chair where that floor is known to be misnamed, not otherwise
    (fresh recording 71: a chair's base, 49 floor labels above the floor and 10 chair)."""
    seat = grid_patch((0.0, 0.45), (0.0, 0.45), z=0.45, step=STEP).astype(np.float64)
    plate = grid_patch((0.47, 0.92), (y0, y0 + 0.45), step=STEP).astype(np.float64)
    back = np.column_stack([np.zeros(len(plate)), plate[:, 1], plate[:, 0]])
    points = np.vstack([seat, back])
    is_back = np.r_[np.zeros(len(seat), bool), np.ones(len(back), bool)]
    labels, clusters = _phase_ii(is_back)
    near = np.linalg.norm(back[:, None, :] - seat[None, :, :], axis=2).min(axis=1)
    assert (near < 2.5 * STEP).sum() == contacts
    rows = np.arange(len(points))
    said = np.full(len(points), CHAIR, np.uint8)
    said[np.flatnonzero(is_back)[::3]] = FLOOR
    out, ids, adopted = adopt_orphans(points, labels, clusters, rows, said)
    assert (out[is_back] == CHAIR).all() and (ids[is_back] == 1).all()
    assert np.array_equal(adopted, np.flatnonzero(is_back))
    said[is_back] = FLOOR
    said[np.flatnonzero(is_back)[::5]] = CHAIR
    misnamed = is_back & (said == FLOOR)
    out, _, adopted = adopt_orphans(points, labels, clusters, rows, said)
    assert (out[is_back] == 0).all() and len(adopted) == 0
    out, _, adopted = adopt_orphans(points, labels, clusters, rows, said, misnamed=misnamed)
    assert (out[is_back] == CHAIR).all() and np.array_equal(adopted, np.flatnonzero(is_back))


def test_a_segment_touching_only_a_table_is_not_made_table() -> None:
    """What touches only a desk stands on it: a box on a desk the network called floor."""
    points, back = _chair()
    labels, clusters = _phase_ii(back, seat_label=TABLE)
    said = np.where(back, FLOOR, TABLE).astype(np.uint8)
    out, _, adopted = adopt_orphans(points, labels, clusters, np.arange(len(points)), said)
    assert (out[back] == 0).all() and len(adopted) == 0


def test_a_segment_touching_two_classes_stays_unlabelled() -> None:
    """Half the seat a chair, half a person sitting on it: no class holds 95 % of the contacts."""
    points, back = _chair()
    labels, clusters = _phase_ii(back)
    person = ~back & (points[:, 1] > 0.225)
    labels[person], clusters[person] = PERSON, 2
    said = np.where(back, FLOOR, labels).astype(np.uint8)
    out, _, adopted = adopt_orphans(points, labels, clusters, np.arange(len(points)), said)
    assert (out[back] == 0).all() and len(adopted) == 0


def test_refine_gives_the_back_called_floor_to_the_chair() -> None:
    """Through refine: the plane step takes floor 0.5 m above the floor away; the back, an
    unlabelled strip beyond the seat cluster's reach, is adopted, counted and shown as regrown."""
    points, back = _chair()
    points[:, :2] += 0.5
    floor = grid_patch((-1.0, 2.0), (-1.0, 2.0), step=0.02).astype(np.float64)
    labels = np.r_[np.full(len(floor), FLOOR), np.where(back, FLOOR, CHAIR)]
    cloud = labelled(np.vstack([floor, points]), labels)
    cfg = RefineConfig(plane_min_points=3000, plane_max_remaining=100)
    up = np.array([0.0, 0.0, 1.0])
    at = len(floor)
    out = refine(cloud, cfg, up=up)
    # SOR takes ~6 % of the plates' points: their edges
    assert (out.labels_iii[at:][back] == CHAIR).mean() > 0.9
    assert (out.labels_iii[at:][~back] == CHAIR).mean() > 0.9
    assert refinement_metrics(out, gt_cloud=None)["points"]["orphans_adopted"] > 1500
    assert np.isin(out.orphans, out.regrown).all()
    off = refine(cloud, dataclasses.replace(cfg, orphan_adoption=False), up=up)
    assert (off.labels_iii[at:][back] == CHAIR).mean() < 0.25  # regrowth alone: its foot
    assert not RefineConfig.paper().orphan_adoption


def test_refine_hands_the_plane_steps_misnamed_floor_to_the_orphans(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The floor 0.5 m above the floor that the plane step marks (`not_floor`) reaches the
    orphans' few-contacts test as `misnamed` (fresh recording 71's chair base; the test's own
    geometry regrowth already fills, so the hand-over itself is checked)."""
    seen: list[npt.NDArray[np.bool_] | None] = []

    def spy(*args: object, misnamed: npt.NDArray[np.bool_] | None = None, **kw: object) -> object:
        seen.append(misnamed)
        return adopt_orphans(*args, misnamed=misnamed, **kw)  # type: ignore[arg-type]

    monkeypatch.setattr(steps, "adopt_orphans", spy)
    points, back = _chair()
    points[:, :2] += 0.5
    floor = grid_patch((-1.0, 2.0), (-1.0, 2.0), step=0.02).astype(np.float64)
    cloud = labelled(
        np.vstack([floor, points]), np.r_[np.full(len(floor), FLOOR), np.where(back, FLOOR, CHAIR)]
    )
    out = refine(cloud, RefineConfig(plane_min_points=3000, plane_max_remaining=100),
                 up=np.array([0.0, 0.0, 1.0]))  # fmt: skip
    assert len(seen) == 1 and seen[0] is not None and out.planes.not_floor is not None
    assert np.array_equal(seen[0], out.planes.not_floor)
    assert seen[0][len(floor) :][back].mean() > 0.9  # the back, called floor 0.5 m up


def _leg(at: tuple[float, float], height: float = 0.4) -> Points:
    """A chair's leg: a 2 x 2 cm square post of points 1 cm apart, standing at `at`."""
    z = np.arange(0.0, height, STEP)
    square = [(dx, dy) for dx in (0.0, STEP, 2 * STEP) for dy in (0.0, STEP, 2 * STEP)]
    return np.array([(at[0] + dx, at[1] + dy, h) for h in z for dx, dy in square])


def _seat_and_leg(x: float) -> tuple[Points, npt.NDArray[np.bool_]]:
    """The chair of `_chair` (seat at 0 <= x <= 0.45, 45 cm up) and a leg 44 cm tall at `x`,
    unlabelled after phase II; returns the points and the mask of the leg."""
    points, _ = _chair()
    leg = _leg((x, 0.2), height=0.45)
    return np.vstack([points, leg]), np.r_[np.zeros(len(points), bool), np.ones(len(leg), bool)]


def test_a_segment_touching_no_object_becomes_an_object_of_its_class() -> None:
    """A chair's leg 1 m from every object, 405 points the network called chair, that DBSCAN
    dropped: a cluster of its own, with an id above every id in use."""
    points, leg = _seat_and_leg(1.5)
    labels = np.where(leg, 0, CHAIR).astype(np.uint8)
    clusters = np.where(leg, 0, 7).astype(np.int32)
    said = np.full(len(points), CHAIR, np.uint8)
    said[np.flatnonzero(leg)[:20]] = 0  # the network missed a few: the segment takes them too
    out, ids, made = lone_objects(
        points, labels, clusters, np.arange(len(points)), said, min_points=30
    )
    assert (out[leg] == CHAIR).all() and (ids[leg] == 8).all()
    assert np.array_equal(made, np.flatnonzero(leg))
    assert (out[~leg] == CHAIR).all() and (ids[~leg] == 7).all()
    assert (labels[leg] == 0).all()  # the input is not changed in place
    # split between chair and table, 3 to 2: the class holding most of it takes it all
    said[np.flatnonzero(leg)[::5]] = TABLE
    said[np.flatnonzero(leg)[1::5]] = TABLE
    out, _, made = lone_objects(
        points, labels, clusters, np.arange(len(points)), said, min_points=30
    )
    assert (out[leg] == CHAIR).all() and len(made) == leg.sum()


def test_a_lone_segment_half_called_floor_above_the_floor_becomes_its_object() -> None:
    """A chair's leg the network called chair on 45 % of it and floor, 0-44 cm up, on the rest
    (rec seed 71: a seat 85 chair, 90 floor labels): "floor" above the floor is a class that
    cannot be right there, the network saw something, so the segment is seen and chair. Without
    `misnamed` it is under half seen and stays unlabelled; "floor" on the floor stays unseen."""
    points, leg = _seat_and_leg(1.5)
    labels = np.where(leg, 0, CHAIR).astype(np.uint8)
    clusters = np.where(leg, 0, 7).astype(np.int32)
    rows = np.arange(len(points))
    said = np.full(len(points), CHAIR, np.uint8)
    floor_said = np.flatnonzero(leg)[np.arange(leg.sum()) % 20 < 11]  # 55 %
    said[floor_said] = FLOOR
    assert len(lone_objects(points, labels, clusters, rows, said, min_points=30)[2]) == 0
    misnamed = np.zeros(len(points), bool)
    misnamed[floor_said] = True
    out, ids, made = lone_objects(
        points, labels, clusters, rows, said, min_points=30, misnamed=misnamed
    )
    assert (out[leg] == CHAIR).all() and (ids[leg] == 8).all()
    assert np.array_equal(made, np.flatnonzero(leg))
    # all of it misnamed, no object label at all: no class to give it
    said[leg] = FLOOR
    misnamed[leg] = True
    assert len(lone_objects(points, labels, clusters, rows, said, min_points=30,
                            misnamed=misnamed)[2]) == 0  # fmt: skip


def test_a_segment_that_is_small_mixed_unseen_or_touching_stays_unlabelled() -> None:
    points, leg = _seat_and_leg(1.5)
    labels = np.where(leg, 0, CHAIR).astype(np.uint8)
    clusters = np.where(leg, 0, 1).astype(np.int32)
    rows = np.arange(len(points))
    said = np.full(len(points), CHAIR, np.uint8)
    # fewer points than min_points
    _, _, made = lone_objects(points, labels, clusters, rows, said, min_points=int(leg.sum()) + 1)
    assert len(made) == 0
    # the network gave the leg three classes, none of them most of it
    mixed = said.copy()
    mixed[np.flatnonzero(leg)[::3]] = TABLE
    mixed[np.flatnonzero(leg)[1::3]] = PERSON
    assert len(lone_objects(points, labels, clusters, rows, mixed, min_points=30)[2]) == 0
    # the network saw almost nothing there: furniture it has no class for
    unseen = said.copy()
    unseen[np.flatnonzero(leg)[: int(leg.sum() * 0.6)]] = 0
    assert len(lone_objects(points, labels, clusters, rows, unseen, min_points=30)[2]) == 0
    # under the seat, 1 cm below it, it touches the chair: adoption's case, not this one
    points, leg = _seat_and_leg(0.4)
    assert len(lone_objects(points, labels, clusters, rows, said, min_points=30)[2]) == 0


def test_refine_keeps_a_lone_leg_dbscan_dropped() -> None:
    """Through refine: a chair and, 1 m away, a leg of 270 points the network called chair.
    DBSCAN drops the leg (too thin for the chair's MinPts); it comes back as a chair object,
    counted in metrics.json and shown as regrown; without the rule it stays unlabelled."""
    points, _ = _chair()
    leg = _leg((1.5, 0.2), height=0.3)
    floor = grid_patch((-1.0, 2.5), (-1.0, 1.5), step=0.02).astype(np.float64)
    cloud = labelled(
        np.vstack([floor, points, leg]),
        np.r_[np.full(len(floor), FLOOR), np.full(len(points) + len(leg), CHAIR)],
    )
    cfg = RefineConfig(plane_min_points=3000, plane_max_remaining=100)
    up = np.array([0.0, 0.0, 1.0])
    at = len(floor) + len(points)
    off = refine(cloud, dataclasses.replace(cfg, lone_objects=False), up=up)
    assert (off.labels_iii[at:] == 0).mean() > 0.9  # dropped by phase II, out of reach
    out = refine(cloud, cfg, up=up)
    chair = out.labels_iii[at:] == CHAIR
    assert chair.mean() > 0.9  # its foot is on the floor plane
    assert len(np.unique(out.clusters_iii[at:][chair])) == 1
    assert refinement_metrics(out, gt_cloud=None)["points"]["lone_objects"] == len(out.lone) > 100
    assert np.isin(out.lone, out.regrown).all()
    assert not RefineConfig.paper().lone_objects


UP = np.array([0.0, 0.0, 1.0])


Labels = npt.NDArray[np.uint8]
Scene = tuple[Points, Labels, npt.NDArray[np.int32], Labels, npt.NDArray[np.bool_]]


def _chair_over_base(x: float = 0.0, every: int = 2, z: float = 0.05) -> Scene:
    """The chair of `_chair` (cluster 1) and a base `z` over the floor (a 45 cm square of points
    1.5 cm apart, shifted by `x`; 5 cm: 40 cm under the seat): what phase II left after the
    network called chair every `every`-th point of the base's every `every`-th row (2: a
    quarter of it, 3 cm apart; 3: 11 %) and DBSCAN dropped them. Returns points, labels,
    clusters, the network's labels and the mask of the base."""
    points, _ = _chair()
    base = grid_patch((x, x + 0.45), (0.0, 0.45), z=z, step=0.015).astype(np.float64)
    points = np.vstack([points, base])
    on_base = np.r_[np.zeros(len(points) - len(base), bool), np.ones(len(base), bool)]
    labels = np.where(on_base, 0, CHAIR).astype(np.uint8)
    clusters = np.where(on_base, 0, 1).astype(np.int32)
    said = labels.copy()
    cell = np.round((base[:, :2] - base[:, :2].min(axis=0)) / 0.015).astype(int)
    said[np.flatnonzero(on_base)[np.all(cell % every == 0, axis=1)]] = CHAIR
    return points, labels, clusters, said, on_base


def test_a_base_the_network_saw_in_part_under_its_chair_joins_the_chair() -> None:
    """A chair's base 40 cm under its seat, a quarter of it called chair: too little seen to be an
    object on its own (under half), but under a chair, the class the network gives it, it joins
    that chair (cluster 1), as it does two thirds under; floor points in the floor plane's band
    that touch it (`ground`) do not. Without `up` it stays unlabelled; so
    it does 11 % seen, beside the chair rather than under it (a fifth under), over it, split
    between three classes, called a class no object above holds, or a class that does not stand
    on the floor (clutter)."""
    points, labels, clusters, said, base = _chair_over_base()
    rows = np.arange(len(points))
    out, ids, made = lone_objects(points, labels, clusters, rows, said, min_points=30, up=UP)
    assert (out[base] == CHAIR).all() and (ids[base] == 1).all()
    assert np.array_equal(made, np.flatnonzero(base))
    assert len(lone_objects(points, labels, clusters, rows, said, min_points=30)[2]) == 0
    _, labels, clusters, few, base = _chair_over_base(every=3)
    assert len(lone_objects(points, labels, clusters, rows, few, min_points=30, up=UP)[2]) == 0
    beside = _chair_over_base(x=1.0)
    assert len(lone_objects(*beside[:2], beside[2], rows, beside[3], min_points=30, up=UP)[2]) == 0
    half_beside = _chair_over_base(x=0.45)  # a fifth under the seat's cells and neighbours
    assert len(lone_objects(*half_beside[:3], rows, half_beside[3], min_points=30, up=UP)[2]) == 0
    ring = grid_patch((0.45, 0.6), (0.0, 0.45), z=0.04, step=0.015).astype(np.float64)
    on_ground = np.r_[points, ring]  # floor its band gave back, touching the base's edge
    ground = np.r_[np.zeros(len(points), bool), np.ones(len(ring), bool)]
    grounded = (
        np.r_[labels, np.zeros(len(ring), np.uint8)],
        np.r_[clusters, np.zeros(len(ring), np.int32)],
    )
    out, _, made = lone_objects(on_ground, *grounded, np.arange(len(on_ground)),
                                np.r_[said, np.zeros(len(ring), np.uint8)], min_points=30, up=UP,
                                ground=ground)  # fmt: skip
    assert np.array_equal(made, np.flatnonzero(base)) and (out[ground] == 0).all()
    most = _chair_over_base(x=0.25)  # two thirds under: it joins
    assert len(lone_objects(*most[:3], rows, most[3], min_points=30, up=UP)[2]) == base.sum()
    split = said.copy()  # chair 40 %, person and sofa 30 %: no class holds most of what it saw
    seen = np.flatnonzero(base & (said == CHAIR))
    split[seen[np.arange(len(seen)) % 10 < 3]] = PERSON
    split[seen[np.arange(len(seen)) % 10 >= 7]] = Label.SOFA
    shelf = _chair_over_base(z=1.2)  # over the chair's back: no chair above it
    assert len(lone_objects(*shelf[:3], rows, shelf[3], min_points=30, up=UP)[2]) == 0
    assert len(lone_objects(points, labels, clusters, rows, split, min_points=30, up=UP)[2]) == 0
    tables = np.where(said == CHAIR, TABLE, said).astype(np.uint8)
    assert len(lone_objects(points, labels, clusters, rows, tables, min_points=30, up=UP)[2]) == 0
    clutter = np.where(said == CHAIR, Label.CLUTTER, said).astype(np.uint8)
    boxes = np.where(labels == CHAIR, Label.CLUTTER, labels).astype(np.uint8)
    assert len(lone_objects(points, boxes, clusters, rows, clutter, min_points=30, up=UP)[2]) == 0


def test_a_base_seen_in_part_touching_a_desks_leg_joins_the_chair_above_it() -> None:
    """The base of the test above touches a desk's leg (cluster 2, table) at its edge: not a
    lone segment, and seen too little (a quarter) to join what it touches; under its chair, the
    class the network gives it, it joins the chair, not the desk. Without `up` it stays
    unlabelled."""
    points, labels, clusters, said, base = _chair_over_base()
    leg = _leg((0.445, 0.2), height=0.7)
    points = np.vstack([points, leg])
    labels = np.r_[labels, np.full(len(leg), TABLE)].astype(np.uint8)
    clusters = np.r_[clusters, np.full(len(leg), 2)].astype(np.int32)
    said = np.r_[said, np.full(len(leg), TABLE)].astype(np.uint8)
    base = np.r_[base, np.zeros(len(leg), bool)]
    rows = np.arange(len(points))
    assert len(lone_objects(points, labels, clusters, rows, said, min_points=30, up=UP)[2]) == 0
    out, ids, made = adopt_orphans(points, labels, clusters, rows, said, up=UP)
    assert (out[base] == CHAIR).all() and (ids[base] == 1).all()
    assert np.array_equal(made, np.flatnonzero(base))
    assert len(adopt_orphans(points, labels, clusters, rows, said)[2]) == 0


def test_refine_gives_a_chairs_base_seen_in_part_to_the_chair_above() -> None:
    """Through refine, on a floor, the chair pushed under a desk (its top 75 cm up): the base's
    chair labels are too sparse for DBSCAN, the base lies 40 cm under the seat, out of
    regrowth's reach, and inside the desk's box too, so its chair labels do not rejoin the
    chair; it joins the chair (counted with the lone objects in metrics.json). Switched off
    (and in `paper()`) it stays unlabelled."""
    points, _, _, said, base = _chair_over_base()
    floor = grid_patch((-1.0, 1.5), (-1.0, 1.5), step=0.02).astype(np.float64)
    desk = grid_patch((-0.3, 1.0), (-0.3, 0.9), z=0.75, step=0.02).astype(np.float64)
    cloud = labelled(
        np.vstack([floor, points, desk]),
        np.r_[np.full(len(floor), FLOOR), said, np.full(len(desk), TABLE)],
    )
    cfg = RefineConfig(plane_min_points=3000, plane_max_remaining=100)
    at = len(floor) + np.flatnonzero(base)
    off = refine(cloud, dataclasses.replace(cfg, standing_bases=False), up=UP)
    assert (off.labels_iii[at] == 0).mean() > 0.9
    out = refine(cloud, cfg, up=UP)
    assert (out.labels_iii[at] == CHAIR).mean() > 0.95
    seat = len(floor) + np.flatnonzero(~base)
    assert np.unique(out.clusters_iii[at]).tolist() == np.unique(out.clusters_iii[seat]).tolist()
    assert np.isin(at, out.lone).mean() > 0.95
    assert refinement_metrics(out, gt_cloud=None)["points"]["lone_objects"] == len(out.lone)
    assert not RefineConfig.paper().standing_bases
