"""Recordings of other writers replay through our reader; other readers accept our recordings."""

from __future__ import annotations

import itertools
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from helpers_capture import SoftCamera

from capture.errors import RecordingError
from capture.recording import RecordingReader, RecordingWriter

ICL_MCAP = "icl_nuim/icl_nuim_5frames.mcap"


def _rerun() -> str:
    exe = Path(sys.executable).with_name("rerun")
    found = str(exe) if exe.is_file() else shutil.which("rerun")
    if found is None:
        pytest.skip("the rerun CLI of rerun-sdk is not installed")
    return found


def test_independent_realsense_ros_recording_replays(shared_data: Path) -> None:
    with RecordingReader(shared_data / ICL_MCAP) as rec:
        assert rec.aligned and rec.has_ground_truth and len(rec) == 5
        frames = list(rec.frames())
    assert len(frames) == 5
    for i, frame in enumerate(frames):
        png = np.asarray(cv2.imread(str(shared_data / "icl_nuim" / "depth" / f"{i:05d}.png"), -1))
        jpg = np.asarray(cv2.imread(str(shared_data / "icl_nuim" / "color" / f"{i:05d}.jpg")))
        np.testing.assert_array_equal(frame.depth_m, png.astype(np.float32) * np.float32(0.001))
        assert frame.color.shape == (480, 640, 3)
        # The other writer stored the decoded JPEG: the same pixels up to decoder rounding.
        assert np.abs(frame.color.astype(int) - jpg[..., ::-1].astype(int)).mean() < 1.0
        k = frame.color_intrinsics
        assert (k.fx, k.fy, k.cx, k.cy) == (525.0, 525.0, 319.5, 239.5)
        assert frame.ground_truth is not None and frame.ground_truth.world_from_camera is not None
    assert [f.index for f in frames] == [0, 1, 2, 3, 4]
    assert all(b.stamp_ns > a.stamp_ns for a, b in itertools.pairwise(frames))


def test_a_robot_recording_without_images_is_refused_in_one_line(shared_data: Path) -> None:
    path = shared_data / "ros2_other" / "nav2_turtlebot.mcap"
    with pytest.raises(RecordingError) as info:
        RecordingReader(path).open()
    text = str(info.value)
    assert "\n" not in text and text.endswith(str(path))
    assert text.startswith("no colour topic")
    assert "found: /odom (nav_msgs/msg/Odometry), /tf (tf2_msgs/msg/TFMessage)" in text


def _check(rerun: str, path: Path) -> str:
    done = subprocess.run(
        [rerun, "mcap", "check", "--full", str(path)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    return done.stdout


def test_rerun_checks_our_recordings(recording: Path, tmp_path: Path) -> None:
    rerun = _rerun()
    out = _check(rerun, recording)
    assert "/camera/camera/depth/image_rect_raw" in out and "ok" in out
    jpeg = tmp_path / "jpeg.mcap"
    with (
        RecordingWriter(jpeg, color_jpeg=True, compression="lz4") as w,
        RecordingReader(recording) as rec,
    ):
        for frame in rec.frames():
            w.write_frame(frame)
    assert "/camera/camera/color/image_raw/compressed" in _check(rerun, jpeg)


def test_rerun_checks_a_converted_realsense_file(tmp_path: Path) -> None:
    from capture.realsense.record import convert

    rerun = _rerun()
    SoftCamera().record_file(tmp_path / "cam.db3", 3)
    convert(tmp_path / "cam.db3", tmp_path / "cam.mcap")
    out = _check(rerun, tmp_path / "cam.mcap")
    assert "/camera/camera/color/metadata" in out


def test_rerun_refuses_a_broken_file(tmp_path: Path, recording: Path) -> None:
    rerun = _rerun()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(recording.read_bytes()[:5000])
    done = subprocess.run([rerun, "mcap", "check", str(cut)], capture_output=True, timeout=60)
    assert done.returncode != 0  # so the checks above can fail
