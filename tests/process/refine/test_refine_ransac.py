"""RANSAC plane hypotheses (process/refine/ransac.py): known planes, counts and seeds."""

from __future__ import annotations

import numpy as np
import pytest

from process.refine.ransac import best_plane, inlier_counts, uniform_planes


def _floor_and_clutter(rng: np.random.Generator) -> np.ndarray:
    floor = np.column_stack([rng.uniform(0, 4, (6000, 2)), rng.normal(0.0, 0.003, 6000)])
    clutter = rng.uniform([0, 0, 0.1], [4, 4, 2.0], (4000, 3))
    return np.concatenate([floor, clutter]).astype(np.float32)


def test_three_points_give_their_plane_and_a_line_gives_none() -> None:
    sample = np.array([[0, 0, 1], [1, 0, 1], [0, 1, 1], [2, 2, 2], [3, 3, 3]], np.float32)
    rng = np.random.default_rng(0)
    planes = uniform_planes(sample, 400, rng)
    assert 0 < len(planes) < 400  # draws of a repeated point or of a line are dropped
    np.testing.assert_allclose(np.linalg.norm(planes[:, :3], axis=1), 1.0, atol=1e-9)
    ones = (np.abs(planes[:, 2]) > 1 - 1e-9) & np.isclose(np.abs(planes[:, 3]), 1.0)
    assert ones.any()  # z = 1 through the first three
    # every plane passes through the three points it was drawn from: all lie within 1e-6 of
    # at least three of the five
    distance = np.abs(sample @ planes[:, :3].T + planes[:, 3])
    assert ((distance < 1e-6).sum(axis=0) >= 3).all()


def test_inlier_counts_are_exact_across_chunks() -> None:
    points = np.zeros((7, 3), np.float32)
    points[:, 2] = [0.0, 0.01, 0.019, 0.021, -0.015, 0.5, -2.0]
    models = np.tile([0.0, 0.0, 1.0, 0.0], (600, 1))  # z = 0, over several 64-plane chunks
    models[300:, 3] = -0.5  # z = 0.5
    counts = inlier_counts(points, models, 0.02)
    assert (counts[:300] == 4).all()  # 0, 0.01, 0.019, -0.015
    assert (counts[300:] == 1).all()


def test_the_dominant_plane_is_found_and_the_seed_alone_decides() -> None:
    points = _floor_and_clutter(np.random.default_rng(1))
    model, count = best_plane(
        points, uniform=300, local=300, distance_m=0.02, rng=np.random.default_rng(5)
    )
    assert abs(model[2]) > np.cos(np.radians(1.0)) and abs(model[3]) < 0.01
    assert 6000 <= count <= 6000 + 60  # the floor and the few clutter points within 2 cm
    again = best_plane(
        points, uniform=300, local=300, distance_m=0.02, rng=np.random.default_rng(5)
    )
    np.testing.assert_array_equal(again[0], model)


def test_uniform_draws_alone_find_it_too_and_no_hypothesis_is_an_error() -> None:
    points = _floor_and_clutter(np.random.default_rng(2))
    model, count = best_plane(
        points, uniform=300, local=0, distance_m=0.02, rng=np.random.default_rng(0)
    )
    assert abs(model[2]) > np.cos(np.radians(3.0)) and count > 5000
    with pytest.raises(ValueError, match="3 points"):
        best_plane(points[:2], uniform=10, local=10, distance_m=0.02, rng=np.random.default_rng())
    with pytest.raises(ValueError, match="at least one hypothesis"):
        best_plane(points, uniform=0, local=0, distance_m=0.02, rng=np.random.default_rng())


def test_preemptive_scoring_keeps_the_plane_all_hypotheses_scored_in_full_give(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """On a sample of 20,000 points the hypotheses are scored on an even tenth first and the
    best 64 on all of it: the same plane and count as scoring all 600 on every point."""
    import process.refine.ransac as ransac

    rng = np.random.default_rng(5)
    sample = np.concatenate([_floor_and_clutter(rng) for _ in range(2)])  # 20,000 points
    quick = best_plane(
        sample, uniform=300, local=300, distance_m=0.02, rng=np.random.default_rng(1)
    )
    monkeypatch.setattr(ransac, "_PRE_KEEP", 10**6)  # every hypothesis on every point
    full = best_plane(sample, uniform=300, local=300, distance_m=0.02, rng=np.random.default_rng(1))
    np.testing.assert_array_equal(quick[0], full[0])
    assert quick[1] == full[1] > 0.55 * len(sample)
