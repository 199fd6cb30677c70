"""The seam vote: a label bled across a contact goes back to the surface's class, objects stay."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest

import process.refine.seams as seams
from capture.recording import Label
from process.refine.seams import seam_vote

CHAIR, PERSON, TABLE, CLUTTER = Label.CHAIR, Label.PERSON, Label.TABLE, Label.CLUTTER
TV = Label.TV_MONITOR
UP = np.array([0.0, 0.0, 1.0])
STEP = 0.01

Points = npt.NDArray[np.float64]


def _vote(
    points: Points,
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    *,
    flatness: float = 0.06,
    max_points: int = 400_000,
) -> seams.SeamVote:
    """The vote at the defaults of RefineConfig."""
    return seam_vote(
        points, labels, clusters, seam_m=0.08, angle_deg=15.0, flatness=flatness,
        max_points=max_points,
    )  # fmt: skip


def _plate(x: tuple[float, float], y: tuple[float, float], z: float) -> Points:
    gx, gy = np.meshgrid(np.arange(*x, STEP), np.arange(*y, STEP))
    return np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, z)])


def _box_sides(x: tuple[float, float], y: tuple[float, float], z: tuple[float, float]) -> Points:
    """The four sides and the top of a box (its bottom rests on something)."""
    zs = np.arange(z[0] + STEP, z[1], STEP)
    sides = []
    for fixed, span, axis in ((x[0], y, 1), (x[1], y, 1), (y[0], x, 0), (y[1], x, 0)):
        a, b = np.meshgrid(np.arange(*span, STEP), zs)
        other = np.full(a.size, fixed)
        xy = (other, a.ravel()) if axis == 1 else (a.ravel(), other)
        sides.append(np.column_stack([*xy, b.ravel()]))
    return np.vstack([*sides, _plate(x, y, z[1])])


def _noisy(points: Points, seed: int = 0) -> Points:
    return points + np.random.default_rng(seed).normal(0.0, 0.001, points.shape)


def _seated() -> tuple[Points, npt.NDArray[np.uint8], npt.NDArray[np.int32], npt.NDArray[np.bool_]]:
    """A chair seat with a person's block on it; the person's label bled 5 cm onto the seat."""
    seat = _plate((0.0, 0.6), (0.0, 0.6), 0.45)
    body = _box_sides((0.15, 0.45), (0.2, 0.4), (0.45, 1.05))
    on_body = (seat[:, 0] > 0.15) & (seat[:, 0] < 0.45) & (seat[:, 1] > 0.2) & (seat[:, 1] < 0.4)
    seat = seat[~on_body]  # hidden under the body
    gap = np.maximum(np.abs(seat[:, 0] - 0.3) - 0.15, 0) + np.maximum(
        np.abs(seat[:, 1] - 0.3) - 0.1, 0
    )
    bleed = gap < 0.05
    points = _noisy(np.vstack([seat, body]))
    labels = np.concatenate([np.where(bleed, PERSON, CHAIR), np.full(len(body), PERSON)])
    clusters = np.concatenate([np.where(bleed, 2, 1), np.full(len(body), 2)]).astype(np.int32)
    truth_bleed = np.concatenate([bleed, np.zeros(len(body), bool)])
    return points, labels.astype(np.uint8), clusters, truth_bleed


def test_a_person_label_bled_onto_a_seat_goes_back_to_the_chair() -> None:
    points, labels, clusters, bleed = _seated()
    vote = _vote(points, labels, clusters)
    back = bleed & (vote.labels == CHAIR)
    assert bleed.sum() > 300 and back.sum() > 0.7 * bleed.sum()
    # what stays is the crease: points whose neighbourhood reaches up the body's side
    gap = np.maximum(np.abs(points[:, 0] - 0.3) - 0.15, 0) + np.maximum(
        np.abs(points[:, 1] - 0.3) - 0.1, 0
    )
    assert np.all(gap[bleed & ~back] < 0.025)
    assert np.all(vote.labels[~bleed] == labels[~bleed])  # the body keeps its label
    assert set(vote.relabelled.tolist()) == set(np.flatnonzero(back).tolist())


def test_past_max_points_the_vote_runs_on_class_cells_with_the_same_verdict() -> None:
    points, labels, clusters, bleed = _seated()
    assert len(points) > 4000
    vote = _vote(points, labels, clusters, max_points=3000)  # about 3 points a cell
    back = bleed & (vote.labels == CHAIR)
    assert back.sum() > 0.6 * bleed.sum()
    assert np.all(vote.labels[~bleed] == labels[~bleed])


def test_a_thin_object_lying_flat_on_a_desk_stays_itself() -> None:
    """A sheet on a desk shares the desk's surface, but all of its object lies on it."""
    desk = _plate((0.0, 1.2), (0.0, 0.6), 0.75)
    sheet = (desk[:, 0] > 0.4) & (desk[:, 0] < 0.7) & (desk[:, 1] > 0.2) & (desk[:, 1] < 0.42)
    points = _noisy(desk + np.where(sheet, 0.002, 0.0)[:, None] * [0, 0, 1])
    labels = np.where(sheet, CLUTTER, TABLE).astype(np.uint8)
    clusters = np.where(sheet, 2, 1).astype(np.int32)
    assert np.array_equal(_vote(points, labels, clusters).labels, labels)


