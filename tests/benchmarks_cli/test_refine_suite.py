"""The refinement's test-cloud suite: 58 named clouds, cached once, settings from --set."""

from __future__ import annotations

from functools import partial
from pathlib import Path

import numpy as np
import pytest

from benchmarks import refine_suite
from benchmarks.ceiling import majority_ceiling
from benchmarks.refine_suite import Case, cases, held_out, load, recordings
from capture.recording import Label
from process.cloud import LabelledCloud
from process.refine import RefineConfig


def test_the_suite_names_fifty_eight_clouds_of_every_generator() -> None:
    names = list(cases())
    assert len(names) == len(set(names)) == 58
    groups = {name.split()[0] for name in names}
    assert groups == {"g1", "tsdf", "g2", "g3", "g4", "g5", "rec"}


def _case(up: np.ndarray | None) -> Case:
    rng = np.random.default_rng(0)
    points = rng.normal(size=(50, 3)).astype(np.float32)
    labels = rng.integers(0, 11, 50).astype(np.uint8)
    cloud = LabelledCloud(points, np.zeros((50, 3), np.uint8), labels)
    return Case(cloud, np.full(50, Label.CHAIR, np.uint8), up)


@pytest.mark.parametrize("up", [None, np.array([0.0, 0.6, 0.8])])
def test_a_cloud_is_made_once_and_read_back_whole(tmp_path: Path, up: np.ndarray | None) -> None:
    made = []

    def make() -> Case:
        made.append(1)
        return _case(up)

    first, again = load("x y", make, tmp_path), load("x y", make, tmp_path)
    assert len(made) == 1 and [p.name for p in tmp_path.iterdir()] == ["x_y.npz"]
    for case in (first, again):
        np.testing.assert_array_equal(case.cloud.points, _case(up).cloud.points)
        np.testing.assert_array_equal(case.cloud.labels, _case(up).cloud.labels)
        np.testing.assert_array_equal(case.truth, _case(up).truth)
        assert (case.up is None) == (up is None)
        if up is not None:
            assert case.up is not None
            np.testing.assert_allclose(case.up, up)


def test_set_takes_the_fields_type_and_refuses_an_unknown_field() -> None:
    cfg = RefineConfig()
    assert refine_suite._field(cfg, "piece_vote=false") == ("piece_vote", False)
    assert refine_suite._field(cfg, "seam_vote_m=0.05") == ("seam_vote_m", 0.05)
    assert refine_suite._field(cfg, "min_cluster_points=12") == ("min_cluster_points", 12)
    with pytest.raises(SystemExit, match="no field 'nope'"):
        refine_suite._field(cfg, "nope=1")
    with pytest.raises(SystemExit, match=r"seam_vote_m expects float .* got 'abc'"):
        refine_suite._field(cfg, "seam_vote_m=abc")
    with pytest.raises(SystemExit, match=r"piece_vote expects true or false .* got 'flase'"):
        refine_suite._field(cfg, "piece_vote=flase")


def test_set_out_of_range_is_a_one_line_error() -> None:
    with pytest.raises(SystemExit, match=r"--set: refinement.seam_vote_m must be in 0.0..1.0"):
        refine_suite.main(["--set", "seam_vote_m=-1", "--only", "no such cloud"])


def test_the_held_out_clouds_share_no_seed_with_the_suite() -> None:
    held = held_out()
    assert len(held) == len(set(held)) == 152

    def seed(
        name: str,
    ) -> tuple[str, int]:  # (generator, seed): "g4 60k office 200", "rec seed 20 300f"
        words = name.split()
        return words[0], int(words[2] if words[0] == "rec" else words[-1])

    seeds = {seed(name) for name in held}
    tuned = set()
    for name, make in cases().items():
        if name.split()[0] in ("g2", "g3", "g4", "g5", "rec"):
            assert isinstance(make, partial)
            tuned.add((name.split()[0], make.args[0]))
    assert len(tuned) == 14 + 8 + 12 + 8 + 5 and not seeds & tuned
    groups = {refine_suite._group(n) for n in held}
    assert groups == {"g2", "g3", "g4 60k", "g4 200k", "g4 500k", "g5 60k", "g5 200k", "rec"}
    assert refine_suite._group("g4 office 60k") == "g4"  # the suite's g4 line stays one
    assert refine_suite._group("g5 seed 3 200k") == "g5"


