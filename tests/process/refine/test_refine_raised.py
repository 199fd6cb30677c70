"""Table labels raised above a table's top (process/refine/raised.py): known relabellings."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from helpers_refine import grid_patch, labelled

import process.refine.steps as steps
from capture.recording import Label
from process.refine import RefineConfig, refine
from process.refine.job import refinement_metrics
from process.refine.raised import raised_off_tables
from process.refine.seams import seam_vote

UP = np.array([0.0, 0.0, 1.0])
DESK_Z = 0.75
STEP = 0.01


def _box(lo: tuple[float, float, float], hi: tuple[float, float, float]) -> np.ndarray:
    """Return the surface of an axis-aligned box sampled every STEP (all six faces)."""
    faces = []
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    for z in (z0, z1):
        faces.append(grid_patch((x0, x1), (y0, y1), z=z, step=STEP))
    gx, gz = np.meshgrid(np.arange(x0, x1, STEP), np.arange(z0, z1, STEP))
    for y in (y0, y1):
        faces.append(np.column_stack([gx.ravel(), np.full(gx.size, y), gz.ravel()]))
    gy, gz = np.meshgrid(np.arange(y0, y1, STEP), np.arange(z0, z1, STEP))
    for x in (x0, x1):
        faces.append(np.column_stack([np.full(gy.size, x), gy.ravel(), gz.ravel()]))
    return np.concatenate(faces).astype(np.float32)


def _desk_with_monitor(rng: np.random.Generator) -> dict[str, np.ndarray]:
    """A desk top with 2 mm noise; a monitor on a 1.1 cm base plate; a box; a shelf above."""
    desk = grid_patch((0.0, 1.6), (0.0, 0.8), z=DESK_Z, step=STEP)
    desk[:, 2] += rng.normal(0.0, 0.002, len(desk)).astype(np.float32)
    plate = _box((0.3, 0.3, DESK_Z), (0.48, 0.52, DESK_Z + 0.011))
    stand = _box((0.37, 0.39, DESK_Z + 0.011), (0.40, 0.45, DESK_Z + 0.2))
    screen = _box((0.35, 0.1, DESK_Z + 0.12), (0.38, 0.7, DESK_Z + 0.45))
    box = _box((1.0, 0.2, DESK_Z), (1.15, 0.35, DESK_Z + 0.1))  # the network calls it table
    return {"desk": desk, "plate": plate, "stand": stand, "screen": screen, "box": box}


def _scene(parts: dict[str, np.ndarray]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    points = np.concatenate(list(parts.values()))
    index, start = {}, 0
    for name, part in parts.items():
        index[name] = np.arange(start, start + len(part))
        start += len(part)
    return points, index


def _desk_on_legs() -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The desk with its monitor on four legs over a floor: what refine finds a table surface in."""
    parts = _desk_with_monitor(np.random.default_rng(3))
    legs = [_box((x, y, 0.0), (x + 0.04, y + 0.04, DESK_Z)) for x in (0.0, 1.5) for y in (0.0, 0.7)]
    floor = grid_patch((-0.5, 2.1), (-0.5, 1.3), z=0.0, step=0.02)
    return _scene({**parts, "legs": np.concatenate(legs), "floor": floor})


def test_a_monitors_plate_and_stand_foot_called_table_join_the_monitor() -> None:
    points, at = _scene(_desk_with_monitor(np.random.default_rng(0)))
    labels = np.full(len(points), Label.TABLE, np.uint8)
    clusters = np.full(len(points), 1, np.int32)  # the desk's object holds it all ...
    stand_low = at["stand"][points[at["stand"], 2] < DESK_Z + 0.06]  # bleed: 6 cm up
    for name in ("screen", "stand"):
        labels[at[name]], clusters[at[name]] = Label.TV_MONITOR, 2  # ... but the monitor
    labels[stand_low], clusters[stand_low] = Label.TABLE, 1
    before = labels.copy()
    tops = [(np.array([0.0, 0.0, 1.0, -DESK_Z]), at["desk"])]
    vote = raised_off_tables(points, labels, clusters, tops, UP)
    plate_top = at["plate"][points[at["plate"], 2] > DESK_Z + 0.008]
    assert (vote.labels[plate_top] == Label.TV_MONITOR).all()
    assert (vote.labels[stand_low] == Label.TV_MONITOR).all()
    assert (vote.clusters[stand_low] == 2).all()  # into the monitor's object
    assert (vote.labels[at["desk"]] == Label.TABLE).all()  # the top itself stays
    assert (vote.labels[at["box"]] == Label.TABLE).all()  # touches nothing but table
    assert set(vote.relabelled) <= set(at["plate"]) | set(stand_low)
    assert (labels == before).all()  # the input is not changed in place