def test_the_fringe_rule_is_what_keeps_the_sheet(monkeypatch: pytest.MonkeyPatch) -> None:
    desk = _plate((0.0, 1.2), (0.0, 0.6), 0.75)
    sheet = (desk[:, 0] > 0.4) & (desk[:, 0] < 0.7) & (desk[:, 1] > 0.2) & (desk[:, 1] < 0.42)
    labels = np.where(sheet, CLUTTER, TABLE).astype(np.uint8)
    clusters = np.where(sheet, 2, 1).astype(np.int32)
    monkeypatch.setattr(seams, "FRINGE", 1.01)  # any share: the sheet would be desk
    vote = _vote(_noisy(desk), labels, clusters)
    assert np.mean(vote.labels[sheet] == TABLE) > 0.5  # all but its middle, beyond seam_m


def _arm_on_desk() -> tuple[Points, npt.NDArray[np.uint8], npt.NDArray[np.int32], int]:
    """A forearm (a 4 cm cylinder) lying on a desk, part of a person standing beside it."""
    desk = _plate((0.0, 1.0), (0.0, 0.6), 0.75)
    angle, x = np.meshgrid(np.linspace(0, 2 * np.pi, 26, endpoint=False), np.arange(0.3, 0.7, STEP))
    arm = np.column_stack(
        [x.ravel(), 0.3 + 0.04 * np.cos(angle.ravel()), 0.79 + 0.04 * np.sin(angle.ravel())]
    )
    arm = arm[arm[:, 2] > 0.755]  # the underside rests on the desk
    desk = desk[~((desk[:, 0] > 0.3) & (desk[:, 0] < 0.7) & (np.abs(desk[:, 1] - 0.3) < 0.02))]
    body = _box_sides((1.1, 1.4), (0.2, 0.4), (0.0, 1.3))
    points = _noisy(np.vstack([desk, arm, body]))
    labels = np.concatenate([np.full(len(desk), TABLE), np.full(len(arm) + len(body), PERSON)])
    clusters = np.concatenate([np.full(len(desk), 1), np.full(len(arm) + len(body), 2)])
    return points, labels.astype(np.uint8), clusters.astype(np.int32), len(desk)


def test_an_arm_lying_on_a_desk_stays_the_persons() -> None:
    points, labels, clusters, _ = _arm_on_desk()
    assert np.array_equal(_vote(points, labels, clusters).labels, labels)


def test_the_flatness_rule_is_what_keeps_the_arm() -> None:
    points, labels, clusters, n_desk = _arm_on_desk()
    loose = _vote(points, labels, clusters, flatness=1.0 / 3.0)
    assert np.any(loose.labels[n_desk:] == TABLE)  # a surface creeping round the arm's underside


def test_one_class_or_none_changes_nothing() -> None:
    points = _noisy(_plate((0.0, 0.5), (0.0, 0.5), 0.0))
    for labels in (np.full(len(points), CHAIR), np.zeros(len(points))):
        vote = _vote(points, labels.astype(np.uint8), np.ones(len(points), np.int32))
        assert np.array_equal(vote.labels, labels) and len(vote.relabelled) == 0