def test_the_forty_recordings_share_no_seed_with_the_suite_or_the_held_out_ones() -> None:
    """`--recordings`: seeds 60-99, one summary line, none of the suite's or held-out seeds."""
    made = recordings()
    assert len(made) == 40 and {refine_suite._group(n) for n in made} == {"rec"}
    seeds = {make.args[0] for make in made.values() if isinstance(make, partial)}
    assert seeds == set(range(60, 100))
    others = {**cases(), **held_out()}
    other = {m.args[0] for n, m in others.items() if n.startswith("rec") and isinstance(m, partial)}
    assert other == {7, 8, 9, 12, 13, *range(20, 28)} and not seeds & other


def test_held_out_and_recordings_are_one_or_the_other(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        refine_suite.main(["--held-out", "--recordings", "--only", "no such cloud"])
    assert "not allowed with argument" in capsys.readouterr().err


def test_a_groups_line_counts_the_clouds_at_095_and_those_gaining_005() -> None:
    pairs = [(0.80, 0.96), (0.93, 0.96), (0.90, 0.94), (0.88, 0.955)]  # (phase I, phase III)
    line = refine_suite._summary("rec", [(i, iii, None) for i, iii in pairs])
    assert line == "rec: mean III 0.954, 3 of 4 >= 0.95, 2 >= I + 0.05"  # not 0.90 -> 0.94
    # with --ceiling: the second cloud's ceiling is 0.04 over its phase I, +0.05 cannot be
    ceilings = [0.99, 0.97, 0.98, 0.96]
    line = refine_suite._summary("rec", [(*p, c) for p, c in zip(pairs, ceilings, strict=True)])
    assert line.endswith("2 >= I + 0.05 (3 of 4 have a ceiling >= I + 0.05)")


def _blobs() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Three chairs' and a sofa's worth of points 1 m apart: a chair 70 % right, a sofa the
    network calls chair on most of its points, a chair it missed whole, chair labels on a wall."""
    grid = np.stack(np.meshgrid(np.arange(10), np.arange(10)), -1).reshape(-1, 2) * 0.01
    blob = np.column_stack([grid, np.zeros(100)])
    points = np.concatenate([blob + np.array([x, 0.0, 0.0]) for x in (0.0, 1.0, 2.0, 3.0)])
    truth = np.repeat(np.array([Label.CHAIR, Label.SOFA, Label.CHAIR, Label.WALL], np.uint8), 100)
    labels = np.zeros(400, np.uint8)
    labels[:70], labels[70:100] = Label.CHAIR, Label.SOFA
    labels[100:160] = Label.CHAIR  # the sofa, 40 of its points unlabelled
    labels[300:320] = Label.CHAIR  # on the wall
    return points, labels, truth


def test_the_ceiling_gives_each_true_object_its_majority_and_leaves_the_rest() -> None:
    """The first chair keeps its class whole, the sofa becomes chair whole, the missed chair
    stays unlabelled, the wall loses its chair labels: TP 100, FP 100, FN 200."""
    points, labels, truth = _blobs()
    assert majority_ceiling(points, labels, truth) == pytest.approx(200 / 500)
    assert majority_ceiling(points, truth, truth) == pytest.approx(1.0)


def test_ceiling_prints_each_clouds_ceiling_beside_its_phases(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    points, labels, truth = _blobs()
    cloud = LabelledCloud(points.astype(np.float32), np.zeros((400, 3), np.uint8), labels)
    monkeypatch.setattr(refine_suite, "cases", lambda: {"blobs": lambda: Case(cloud, truth, None)})
    assert refine_suite.main(["--cache", str(tmp_path), "--ceiling"]) == 0
    line = capsys.readouterr().out.splitlines()[0]
    assert line.startswith("blobs") and line.endswith("ceiling 0.4000")