def test_a_desk_top_seen_from_both_faces_still_gives_the_plate_back() -> None:
    """RANSAC's 2 cm band takes the top's upper and lower face, 2.7 cm apart; the plane lies
    between them. The top is the upper face (upper quartile), not the plane: with the median
    the whole upper face would stand above the band, one piece with the plate, larger than
    the monitor, and nothing would move. A table-labelled box beside the desk, off its
    footprint, touching a monitor there, stays table."""
    parts = _desk_with_monitor(np.random.default_rng(5))
    underside = parts["desk"].copy()
    underside[:, 2] -= 0.027
    beside = _box((2.0, 0.3, DESK_Z), (2.1, 0.4, DESK_Z + 0.05))  # off the desk
    screen2 = _box((2.0, 0.3, DESK_Z + 0.05), (2.1, 0.4, DESK_Z + 0.3))
    points, at = _scene({**parts, "underside": underside, "beside": beside, "screen2": screen2})
    labels = np.full(len(points), Label.TABLE, np.uint8)
    foot = at["stand"][points[at["stand"], 2] < DESK_Z + 0.06]
    labels[at["screen"]] = labels[at["stand"]] = labels[at["screen2"]] = Label.TV_MONITOR
    labels[foot] = Label.TABLE
    clusters = np.where(labels == Label.TABLE, 1, 2).astype(np.int32)
    plane = np.array([0.0, 0.0, 1.0, -(DESK_Z - 0.0135)])  # between the two faces
    tops = [(plane, np.concatenate([at["desk"], at["underside"]]))]
    vote = raised_off_tables(points, labels, clusters, tops, UP)
    plate_top = at["plate"][points[at["plate"], 2] > DESK_Z + 0.008]
    assert (vote.labels[plate_top] == Label.TV_MONITOR).all()
    assert (vote.labels[foot] == Label.TV_MONITOR).all()
    # the upper face stays: a few of its noise tail at the plate's rim (measured 10 of 6,400,
    # 6 mm up) go with the plate
    rim = np.abs(points[at["desk"], :2] - [0.39, 0.41]).max(axis=1) < 0.13
    assert (vote.labels[at["desk"][~rim]] == Label.TABLE).all()
    assert (vote.labels[at["desk"]] == Label.TABLE).mean() > 0.995
    assert (vote.labels[at["beside"]] == Label.TABLE).all()


def test_a_shelf_called_table_above_the_desk_stays_table_under_a_small_monitor() -> None:
    parts = _desk_with_monitor(np.random.default_rng(1))
    shelf = _box((0.0, 0.6, DESK_Z + 0.3), (1.6, 0.8, DESK_Z + 0.32))  # a hutch's shelf
    small = _box((0.7, 0.65, DESK_Z + 0.32), (0.8, 0.75, DESK_Z + 0.42))  # a small monitor
    points, at = _scene({**parts, "shelf": shelf, "small": small})
    labels = np.full(len(points), Label.TABLE, np.uint8)
    labels[at["small"]] = Label.TV_MONITOR
    labels[at["screen"]] = labels[at["stand"]] = Label.TV_MONITOR
    labels[at["stand"][points[at["stand"], 2] < DESK_Z + 0.06]] = Label.TABLE
    clusters = np.where(labels == Label.TABLE, 1, 2).astype(np.int32)
    tops = [(np.array([0.0, 0.0, 1.0, -DESK_Z]), at["desk"])]
    vote = raised_off_tables(points, labels, clusters, tops, UP)
    assert (vote.labels[at["shelf"]] == Label.TABLE).all()  # larger than what it touches
    plate_top = at["plate"][points[at["plate"], 2] > DESK_Z + 0.008]
    assert (vote.labels[plate_top] == Label.TV_MONITOR).all()  # the big monitor's plate still


