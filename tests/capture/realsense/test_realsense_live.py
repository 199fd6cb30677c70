"""The live `record` path over a pyrealsense2 software device: frames, drops, restarts, signals."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from helpers_capture import (
    COLOR_H,
    COLOR_W,
    DEPTH_H,
    DEPTH_W,
    ROOT,
    SoftCamera,
    color_image,
    depth_image,
    expected_extrinsics,
    expected_intrinsics,
)

from capture.errors import CameraError, CaptureError
from capture.realsense.record import record
from capture.realsense.session import RecordConfig, RecordResult, RecordStatus
from capture.realsense.sink import StreamFrame, ThreadedWriter
from capture.recording import RecordingReader, RecordingWriter

CONFIG = RecordConfig(
    width=COLOR_W, height=COLOR_H, depth_width=DEPTH_W, depth_height=DEPTH_H,
    frame_timeout_s=0.4, retries=1,
)  # fmt: skip


def _record(
    tmp_path: Path, indices: list[int], config: RecordConfig = CONFIG
) -> tuple[Path, RecordResult, list[RecordStatus]]:
    """Record a software camera that sends `indices`, then falls silent until given up."""
    cam = SoftCamera()
    go = threading.Event()
    feeder = cam.feed(indices, after=go)
    threading.Timer(0.2, go.set).start()
    statuses: list[RecordStatus] = []
    path = tmp_path / "live.mcap"
    result = record(path, config, device=cam.device, on_status=statuses.append)
    feeder.join()
    return path, result, statuses


def test_live_frames_are_written_exactly_with_their_calibration(tmp_path: Path) -> None:
    path, result, statuses = _record(tmp_path, list(range(40)))
    assert result.frames_written == {"color": 40, "depth": 40}
    assert result.frames_dropped == {"color": 0, "depth": 0}
    with RecordingReader(path) as rec:
        assert rec.finished and not rec.aligned
        frames = list(rec.frames())
        device, capture = rec.metadata["device"], rec.metadata["capture"]
    assert len(frames) == 40
    for i, frame in enumerate(frames):
        np.testing.assert_array_equal(frame.color, color_image(i))
        np.testing.assert_array_equal(np.rint(frame.depth_m * 1000.0), depth_image(i))
        assert frame.color_intrinsics == expected_intrinsics("color")
        assert frame.depth_intrinsics == expected_intrinsics("depth")
        assert frame.metadata["timestamp_domain"] == "global_time"
    assert frames[0].depth_to_color is not None
    np.testing.assert_allclose(
        frames[0].depth_to_color.color_from_depth, expected_extrinsics().color_from_depth, atol=1e-7
    )
    assert device["serial_number"] == "000123456789" and device["product_line"] == "D400"
    assert json.loads(capture["config"])["width"] == COLOR_W
    assert json.loads(capture["frames_written"]) == {"color": 40, "depth": 40}
    assert statuses and statuses[0].fps > 10.0 and statuses[-1].dropped == 0


def test_frame_number_gaps_are_counted_as_drops(tmp_path: Path) -> None:
    path, result, _ = _record(tmp_path, [0, 1, 2, 5, 6, 7, 8, 12])
    assert result.frames_written == {"color": 8, "depth": 8}
    assert result.frames_dropped == {"color": 5, "depth": 5}
    with RecordingReader(path) as rec:
        capture = rec.metadata["capture"]
        assert len(list(rec.frames())) == 8
    assert json.loads(capture["dropped_by_camera"]) == {"color": 5, "depth": 5}
    assert json.loads(capture["frames_dropped"]) == {"color": 5, "depth": 5}


def test_a_silent_camera_is_restarted_then_given_up_with_a_finished_file(tmp_path: Path) -> None:
    config = replace(CONFIG, retries=2, frame_timeout_s=0.3)
    t0 = time.monotonic()
    path, result, _ = _record(tmp_path, list(range(5)), config)
    elapsed = time.monotonic() - t0
    assert result.camera_lost
    assert result.stop_reason == "camera lost (no frame for 0.3 s after 2 restarts)"
    assert elapsed >= 3 * 0.3  # it waited out the timeout three times
    with RecordingReader(path) as rec:
        assert rec.finished and len(list(rec.frames())) == 5


def test_duration_ends_the_recording(tmp_path: Path) -> None:
    config = replace(CONFIG, duration_s=0.6)
    _, result, _ = _record(tmp_path, list(range(60)), config)
    assert result.stop_reason == "duration"
    written = result.frames_written["color"]
    assert 5 <= written < 60


def test_aligned_depth_is_in_the_colour_camera(tmp_path: Path) -> None:
    config = replace(CONFIG, align=True)
    path, _, _ = _record(tmp_path, list(range(20)), config)
    with RecordingReader(path) as rec:
        assert rec.aligned
        frames = list(rec.frames())
    assert len(frames) >= 15  # a syncer may let the first frames go unmatched
    for frame in frames:
        i = int(frame.metadata["frame_number"])
        np.testing.assert_array_equal(frame.color, color_image(i))
        assert frame.depth_m.shape == (COLOR_H, COLOR_W)
        assert frame.depth_intrinsics == expected_intrinsics("color")
        # Alignment moves depth values, it does not change them.
        moved = np.rint(frame.depth_m[frame.depth_m > 0] * 1000.0).astype(np.uint16)
        assert moved.size > COLOR_H * COLOR_W // 4
        assert np.isin(moved, depth_image(i)).all()


def test_a_mode_the_camera_lacks_is_refused_with_what_it_offers(tmp_path: Path) -> None:
    config = replace(CONFIG, width=1280, height=720)
    with pytest.raises(
        CameraError, match=r"no color stream 1280x720@30 rgb8; the device offers: 96x72@30 rgb8"
    ):
        record(tmp_path / "x.mcap", config, device=SoftCamera().device)
    with pytest.raises(CameraError, match="this camera has no depth presets"):
        record(tmp_path / "x.mcap", replace(CONFIG, preset="High Accuracy"),
               device=SoftCamera().device)  # fmt: skip
    with pytest.raises(CaptureError, match=r"invalid record settings \(sizes and rates"):
        RecordConfig(fps=0)


def test_a_full_queue_drops_and_counts_instead_of_blocking(tmp_path: Path) -> None:
    k = expected_intrinsics("color")
    with RecordingWriter(tmp_path / "q.mcap") as writer:
        sink = ThreadedWriter(writer, color_intrinsics=k, depth_intrinsics=k, queue_size=2)
        image = color_image(0)
        accepted = [sink.submit(StreamFrame("color", i, i, i, image)) for i in range(5)]
        assert accepted == [True, True, False, False, False]  # the writer thread is not running
        assert not sink.submit(StreamFrame("color", 4, 4, 4, image))  # a repeated frame number
        sink.start()
        stats = sink.stop()
    assert stats.written == {"color": 2, "depth": 0}
    assert stats.dropped_by_queue == {"color": 3, "depth": 0}
    assert stats.dropped_by_camera == {"color": 0, "depth": 0}


def test_sigterm_finishes_the_file(tmp_path: Path) -> None:
    out = tmp_path / "term.mcap"
    env = {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{ROOT / 'tests'}"}
    helper = ROOT / "tests" / "helpers_capture.py"
    child = subprocess.Popen(
        [sys.executable, str(helper), "record-until-signal", str(out)],
        stdout=subprocess.PIPE, text=True, env=env,
    )  # fmt: skip
    assert child.stdout is not None
    assert child.stdout.readline().strip() == "recording"
    time.sleep(1.0)
    child.send_signal(signal.SIGTERM)
    reason, count = child.stdout.readline().split()
    assert child.wait(20) == 0
    assert reason == "stopped" and int(count) >= 10
    with RecordingReader(out) as rec:
        assert rec.finished
        assert json.loads(rec.metadata["capture"]["frames_written"])["color"] == int(count)
        assert len(list(rec.frames())) == int(count)