def _box_at_desk_edge() -> tuple[Points, npt.NDArray[np.uint8], npt.NDArray[np.int32], int]:
    """A desk with a front panel, and a box on it whose front lies in the panel's plane."""
    top = _plate((0.0, 1.5), (0.0, 0.7), 0.75)
    box = _box_sides((0.5, 0.8), (0.0, 0.3), (0.75, 0.95))
    top = top[~((top[:, 0] > 0.5) & (top[:, 0] < 0.8) & (top[:, 1] < 0.3))]  # under the box
    gx, gz = np.meshgrid(np.arange(0.0, 1.5, STEP), np.arange(0.4, 0.75, STEP))
    panel = np.column_stack([gx.ravel(), np.zeros(gx.size), gz.ravel()])  # y = 0, as the box's
    desk = np.vstack([top, panel])
    points = _noisy(np.vstack([desk, box]))
    labels = np.concatenate([np.full(len(desk), TABLE), np.full(len(box), CLUTTER)])
    clusters = np.concatenate([np.full(len(desk), 1), np.full(len(box), 2)])
    return points, labels.astype(np.uint8), clusters.astype(np.int32), len(desk)


def test_what_stands_on_a_desk_never_takes_its_label() -> None:
    """The box's front shares a surface with the desk's panel, but it stands above the top."""
    points, labels, clusters, n_desk = _box_at_desk_edge()
    blind = _vote(points, labels, clusters)
    front = np.flatnonzero(blind.labels[n_desk:] == TABLE) + n_desk
    assert len(front) > 100 and np.all(np.abs(points[front, 1]) < 0.01)  # the guard is needed
    above = np.arange(n_desk, len(points))  # raised.py's: above the top's band, over the desk
    vote = seam_vote(
        points, labels, clusters, seam_m=0.08, angle_deg=15.0, flatness=0.06, standing=above,
        up=UP,
    )  # fmt: skip
    assert np.array_equal(vote.labels[n_desk:], labels[n_desk:])  # the box stays whole
    assert np.array_equal(vote.labels[:n_desk], blind.labels[:n_desk])  # the desk votes as before


def test_past_max_points_what_stands_on_a_desk_keeps_its_label_too() -> None:
    points, labels, clusters, n_desk = _box_at_desk_edge()
    above = np.arange(n_desk, len(points))
    vote = seam_vote(
        points, labels, clusters, seam_m=0.08, angle_deg=15.0, flatness=0.06,
        max_points=len(points) // 3, standing=above, up=UP,
    )  # fmt: skip
    assert np.array_equal(vote.labels[n_desk:], labels[n_desk:])


def test_a_level_stretch_of_the_top_above_its_band_still_takes_the_desks_label() -> None:
    """A monitor's label bled onto the desk around its foot, where the desk rises past the
    top's band (a second desk's top 1.5 cm higher, a warped top): level, it is the desk's."""
    desk = _plate((0.0, 1.2), (0.0, 0.6), 0.75)
    monitor = _box_sides((0.45, 0.75), (0.25, 0.35), (0.75, 1.1))
    gap = np.maximum(np.abs(desk[:, 0] - 0.6) - 0.15, 0) + np.maximum(
        np.abs(desk[:, 1] - 0.3) - 0.05, 0
    )
    desk = desk[gap > 0]  # under the monitor
    bleed = gap[gap > 0] < 0.05
    points = _noisy(np.vstack([desk, monitor]))
    labels = np.concatenate([np.where(bleed, TV, TABLE), np.full(len(monitor), TV)])
    clusters = np.concatenate([np.where(bleed, 2, 1), np.full(len(monitor), 2)])
    n_desk = len(desk)
    standing = np.concatenate([np.flatnonzero(bleed), np.arange(n_desk, len(points))])
    vote = seam_vote(
        points, labels.astype(np.uint8), clusters.astype(np.int32), seam_m=0.08,
        angle_deg=15.0, flatness=0.06, standing=standing, up=UP,
    )  # fmt: skip
    assert bleed.sum() > 200 and np.mean(vote.labels[:n_desk][bleed] == TABLE) > 0.7
    assert np.array_equal(vote.labels[n_desk:], labels[n_desk:])  # the monitor stands