def test_a_level_sheet_above_the_top_stays_table_beside_a_person() -> None:
    """A second desk's top 1.5 cm higher, touching a person leaning on it: part of a table."""
    rng = np.random.default_rng(4)
    desk = grid_patch((0.0, 1.0), (0.0, 0.8), z=DESK_Z, step=STEP)
    higher = grid_patch((1.0, 1.2), (0.0, 0.8), z=DESK_Z + 0.015, step=STEP)
    person = _box((1.05, 0.3, DESK_Z + 0.016), (1.15, 0.5, DESK_Z + 0.4))  # an arm on it
    points = np.concatenate([desk, higher, person])
    points[:, 2] += rng.normal(0.0, 0.001, len(points)).astype(np.float32)
    labels = np.r_[np.full(len(desk) + len(higher), Label.TABLE), np.full(len(person), 6)]
    labels = labels.astype(np.uint8)
    clusters = np.where(labels == Label.TABLE, 1, 2).astype(np.int32)
    tops = [(np.array([0.0, 0.0, 1.0, -DESK_Z]), np.arange(len(desk) + len(higher)))]
    vote = raised_off_tables(points, labels, clusters, tops, UP)
    assert (vote.labels[: len(desk) + len(higher)] == Label.TABLE).all()


def test_without_tops_or_with_nothing_above_nothing_changes() -> None:
    points, at = _scene(_desk_with_monitor(np.random.default_rng(2)))
    labels = np.full(len(points), Label.TABLE, np.uint8)
    labels[at["screen"]] = Label.TV_MONITOR
    clusters = np.ones(len(points), np.int32)
    vote = raised_off_tables(points, labels, clusters, [], UP)
    assert len(vote.relabelled) == 0 and (vote.labels == labels).all()
    high = [(np.array([0.0, 0.0, 1.0, -(DESK_Z + 1.0)]), at["desk"][:5])]  # too few points
    assert len(raised_off_tables(points, labels, clusters, high, UP).relabelled) == 0


def test_refine_gives_the_plate_and_foot_back_to_the_monitor() -> None:
    """Through refine (the desk found as a table surface above a floor), shown in the .rrd."""
    points, at = _desk_on_legs()
    labels = np.full(len(points), Label.TABLE, np.uint8)
    labels[at["floor"]] = Label.FLOOR
    labels[at["screen"]] = labels[at["stand"]] = Label.TV_MONITOR
    foot = at["stand"][points[at["stand"], 2] < DESK_Z + 0.06]
    labels[foot] = Label.TABLE
    cloud = labelled(points, labels)
    cfg = RefineConfig(plane_min_points=1500, plane_max_remaining=100)
    out = refine(cloud, cfg, up=UP)
    top = next(p.top for p in out.planes.planes if p.top is not None)
    assert np.isin(at["desk"], top).mean() > 0.9
    assert (out.labels_iii[foot] == Label.TV_MONITOR).mean() > 0.9
    assert refinement_metrics(out, gt_cloud=None)["points"]["raised_relabelled"] >= len(foot)
    assert len(out.seam_cloud()) >= len(out.raised)  # shown with the seams in the .rrd
    off = refine(cloud, dataclasses.replace(cfg, raised_vote=False), up=UP)
    assert (off.labels_iii[foot] == Label.TABLE).mean() > 0.9
    assert not RefineConfig.paper().raised_vote


def test_refine_gives_the_bled_underside_to_the_desk_and_counts_it() -> None:
    """Through refine: the monitor's label bled onto the desk's underside, 3 cm under its top,
    goes to the desk under the raised vote, and `metrics.json` counts it."""
    parts = _desk_with_monitor(np.random.default_rng(4))
    underside = parts["desk"].copy()
    underside[:, 2] -= 0.03
    legs = [_box((x, y, 0.0), (x + 0.04, y + 0.04, DESK_Z)) for x in (0.0, 1.5) for y in (0.0, 0.7)]
    floor = grid_patch((-0.5, 2.1), (-0.5, 1.3), z=0.0, step=0.02)
    points, at = _scene(
        {**parts, "underside": underside, "legs": np.concatenate(legs), "floor": floor}
    )
    labels = np.full(len(points), Label.TABLE, np.uint8)
    labels[at["floor"]] = Label.FLOOR
    labels[at["screen"]] = labels[at["stand"]] = labels[at["plate"]] = Label.TV_MONITOR
    near = np.abs(points[at["underside"], :2] - [0.39, 0.41]).max(axis=1) < 0.2
    bled = at["underside"][near]
    labels[bled] = Label.TV_MONITOR
    cfg = RefineConfig(plane_min_points=1500, plane_max_remaining=100)
    out = refine(labelled(points, labels), cfg, up=UP)
    assert (out.labels_iii[bled] == Label.TABLE).mean() > 0.9
    sunk = refinement_metrics(out, gt_cloud=None)["points"]["sunk_under_tables"]
    assert sunk == out.sunk and sunk >= 0.9 * len(bled)
    # the rule's own test above fails without it; here the seam vote would also take a bled
    # patch of a clean synthetic underside, so this one checks the count reaches metrics.json


