"""`process run --follow`: a recording processed while another process writes it at camera speed."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from capture.recording import RecordingReader
from process import outputs

ROOT = Path(__file__).resolve().parents[2]


def _follower(live: Path, out: Path, *extra: str) -> subprocess.Popen[str]:
    args = [sys.executable, "-m", "process", "run", str(live), "--out", str(out), "--follow"]
    args += ["--stages", "odometry", "--follow-idle", "20", *extra]
    follower = subprocess.Popen(args, cwd=ROOT, stderr=subprocess.PIPE, text=True)
    assert follower.stderr is not None
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:  # start writing once the follower waits for frames
        line = follower.stderr.readline()
        if line.startswith("following"):
            return follower
        assert line or follower.poll() is None, "the follower ended before following"
    pytest.fail("the follower never said it was following")


def _writer(src: Path, live: Path, speed: float) -> subprocess.Popen[str]:
    args = [sys.executable, "-m", "benchmarks.live_writer", str(src), str(live)]
    return subprocess.Popen([*args, "--speed", str(speed)], cwd=ROOT, text=True)


@pytest.mark.slow
def test_follow_processes_every_frame_as_written_and_ends_with_the_capture(
    sim_recording: Path, tmp_path: Path
) -> None:
    live, out = tmp_path / "live.mcap", tmp_path / "out"
    every_frame = tmp_path / "every_frame.toml"  # a loaded machine must not drop frames here
    every_frame.write_text("[follow]\nmax_lag_s = 0\n")
    follower = _follower(live, out, "--no-viz", "--config", str(every_frame))
    # 30 frames over 4 s: at 2 s a loaded machine's follower once first opened the file after the
    # writer had finished it, and a finished recording is read as a file, not followed
    writer = _writer(sim_recording, live, speed=0.25)
    assert writer.wait(timeout=120) == 0
    assert follower.wait(timeout=120) == 0
    metrics = json.loads((out / outputs.METRICS).read_text())
    with RecordingReader(live) as rec:
        assert rec.finished and metrics["odometry"]["frames"] == len(rec) == 30
    lag = metrics["follow"]
    assert 0 < lag["lag_s_median"] <= lag["lag_s_max"] < 10  # seconds behind the writer
    assert lag["keyframes_skipped"] == 0  # odometry only: no keyframe waits for segmentation


@pytest.mark.slow
def test_ctrl_c_stops_following_and_finishes_with_the_frames_so_far(
    sim_recording: Path, tmp_path: Path
) -> None:
    live, out = tmp_path / "live.mcap", tmp_path / "out"
    follower = _follower(live, out, "--no-viz")
    writer = _writer(sim_recording, live, speed=0.2)  # 5 s of camera time per second of it
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and not (live.exists() and live.stat().st_size > 1e6):
        time.sleep(0.1)
    time.sleep(2.0)
    follower.send_signal(signal.SIGINT)
    assert follower.wait(timeout=120) == 0
    writer.kill()
    writer.wait()
    frames = json.loads((out / outputs.METRICS).read_text())["odometry"]["frames"]
    assert 0 < frames < 30
    assert sorted(p.name for p in out.iterdir()) == sorted(
        [outputs.CONFIG, outputs.METRICS, outputs.TRAJECTORY]
    )


@pytest.mark.slow
def test_serve_streams_to_viewers_on_a_local_port_while_following(tmp_path: Path) -> None:
    with socket.socket() as probe:  # a free port on this machine
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    live, out = tmp_path / "live.mcap", tmp_path / "out"
    args = ["--serve", "--port", str(port)]
    follower = _follower(live, out, *args, "--follow-idle", "3")
    with socket.create_connection(("127.0.0.1", port), timeout=10):
        pass  # a viewer can connect while the capture has not even started
    assert follower.wait(timeout=120) != 0  # no capture came: one line, nothing half-written
    assert follower.stderr is not None
    assert "found no complete frame topics" in follower.stderr.read()
    assert not out.exists() or outputs.RRD not in [p.name for p in out.iterdir()]


@pytest.mark.parametrize(
    ("max_lag_s", "min_tracked_hz", "every"), [(1.2, 10.0, 3), (1.2, 15.0, 2), (0.0, 10.0, 1)]
)
def test_following_drops_late_frames_but_tracks_at_min_tracked_hz(
    sim_recording: Path, tmp_path: Path, max_lag_s: float, min_tracked_hz: float, every: int
) -> None:
    """A capture still being written whose frames were taken long ago: every frame is late.

    At 30 frames/s, 10 Hz keeps every 3rd frame (100 ms apart) and 15 Hz every 2nd; max_lag_s 0
    drops nothing.
    """
    from capture.recording import RecordingWriter
    from process.config import FollowConfig, ReplayConfig
    from process.job import run_recording
    from process.odometry.config import OdometryConfig
    from process.trajectory import read_tum

    live = tmp_path / "unfinished.mcap"
    with RecordingReader(sim_recording) as rec:
        writer = RecordingWriter(live)
        for frame in rec.frames():
            if frame.index == 0 and frame.depth_to_color is not None:
                writer.write_calibration(frame.depth_to_color, stamp_ns=frame.stamp_ns)
            writer.write_frame(frame)
        writer.flush()
        writer.close_unfinished()  # no end-of-capture record: the capture goes on
        stamps = [f.stamp_ns for f in rec.frames()]
    readout = 0.01 * every  # a config value wins over the recording's (a simulator: none)
    cfg = ReplayConfig(
        odometry=OdometryConfig(rolling_shutter_readout_s=readout),
        follow=FollowConfig(max_lag_s=max_lag_s, min_tracked_hz=min_tracked_hz),
    )
    out = tmp_path / "out"
    result = run_recording(
        live, out, cfg=cfg, stages=("odometry",), no_viz=True, progress=False,
        follow_idle_s=1.0,
    )  # fmt: skip
    kept = stamps[::every]
    assert result.metrics["odometry"]["frames"] == len(kept)
    assert result.metrics["follow"]["frames_dropped"] == len(stamps) - len(kept)
    assert read_tum(out / outputs.TRAJECTORY).stamps_ns.tolist() == kept
    assert result.metrics["odometry"]["rolling_shutter_readout_s"] == readout
