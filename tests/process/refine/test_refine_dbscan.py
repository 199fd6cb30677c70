"""Adaptive DBSCAN: equal to the paper's equations computed literally (O(n^2), K = 1..n-1)."""

from __future__ import annotations

import numpy as np
import pytest
from helpers_refine import blobs, grid_patch, labelled, literal_dbscan, literal_parameters

from process.refine import RefineConfig, refine
from process.refine.dbscan import NeighbourTable, estimate_parameters
from process.refine.selection import stable_choice


@pytest.mark.parametrize(
    ("seed", "sizes"), [(0, (40, 40, 40)), (3, (60, 30)), (4, (25, 25, 25, 25))]
)
def test_chosen_parameters_equal_the_literal_reference(seed: int, sizes: tuple[int, ...]) -> None:
    points = blobs(seed, sizes=sizes)
    literal = literal_parameters(points)
    chosen = literal.chosen
    assert chosen is not None
    _, _, choice = estimate_parameters(points, k_max=len(points) - 1)
    assert choice.stable
    assert choice.k == chosen + 1
    assert choice.eps_m == pytest.approx(literal.eps[chosen], rel=1e-12)
    assert choice.min_pts == literal.min_pts[chosen]


def test_a_k_max_below_n_gives_the_same_choice_when_the_stable_run_ends_before_it() -> None:
    points = blobs(3, sizes=(60, 30))  # literal counts: 2 for K = 1..18, then 1
    literal = literal_parameters(points)
    _, curves, choice = estimate_parameters(points, k_max=20)
    assert literal.chosen is not None
    assert choice.k == literal.chosen + 1 == 18
    evaluated = curves.n_clusters[curves.n_clusters >= 0]
    assert list(evaluated) == literal.n_clusters[: len(evaluated)]


def test_whole_curves_equal_the_literal_ones_on_a_jittered_grid() -> None:
    rng = np.random.default_rng(5)
    points = grid_patch((0.0, 0.24), (0.0, 0.24), step=0.02).astype(np.float64)
    shift = np.array([0.5, 0.0, 0.0])
    points = np.concatenate([points, points[:40] + shift])  # a second, smaller piece
    points += rng.normal(0.0, 0.003, points.shape)
    literal = literal_parameters(points)
    _, curves, _ = estimate_parameters(points, k_max=40, full_curves=True)
    np.testing.assert_allclose(curves.eps_m, literal.eps[:40], rtol=1e-12)
    assert list(curves.min_pts) == literal.min_pts[:40]
    assert list(curves.n_clusters) == literal.n_clusters[:40]


def test_short_neighbour_lists_are_patched_to_exact_counts_and_clusters() -> None:
    points = blobs(1, sizes=(50, 50, 20), spread=0.04)
    literal = literal_parameters(points)
    eps = np.asarray(literal.eps[:30])
    table = NeighbourTable(points, k_query=6)  # most rows lie wholly within eps: cut short
    table.bind(eps)
    assert list(table.min_pts()) == literal.min_pts[:30]
    dist = np.sqrt(((points[:, None] - points[None]) ** 2).sum(axis=2))
    for k in (0, 9, 29):
        min_pts = int(table.min_pts()[k])
        reference = literal_dbscan(dist, float(eps[k]), min_pts)
        ours = table.labels(k, min_pts)
        assert ours.max() == reference.max()
        core = (dist <= eps[k]).sum(axis=1) >= min_pts
        pairs = {(int(a), int(b)) for a, b in zip(ours[core], reference[core], strict=True)}
        assert len(pairs) == len({a for a, _ in pairs})  # core partitions agree up to renaming
        assert ((ours >= 0) == (reference >= 0)).all()  # same noise points


def test_fallback_takes_the_largest_k_of_the_longest_run_and_says_so() -> None:
    index, stable, note = stable_choice(np.array([9, 7, 7, 5, 4, 4, 3, 2]))
    assert (index, stable) == (5, False)
    assert "fallback" in note
    index, stable, _ = stable_choice(np.array([0, 0, 0, 6, 5, 5, 5, 5, 4]))
    assert (index, stable) == (7, True)  # a run of zero clusters is no stable interval


def test_a_mislabelled_blob_is_relabelled_zero() -> None:
    chair = grid_patch((0.0, 0.6), (0.0, 0.6), z=0.45)  # 900 points of chair
    blob = grid_patch((2.0, 2.1), (0.0, 0.1), z=0.45)  # 25 points called "chair", 1.4 m away
    cloud = labelled(np.concatenate([chair, blob]), 5)
    cfg = RefineConfig(plane_min_points=10**6, min_cluster_points=50, k_max=20)
    result = refine(cloud, cfg, up=np.array([0.0, 0.0, 1.0]))
    assert (result.labels_ii[len(chair) :] == 0).all()
    assert (result.labels_iii[len(chair) :] == 0).all()  # too far for regrowth
    assert (result.labels_ii[: len(chair)] == 5).mean() > 0.95
    assert result.dbscan[5].clusters == 1