def test_monitor_labels_under_a_desk_top_go_to_the_desk() -> None:
    """The monitor's label bled through the desk onto its underside, 3 cm under the top, and
    onto the top around the plate. Under the top's band, over its footprint, it is the desk's,
    and so is the ring level with the desk; the plate's top, 1.1 cm up, stays. Clutter stays
    clutter: books on a shelf 4 cm under a board that passes for a table's top, a box on the
    floor; so does a person's knee."""
    parts = _desk_with_monitor(np.random.default_rng(3))
    underside = parts["desk"].copy()
    underside[:, 2] -= 0.03
    floor_box = _box((1.2, 0.2, DESK_Z - 0.7), (1.4, 0.4, DESK_Z - 0.55))
    off_desk = _box((1.8, 0.2, DESK_Z - 0.04), (1.9, 0.3, DESK_Z - 0.02))  # beside, lower
    knee = _box((0.8, 0.3, DESK_Z - 0.05), (1.0, 0.5, DESK_Z - 0.04))  # a person's knee
    books = _box((1.2, 0.5, DESK_Z - 0.3), (1.5, 0.7, DESK_Z - 0.04))  # on a shelf under it
    points, at = _scene(
        {**parts, "underside": underside, "floor_box": floor_box, "off": off_desk, "knee": knee,
         "books": books}
    )  # fmt: skip
    labels = np.full(len(points), Label.TABLE, np.uint8)
    for name in ("screen", "stand", "plate"):
        labels[at[name]] = Label.TV_MONITOR
    bled = at["underside"][np.abs(points[at["underside"], :2] - [0.39, 0.41]).max(axis=1) < 0.2]
    ring = at["desk"][np.abs(points[at["desk"], :2] - [0.39, 0.41]).max(axis=1) < 0.2]
    labels[bled] = labels[ring] = Label.TV_MONITOR
    labels[at["floor_box"]] = labels[at["books"]] = Label.CLUTTER
    labels[at["off"]] = Label.TV_MONITOR
    labels[at["knee"]] = Label.PERSON
    clusters = np.where(labels == Label.TABLE, 1, 2).astype(np.int32)
    tops = [(np.array([0.0, 0.0, 1.0, -DESK_Z]), at["desk"])]
    vote = raised_off_tables(points, labels, clusters, tops, UP)
    assert (vote.labels[bled] == Label.TABLE).all()
    assert (vote.clusters[bled] == 1).all()  # into the desk's object
    # the ring is level with the desk but for its noise tail: 2 sigmas of the local noise
    # estimate (1.5 mm for this 2 mm noise; 89 % of the ring measured)
    assert (vote.labels[ring] == Label.TABLE).mean() > 0.85
    assert (vote.clusters[ring][vote.labels[ring] == Label.TABLE] == 1).all()
    plate_low = at["plate"][points[at["plate"], 2] < DESK_Z + 0.005]  # its hidden bottom face
    assert set(vote.relabelled) <= set(bled) | set(ring) | set(plate_low)
    assert vote.sunk == len(vote.relabelled)
    plate_top = at["plate"][points[at["plate"], 2] > DESK_Z + 0.008]
    assert (vote.labels[plate_top] == Label.TV_MONITOR).all()
    assert (vote.labels[at["floor_box"]] == Label.CLUTTER).all()  # far under the top
    assert (vote.labels[at["books"]] == Label.CLUTTER).all()
    assert (vote.labels[at["off"]] == Label.TV_MONITOR).all()  # beyond the desk's footprint
    assert (vote.labels[at["knee"]] == Label.PERSON).all()


def _ringed(seed: int) -> tuple[np.ndarray, dict[str, np.ndarray], np.ndarray, np.ndarray]:
    """The desk and monitor, the monitor's label bled onto the desk in a ring round the plate."""
    points, at = _scene(_desk_with_monitor(np.random.default_rng(seed)))
    labels = np.full(len(points), Label.TABLE, np.uint8)
    for name in ("screen", "stand", "plate"):
        labels[at[name]] = Label.TV_MONITOR
    ring = at["desk"][np.abs(points[at["desk"], :2] - [0.39, 0.41]).max(axis=1) < 0.2]
    labels[ring] = Label.TV_MONITOR
    return points, at, labels, ring


