"""Generator 3 (benchmarks/generator3.py): deterministic, truthful, errors as parametrised.

The refinement's F1 on these clouds is bench_refine's job; here only phase III >= phase I on
one small cloud.
"""

from __future__ import annotations

from dataclasses import replace
from functools import cache

import numpy as np
import pytest
from scipy.spatial import cKDTree

from benchmarks.gen3_errors import BLEED, BLOB, FLYING, MISSED, SWAPPED, Gen3Errors
from benchmarks.generator3 import Gen3Scene, gen3_scene
from benchmarks.generator3 import main as gen3_main
from process.evaluate import label_metrics
from process.refine import RefineConfig, refine

SPACING_M = 0.03  # ~60k points: fast
NONE = Gen3Errors(miss_rate=0.0, bleed_share=0.0, blob_rate=0.0, swapped_objects=0, speckle=0.0)


@cache
def _scene(seed: int, errors: Gen3Errors = NONE, flying_rate: float = 0.0) -> Gen3Scene:
    return gen3_scene(seed=seed, spacing_m=SPACING_M, errors=errors, flying_rate=flying_rate)


def _with(**rates: float) -> Gen3Errors:
    values = {**NONE.__dict__, **rates}
    return Gen3Errors(**values)


def test_same_seed_same_cloud_other_seed_other_room() -> None:
    a, b = gen3_scene(seed=4, spacing_m=SPACING_M), gen3_scene(seed=4, spacing_m=SPACING_M)
    np.testing.assert_array_equal(a.cloud.points, b.cloud.points)
    np.testing.assert_array_equal(a.cloud.labels, b.cloud.labels)
    np.testing.assert_array_equal(a.truth, b.truth)
    other = gen3_scene(seed=5, spacing_m=SPACING_M)
    assert len(other.cloud) != len(a.cloud) or not np.array_equal(other.truth, a.truth)


def test_truth_is_the_item_each_point_came_from() -> None:
    scene = _scene(1)
    seen = np.unique(scene.instances)
    assert seen[0] > 0  # no flying pixels asked for
    np.testing.assert_array_equal(scene.truth, scene.item_labels[scene.instances])
    assert {1, 2, 3} <= set(scene.truth.tolist())  # ceiling, floor, walls
    placed_objects = np.flatnonzero(scene.item_labels >= 4)
    visible = np.isin(placed_objects, seen)
    assert visible.mean() > 0.8  # a few small things hide behind others
    assert set(scene.item_labels[placed_objects[visible]].tolist()) == set(
        scene.truth[scene.truth >= 4].tolist()
    )
    assert {4, 5, 9, 10} <= set(scene.truth.tolist())  # desks, chairs, monitors, clutter


def test_without_errors_phase_one_is_the_truth_on_objects() -> None:
    scene = _scene(2)
    np.testing.assert_array_equal(scene.cloud.labels, np.where(scene.truth >= 4, scene.truth, 0))
    assert not scene.errors.any()


@pytest.mark.parametrize("rate", [0.1, 0.3])
def test_missed_share_is_the_requested_rate(rate: float) -> None:
    scene = _scene(3, _with(miss_rate=rate))
    objects = scene.truth >= 4
    missed = scene.errors == MISSED
    assert not missed[~objects].any()
    assert (scene.cloud.labels[missed] == 0).all()
    assert abs(missed[objects].mean() - rate) < 0.03
    assert (scene.cloud.labels[objects & ~missed] == scene.truth[objects & ~missed]).all()


def test_bleed_points_lie_within_bleed_distance_of_that_class() -> None:
    bleed_m = 0.05
    scene = _scene(3, _with(bleed_share=0.6, bleed_m=bleed_m))
    bled = np.flatnonzero(scene.errors == BLEED)
    assert len(bled) > 100
    labels, points = scene.cloud.labels, scene.cloud.points
    assert (labels[bled] != scene.truth[bled]).all()
    for label in np.unique(labels[bled]):
        these = bled[labels[bled] == label]
        tree = cKDTree(points[scene.truth == label])
        dist, _ = tree.query(points[these])
        assert dist.max() <= bleed_m + 1e-5
    on_structure = np.isin(scene.truth[bled], (1, 2, 3)).mean()
    assert 0.1 < on_structure < 1.0  # onto floor and walls, and onto neighbouring objects


def test_blobs_and_swapped_objects() -> None:
    scene = _scene(1, _with(blob_rate=0.03, swapped_objects=2))
    objects = int((scene.truth >= 4).sum())
    blob = scene.errors == BLOB
    assert (scene.cloud.labels[blob] != scene.truth[blob]).all()
    assert (scene.cloud.labels[blob] >= 4).all()
    assert 0.03 * objects <= blob.sum() <= 0.03 * objects + 300  # overshoot: one blob
    swapped = scene.errors == SWAPPED
    ids = np.unique(scene.instances[swapped])
    assert len(ids) == 2
    for inst in ids:  # the whole object, one wrong class
        own = scene.instances == inst
        assert len(np.unique(scene.cloud.labels[own & ~blob])) == 1
        assert (scene.cloud.labels[own & swapped] != scene.truth[own & swapped]).all()


def test_defaults_make_every_family_and_flying_pixels_have_no_truth() -> None:
    scene = _scene(0, Gen3Errors(), 0.1)
    assert {0, 1, 2, 3, 4, 6} <= set(scene.errors.tolist())  # speckle can be rare at 3 cm
    flying = scene.errors == FLYING
    assert (scene.truth[flying] == 0).all()
    assert (scene.cloud.labels[flying] >= 4).all()


def test_bad_rate_or_spacing_is_refused() -> None:
    with pytest.raises(ValueError, match="miss_rate"):
        Gen3Errors(miss_rate=1.0)
    with pytest.raises(ValueError, match="spacing_m"):
        gen3_scene(spacing_m=0.001)


def test_refinement_does_not_lower_f1_on_a_small_cloud() -> None:
    scene = gen3_scene(seed=0, spacing_m=0.02)
    result = refine(scene.cloud, RefineConfig(), up=scene.up)
    f1 = {
        p: label_metrics(c.labels, scene.truth)["all"]["f1"]
        for p, c in result.phase_clouds().items()
    }
    assert f1["III"] >= f1["I"]


def test_switching_one_family_off_keeps_the_cloud_and_the_other_families() -> None:
    full, no_blobs = _scene(2, Gen3Errors()), _scene(2, replace(Gen3Errors(), blob_rate=0.0))
    np.testing.assert_array_equal(full.cloud.points, no_blobs.cloud.points)
    np.testing.assert_array_equal(full.errors == MISSED, no_blobs.errors == MISSED)
    assert (full.errors == BLOB).any() and not (no_blobs.errors == BLOB).any()


@pytest.mark.parametrize("argv", [["x"], ["0", "-1"]])
def test_the_command_refuses_bad_arguments_in_one_line(
    argv: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    assert gen3_main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("usage: python -m benchmarks.generator3") and err.count("\n") == 1
