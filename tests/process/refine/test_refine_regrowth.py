"""Regrowth: a cut-away part regrows up to r2 from the centroid; ties go to the nearer cluster."""

from __future__ import annotations

import numpy as np
from helpers_refine import grid_patch

from process.refine.regrowth import regrow


def test_a_cut_away_part_regrows_and_a_point_beyond_r2_does_not() -> None:
    body = grid_patch((0.0, 0.8), (0.0, 0.4))  # cluster 1: centroid (0.39, 0.19), r2 ~ 0.44
    strip = grid_patch((0.8, 1.3), (0.0, 0.4))  # the cut-away part, label 0, chained at 2 cm
    points = np.concatenate([body, strip])
    labels = np.r_[np.full(len(body), 4), np.zeros(len(strip))].astype(np.uint8)
    clusters = np.r_[np.ones(len(body)), np.zeros(len(strip))].astype(np.int32)
    grown = regrow(points, labels, clusters, r1_m={4: 0.025})
    centroid = body.astype(np.float64).mean(axis=0)
    r2 = np.linalg.norm(body.max(axis=0) - body.min(axis=0)) / 2
    assert abs(grown.r2_m[1] - r2) < 1e-5
    inside = np.linalg.norm(strip - centroid, axis=1) <= r2
    assert 0 < inside.sum() < len(strip)  # the test reaches past r2
    strip_labels = grown.labels[len(body) :]
    assert (strip_labels[inside] == 4).all()
    assert (strip_labels[~inside] == 0).all()
    assert (grown.clusters[len(body) :][inside] == 1).all()
    assert len(grown.regrown) == inside.sum()


def test_a_gap_wider_than_r1_stops_the_growth() -> None:
    body = grid_patch((0.0, 0.8), (0.0, 0.4))
    island = grid_patch((0.86, 0.9), (0.1, 0.2))  # 6 cm from the body, inside r2
    points = np.concatenate([body, island])
    labels = np.r_[np.full(len(body), 4), np.zeros(len(island))].astype(np.uint8)
    clusters = np.r_[np.ones(len(body)), np.zeros(len(island))].astype(np.int32)
    grown = regrow(points, labels, clusters, r1_m={4: 0.03})
    assert (grown.labels[len(body) :] == 0).all()


def test_a_point_reached_by_two_clusters_goes_to_the_nearer_one() -> None:
    left = grid_patch((0.0, 0.4), (0.0, 0.8))  # table up to x = 0.38, r2 ~ 0.43
    right = grid_patch((0.5, 0.9), (0.0, 0.8))  # chair from x = 0.5
    between = np.array([[0.41, 0.4, 0.0], [0.47, 0.4, 0.0]], np.float32)  # both within both r1
    points = np.concatenate([left, right, between])
    labels = np.r_[np.full(len(left), 4), np.full(len(right), 5), [0, 0]].astype(np.uint8)
    clusters = np.r_[np.full(len(left), 1), np.full(len(right), 2), [0, 0]].astype(np.int32)
    grown = regrow(points, labels, clusters, r1_m={4: 0.1, 5: 0.1})
    assert list(grown.labels[-2:]) == [4, 5]
    assert list(grown.clusters[-2:]) == [1, 2]


def test_without_clusters_nothing_grows() -> None:
    points = grid_patch((0.0, 0.2), (0.0, 0.2))
    zeros = np.zeros(len(points), np.uint8)
    grown = regrow(points, zeros, zeros.astype(np.int32), r1_m={})
    assert len(grown.regrown) == 0
    assert (grown.labels == 0).all()
