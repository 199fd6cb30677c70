"""Real time on a real recording: the whole job on TUM fr1_rpy, scaling with cores, --follow lag.

TUM RGB-D `freiburg1_rpy` (../shared/data, 694 paired 640x480 frames, a real Kinect) goes through
`process run` with the `.rrd`, on every core and on one (taskset); the frames/s is the job's
own (metrics.json `job`, without the interpreter's start-up). The `--follow` lag runs a writer
that re-records a simulated recording at camera speed while `process run --follow` reads it.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.common import Row
from capture.sim import simulate_recording

AREA = "real time"
TUM = Path(__file__).resolve().parents[2] / "shared" / "data" / "tum_fr1_rpy"
CAMERA_FPS = 30.0


def run() -> list[Row]:
    """Return the whole-job frames/s on fr1_rpy per core count and the --follow lag."""
    rows: list[Row] = []
    with tempfile.TemporaryDirectory() as tmp:
        if TUM.is_dir():
            rec = Path(tmp) / "fr1_rpy.mcap"
            _python("capture", "import", "tum", str(TUM), str(rec))
            cores = sorted({1, os.cpu_count() or 1})
            for n in cores:
                job_fps, odometry_fps = _job(rec, Path(tmp) / f"out_{n}", cores=n)
                rows.append(_fps_row(f"whole job with .rrd, TUM fr1_rpy, {n} core(s)", job_fps))
                if n == cores[-1]:
                    what = "odometry alone (depth + tracking), TUM fr1_rpy, in the job"
                    rows.append(_fps_row(what, odometry_fps))
            rec.unlink()
        else:
            print(
                f"bench_realtime: {TUM} absent: the real-recording rows are skipped",
                file=sys.stderr,
            )
        rows.append(_follow_row(Path(tmp)))
    return rows


def _python(
    *args: str, cores: int | None = None, background: bool = False
) -> subprocess.Popen[str]:
    command = [sys.executable, "-m", *args]
    if cores is not None and shutil.which("taskset"):
        command = ["taskset", "-c", ",".join(str(c) for c in range(cores)), *command]
    child = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    if not background and child.wait() != 0:
        assert child.stderr is not None
        raise RuntimeError(f"{' '.join(command)} failed: {child.stderr.read().strip()[-300:]}")
    return child


def _job(rec: Path, out: Path, *, cores: int) -> tuple[float, float]:
    """Run the whole job on `cores` cores; return the job's and the odometry's frames/s."""
    _python("process", "run", str(rec), "--out", str(out), cores=cores)
    metrics = json.loads((out / "metrics.json").read_text())
    return float(metrics["job"]["fps"]), float(metrics["odometry"]["fps"])


def _fps_row(metric: str, fps: float) -> Row:
    return Row(
        AREA, metric, "frames/s", fps, CAMERA_FPS, "the camera's rate",
        higher_is_better=True, goal=">= 30",
    )  # fmt: skip


def _follow_row(tmp: Path) -> Row:
    """Follow a simulated recording written at camera speed; return the p95 lag row."""
    src, live, out = tmp / "sim.mcap", tmp / "live.mcap", tmp / "follow"
    simulate_recording(src, seed=5, frames=300)
    follower = _python(
        "process", "run", str(live), "--out", str(out), "--follow", "--follow-idle", "30",
        background=True,
    )  # fmt: skip
    assert follower.stderr is not None
    while not follower.stderr.readline().startswith("following"):
        if follower.poll() is not None:
            raise RuntimeError("process run --follow ended before following")
    time.sleep(0.5)
    _python("benchmarks.live_writer", str(src), str(live))
    if follower.wait() != 0:
        raise RuntimeError(f"process run --follow failed: {follower.stderr.read()[-300:]}")
    metrics = json.loads((out / "metrics.json").read_text())
    lag, tracked = metrics["follow"], metrics["odometry"]["frames"]
    what = (
        "--follow: p95 lag behind a camera at 30 frames/s (whole job, .rrd;"
        f" {lag['frames_dropped']} of {tracked + lag['frames_dropped']} frames dropped to keep up)"
    )
    return Row(
        AREA, what, "s", lag["lag_s_p95"], 2.0, "issue 13 goal", goal="<= 2 s",
    )  # fmt: skip
