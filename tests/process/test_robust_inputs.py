"""Plausible but bad camera data: a one-line error for impossible calibration, else a warning."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from helpers_robust import FRAMES, Case, write_case
from typer.testing import CliRunner

from capture.recording import RecordingReader
from process import outputs
from process.cli import app

runner = CliRunner()


def _run(path: Path, out: Path) -> tuple[int, list[str], dict[str, object]]:
    args = ["run", str(path), "--out", str(out), "--stages", "odometry", "--no-viz"]
    result = runner.invoke(app, args)
    errors = [ln for ln in result.stderr.splitlines() if ln.startswith("error:")]
    metrics_path = out / outputs.METRICS
    metrics = json.loads(metrics_path.read_text()) if metrics_path.exists() else {}
    assert result.exception is None or isinstance(result.exception, SystemExit), result.output
    return result.exit_code, errors, metrics


@pytest.mark.parametrize(
    ("case", "expected"),
    [
        (Case(fx=float("nan")), "non-finite intrinsics"),
        (Case(fx=float("inf")), "non-finite intrinsics"),
        (Case(fx=0.0), "focal length fx 0.0"),
        (Case(fx=-60.0), "focal length fx -60.0"),
        (Case(size=(1, 1)), "image size 1x1"),
        (Case(extrinsics_translation=(float("nan"), 0.0, 0.0)), "non-finite depth-to-colour"),
        (Case(depth_offset_ns=1_000_000_000), "no colour frame had a depth frame within 20 ms"),
    ],
    ids=["nan-fx", "inf-fx", "zero-fx", "negative-fx", "1x1", "nan-extrinsics", "no-pairs"],
)
def test_impossible_data_is_one_line_naming_the_cause(
    case: Case, expected: str, tmp_path: Path
) -> None:
    path = write_case(tmp_path / "bad.mcap", case)
    code, errors, _ = _run(path, tmp_path / "out")
    assert code == 1
    assert len(errors) == 1 and expected in errors[0], errors
    assert list((tmp_path / "out").iterdir()) == []


@pytest.mark.parametrize(
    ("case", "frames", "warning"),
    [
        (Case(zero_depth_frames=3), FRAMES, "3 of 8 frame(s) have no valid depth pixel"),
        (Case(nan_depth_32f=True), FRAMES, "8 of 8 frame(s) have no valid depth pixel"),
        (Case(quaternion=(0.0, 0.0, 0.0, 0.0)), FRAMES, "8 invalid ground-truth pose(s)"),
        (Case(quaternion=(float("nan"), 0, 0, 1)), FRAMES, "8 invalid ground-truth pose(s)"),
        (Case(same_stamps=True), 1, "7 colour frame(s) with a stamp not after the previous"),
        (Case(duplicate_messages=True), FRAMES, "8 colour frame(s) with a stamp not after"),
    ],
    ids=["zero-depth-start", "nan-depth", "zero-quat", "nan-quat", "same-stamps", "duplicates"],
)
def test_bad_frames_are_skipped_and_said_in_metrics(
    case: Case, frames: int, warning: str, tmp_path: Path
) -> None:
    path = write_case(tmp_path / "odd.mcap", case)
    code, errors, metrics = _run(path, tmp_path / "out")
    assert code == 0, errors
    assert metrics["odometry"]["frames"] == frames  # type: ignore[index]
    warnings = metrics["warnings"]
    assert isinstance(warnings, list) and any(warning in w for w in warnings), warnings


def test_the_reader_keeps_warnings_for_the_rrd(tmp_path: Path) -> None:
    path = write_case(tmp_path / "odd.mcap", Case(zero_depth_frames=2))
    with RecordingReader(path) as rec:
        assert len(list(rec.frames())) == FRAMES
        assert any("2 of 8 frame(s) have no valid depth pixel" in w for w in rec.warnings)


@pytest.mark.parametrize("scale", ["\x13.001", "nan", "-1", "0"])
def test_a_corrupt_depth_scale_is_said_and_the_default_used(tmp_path: Path, scale: str) -> None:
    from capture.recording import RecordingWriter

    path = write_case(tmp_path / "rec.mcap", Case())
    scaled = tmp_path / "scaled.mcap"
    with RecordingReader(path) as rec, RecordingWriter(scaled) as writer:
        writer.write_metadata("device", {"depth_scale_m": scale})
        writer.write_calibration(next(rec.frames()).depth_to_color, stamp_ns=1)  # type: ignore[arg-type]
        for frame in rec.frames():
            writer.write_frame(frame)
    with RecordingReader(scaled) as rec:
        depths = [float(f.depth_m.max()) for f in rec.frames()]
        assert depths == [2.0] * FRAMES
        assert any("depth_scale_m" in w and "using 0.001" in w for w in rec.warnings)


@pytest.mark.parametrize(
    ("case", "warning"),
    [
        (Case(nan_depth_32f=True), "8 of 8 frame(s) have no valid depth pixel"),
        (Case(same_stamps=True), "7 colour frame(s) with a stamp not after the previous"),
    ],
    ids=["nan-depth", "same-stamps"],
)
def test_every_stage_runs_on_odd_data_and_the_rrd_says_why(
    case: Case, warning: str, tmp_path: Path
) -> None:
    from helpers_viz import read_rrd

    path = write_case(tmp_path / "odd.mcap", case)
    out = tmp_path / "out"
    result = runner.invoke(app, ["run", str(path), "--out", str(out)])
    assert result.exit_code == 0, result.output
    texts = [str(t) for t in read_rrd(out / outputs.RRD).column("/logs", "TextLog:text")]
    assert any(warning in t for t in texts), texts
    assert any(warning in w for w in json.loads((out / outputs.METRICS).read_text())["warnings"])
