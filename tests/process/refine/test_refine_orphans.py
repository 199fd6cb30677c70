"""Orphans: a segment the network saw, unlabelled after phase II, joins the class it touches."""

from __future__ import annotations

import dataclasses

import numpy as np
import numpy.typing as npt
from helpers_refine import grid_patch, labelled

from capture.recording import Label
from process.refine import RefineConfig, refine
from process.refine.job import refinement_metrics
from process.refine.orphans import adopt_orphans

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
