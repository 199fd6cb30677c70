"""Smoke tests of every `semreplay-capture` command through typer's CliRunner."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from conftest import write_synthetic_recording
from helpers_capture import ROOT, SoftCamera
from typer.testing import CliRunner

from capture.cli import app
from capture.recording import RecordingReader, RecordingWriter

runner = CliRunner()


def test_info_describes_a_finished_recording(recording: Path) -> None:
    result = runner.invoke(app, ["info", str(recording)])
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert lines[1] == "finished   yes"
    assert lines[2] == "frames     5 (depth raw, registered with the extrinsics)"
    assert lines[3] == "duration   0.133 s"  # 4 frame intervals of 33.3 ms
    assert "device     name=synthetic depth_scale_m=0.001" in lines
    assert any(line.split()[:3] == ["/ground_truth/pose", "geometry_msgs/msg/PoseStamped", "5"]
               for line in lines)  # fmt: skip


def test_info_says_how_much_an_unfinished_recording_recovered(
    recording: Path, tmp_path: Path
) -> None:
    cut = tmp_path / "cut.mcap"
    data = recording.read_bytes()
    cut.write_bytes(data[: len(data) * 3 // 4])
    result = runner.invoke(app, ["info", str(cut)])
    assert result.exit_code == 0, result.output
    assert "finished   no (writer killed?): recovered" in result.output


def test_convert_then_info(tmp_path: Path) -> None:
    SoftCamera().record_file(tmp_path / "cam.db3", 4)
    result = runner.invoke(app, ["convert", str(tmp_path / "cam.db3"), str(tmp_path / "c.mcap")])
    assert result.exit_code == 0, result.output
    assert (
        result.output.strip()
        == f"{tmp_path / 'c.mcap'}: color 4, depth 4 frames from {tmp_path / 'cam.db3'}"
    )
    info = runner.invoke(app, ["info", str(tmp_path / "c.mcap")])
    assert "dropped    color 0, depth 0" in info.output
    assert "serial_number=000123456789" in info.output


def test_import_a_redwood_folder(shared_data: Path, tmp_path: Path) -> None:
    out = tmp_path / "icl.mcap"
    args = ["import", "redwood", str(shared_data / "icl_nuim"), str(out), "--compression", "lz4"]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    with RecordingReader(out) as rec:
        assert len(rec) == 5


def test_simulate_writes_a_recording_with_ground_truth(tmp_path: Path) -> None:
    out = tmp_path / "sim.mcap"
    args = ["simulate", str(out), "--frames", "2", "--width", "64", "--height", "48", "--seed", "1"]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    with RecordingReader(out) as rec:
        assert len(rec) == 2 and rec.has_ground_truth


def test_record_without_a_camera_is_a_one_line_error(tmp_path: Path) -> None:
    out = tmp_path / "r.mcap"
    result = runner.invoke(app, ["record", str(out), "--serial", "no-such-serial"])
    assert result.exit_code == 1
    assert result.stderr.startswith("error: no RealSense camera")
    assert result.stderr.count("\n") == 1
    assert not out.exists()


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["info", "missing.mcap"], "error: cannot open recording: No such file or directory: "),
        (["convert", "missing.db3", "x.mcap"], "error: no such RealSense recording: "),
        (["import", "tum", "missing-folder", "x.mcap"], "error: "),
    ],
)
def test_bad_inputs_print_one_error_line(
    tmp_path: Path, args: list[str], expected: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    result = runner.invoke(app, args)
    assert result.exit_code == 1
    assert result.stderr.startswith(expected) and result.stderr.count("\n") == 1


def test_help_is_fast_and_ends_with_examples() -> None:
    done = subprocess.run(
        [sys.executable, "-X", "importtime", "-m", "capture", "record", "--help"],
        capture_output=True, text=True, cwd=ROOT, timeout=60, check=True,
    )  # fmt: skip
    assert "semreplay-capture record room.mcap --duration 30" in done.stdout
    imported = done.stderr
    assert " typer\n" in imported  # the -X importtime format this test reads
    for heavy in ("pyrealsense2", "cv2", "mcap", "numpy", "open3d", "torch"):
        assert f" {heavy}\n" not in imported and f" {heavy}." not in imported, heavy


def test_a_finished_recording_written_by_the_writer_reads_in_info(tmp_path: Path) -> None:
    path = tmp_path / "empty.mcap"
    with RecordingWriter(path):
        pass
    result = runner.invoke(app, ["info", str(path)])
    assert result.exit_code == 0
    assert "frames     none: no colour topic" in result.output


def test_info_lists_attachments(tmp_path: Path) -> None:
    path = write_synthetic_recording(tmp_path / "with_attachment.mcap", frames=2)
    with_cloud = tmp_path / "cloud.mcap"
    with RecordingReader(path) as rec, RecordingWriter(with_cloud) as writer:
        for frame in rec.frames():
            writer.write_frame(frame)
        writer.write_attachment(
            "ground_truth_cloud.ply", b"ply\n", media_type="text/plain", log_ns=1
        )
    plain = runner.invoke(app, ["info", str(path)])
    attached = runner.invoke(app, ["info", str(with_cloud)])
    assert "attached   nothing" in plain.output.splitlines()
    assert "attached   ground_truth_cloud.ply" in attached.output.splitlines()
