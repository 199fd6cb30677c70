"""Objects from clusters: near same-class clusters join, so do ones a wrong-class patch spans."""

from __future__ import annotations

import numpy as np
from helpers_refine import grid_patch

from capture.recording import Label
from process.refine.objects import group_objects
from process.refine.regrowth import regrow

CHAIR, SOFA, TABLE, CLUTTER = Label.CHAIR, Label.SOFA, Label.TABLE, Label.CLUTTER


def _boxes(*boxes: tuple[tuple[float, ...], tuple[float, ...]]) -> tuple[np.ndarray, np.ndarray]:
    return np.array([b[0] for b in boxes], float), np.array([b[1] for b in boxes], float)


def test_same_class_clusters_a_patch_spans_are_one_object_a_table_between_joins_nothing() -> None:
    # two chairs 30 cm apart along x, and between them a third cluster touching both
    left, right = ((0.0, 0.0, 0.0), (0.5, 0.5, 0.9)), ((0.8, 0.0, 0.0), (1.3, 0.5, 0.9))
    middle = ((0.45, 0.1, 0.4), (0.85, 0.4, 0.5))
    low, high = _boxes(left, right, middle)
    r1 = np.full(3, 0.05)
    for between, joined in ((CLUTTER, True), (TABLE, False)):
        label = np.array([CHAIR, CHAIR, between], np.uint8)
        obj = group_objects(label, low, high, gap_m=0.15, r1=r1, bridge_m=0.5, patch_max_m=0.7)
        assert (obj[0] == obj[1]) == joined, between
        plain = group_objects(label, low, high, gap_m=0.15)  # no bridge: 30 cm apart
        assert plain[0] != plain[1]


def test_no_bridge_past_its_reach_or_over_a_patch_too_large() -> None:
    left, right = ((0.0, 0.0, 0.0), (0.5, 0.5, 0.9)), ((1.1, 0.0, 0.0), (1.6, 0.5, 0.9))
    middle = ((0.45, 0.1, 0.4), (1.15, 0.4, 0.5))  # touches both, 60 cm apart
    low, high = _boxes(left, right, middle)
    label = np.array([CHAIR, CHAIR, CLUTTER], np.uint8)
    r1 = np.full(3, 0.05)
    far = group_objects(label, low, high, gap_m=0.15, r1=r1, bridge_m=0.5, patch_max_m=1.0)
    assert far[0] != far[1]
    reach = group_objects(label, low, high, gap_m=0.15, r1=r1, bridge_m=0.7, patch_max_m=1.0)
    assert reach[0] == reach[1]
    large = group_objects(label, low, high, gap_m=0.15, r1=r1, bridge_m=0.7, patch_max_m=0.5)
    assert large[0] != large[1]  # a 73 cm cluster between is an object, not a patch


def test_a_sofa_seat_called_chair_between_its_back_and_front_becomes_sofa() -> None:
    """A fused simulated map: the network called a sofa's seat chair and floor, so DBSCAN left
    the back and the front 30 cm apart; the chair patch on the seat touches both."""
    back = grid_patch((0.0, 1.6), (0.4, 0.9))[:, [0, 2, 1]]  # upright at y = 0
    front = grid_patch((0.0, 1.6), (0.05, 0.42))[:, [0, 2, 1]] + (0.0, 0.3, 0.0)
    seat = grid_patch((0.0, 1.6), (0.02, 0.3), z=0.42)
    patch = seat[:, 0] < 0.5  # the chair-labelled end of the seat
    points = np.concatenate([back, front, seat]).astype(np.float32)
    n_back, n_sofa = len(back), len(back) + len(front)
    labels = np.r_[np.full(n_sofa, SOFA), np.where(patch, CHAIR, 0)].astype(np.uint8)
    clusters = np.r_[np.full(n_back, 1), np.full(len(front), 2), np.where(patch, 3, 0)]
    kw = {
        "r1_m": {CHAIR: 0.08, SOFA: 0.08},
        "gap_m": 0.15,
        "up": np.array([0.0, 0.0, 1.0]),
        "prior": labels,
        "nest": True,
        "adopt_ratio": 3.0,
        "patch_max_m": 0.7,
    }
    grown = regrow(points, labels, clusters.astype(np.int32), bridge_m=0.5, **kw)  # type: ignore[arg-type]
    assert (grown.labels[n_sofa:] == SOFA).all()  # the patch adopted, the rest of the seat regrown
    apart = regrow(points, labels, clusters.astype(np.int32), **kw)  # type: ignore[arg-type]
    assert (apart.labels[n_sofa:][patch] == CHAIR).all()  # without the bridge the patch stays


def test_clutter_clusters_a_patch_spans_stay_apart() -> None:
    """Clutter is many small things: a monitor between two clutter clusters on a desk stays a
    monitor (TUM fr1_rpy)."""
    left, right = ((0.0, 0.0, 0.9), (0.3, 0.3, 1.0)), ((0.6, 0.0, 0.9), (0.9, 0.3, 1.0))
    monitor = ((0.28, 0.1, 0.9), (0.62, 0.2, 1.3))
    low, high = _boxes(left, right, monitor)
    label = np.array([CLUTTER, CLUTTER, Label.TV_MONITOR], np.uint8)
    obj = group_objects(label, low, high, gap_m=0.15, r1=np.full(3, 0.05), bridge_m=0.5)
    assert obj[0] != obj[1]
    label[:2] = CHAIR
    obj = group_objects(label, low, high, gap_m=0.15, r1=np.full(3, 0.05), bridge_m=0.5)
    assert obj[0] == obj[1]