def test_the_ring_sinks_under_a_plane_tilted_off_the_desk() -> None:
    """RANSAC's plane through both faces of a thin top tilts: here 0.35 degrees, 1 cm over the
    desk's 1.6 m. The desk's plane refitted on the band still finds the ring level with it
    and the plate's top 1.1 cm above it."""
    points, at, labels, ring = _ringed(7)
    tilt = np.radians(0.35)
    normal = np.array([np.sin(tilt), 0.0, np.cos(tilt)])
    plane = np.array([*normal, -float(normal @ [0.8, 0.4, DESK_Z])])
    clusters = np.where(labels == Label.TABLE, 1, 2).astype(np.int32)
    vote = raised_off_tables(points, labels, clusters, [(plane, at["desk"])], UP)
    assert (vote.labels[ring] == Label.TABLE).mean() > 0.85
    plate_top = at["plate"][points[at["plate"], 2] > DESK_Z + 0.008]
    assert (vote.labels[plate_top] == Label.TV_MONITOR).all()
    # without the refit (the plane's own offsets) the tilt takes the ring's far side out
    offset = points[ring] @ plane[:3] + plane[3]
    assert np.ptp(offset) > 0.003


def test_a_warped_desk_sinks_nothing_within_its_band() -> None:
    """A fused map's desk bent by drift (here a 4 mm wave over 0.8 m, twice the noise) is not
    one plane: nothing in its band is level with it, and the ring keeps its label there."""
    points, at, labels, ring = _ringed(8)
    desk = at["desk"]
    points[desk, 2] += 0.004 * np.sin(2 * np.pi * points[desk, 0] / 0.8)
    clusters = np.where(labels == Label.TABLE, 1, 2).astype(np.int32)
    tops = [(np.array([0.0, 0.0, 1.0, -DESK_Z]), desk)]
    vote = raised_off_tables(points, labels, clusters, tops, UP)
    high = ring[points[ring, 2] >= DESK_Z]  # within the band (only troughs fall under it)
    assert len(high) > 500
    assert (vote.labels[high] == Label.TV_MONITOR).all()


def test_the_vote_names_what_stands_on_the_desk() -> None:
    """`above`: every point over the desk's footprint above its top's band, whatever its label
    (the seam vote keeps the table's label off them); none of the desk's own."""
    points, at = _scene(_desk_with_monitor(np.random.default_rng(6)))
    labels = np.full(len(points), Label.TABLE, np.uint8)
    labels[at["screen"]] = labels[at["stand"]] = Label.TV_MONITOR
    clusters = np.where(labels == Label.TABLE, 1, 2).astype(np.int32)
    tops = [(np.array([0.0, 0.0, 1.0, -DESK_Z]), at["desk"])]
    above = raised_off_tables(points, labels, clusters, tops, UP).above
    high = points[:, 2] > DESK_Z + 0.02  # well clear of the band (2 mm noise, 5 mm at least)
    standing = np.concatenate([at["plate"], at["stand"], at["screen"], at["box"]])
    assert set(np.flatnonzero(high)) <= set(above)
    tail = np.setdiff1d(above, standing)  # the desk's noise tail over its band
    assert np.isin(tail, at["desk"]).all() and len(tail) < 0.01 * len(at["desk"])
    assert len(raised_off_tables(points, labels, clusters, [], UP).above) == 0


def test_refine_tells_the_seam_vote_what_stands_on_the_desk(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Through refine: the seam vote is given the points above the desk's top and gravity, and
    keeps the table's label off the monitor's stand there (test_refine_seams.py)."""
    told: dict[str, object] = {}

    def spy(*args: object, **kwargs: object) -> object:
        told.update(kwargs)
        return seam_vote(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(steps, "seam_vote", spy)
    points, at = _desk_on_legs()
    labels = np.full(len(points), Label.TABLE, np.uint8)
    labels[at["floor"]] = Label.FLOOR
    labels[at["screen"]] = labels[at["stand"]] = labels[at["box"]] = Label.TV_MONITOR
    refine(labelled(points, labels), RefineConfig(plane_min_points=1500), up=UP)
    high = np.flatnonzero(points[:, 2] > DESK_Z + 0.1)  # the screen, the stand, the box's top
    assert np.isin(high, np.asarray(told["standing"])).all()
    assert np.allclose(np.asarray(told["up"]), UP, atol=0.01)  # the floor plane's normal
