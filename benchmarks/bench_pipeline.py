"""The whole `semreplay-process run`: frames per second and peak memory against recording length."""

from __future__ import annotations

import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.common import Row
from capture.sim import simulate_recording

AREA = "process run"
SHORT_FRAMES = 150
LONG_FRAMES = 600
TEN_MINUTES = 10 * 60 * 30  # frames of a 10-minute recording at 30 fps
GOAL_RSS_GB = 4.0


def run() -> list[Row]:
    """Return the pipeline's rows: speed, and peak RSS extrapolated to a 10-minute recording."""
    with tempfile.TemporaryDirectory() as tmp:
        rss_gb: dict[int, float] = {}
        fps: dict[int, float] = {}
        for frames in (SHORT_FRAMES, LONG_FRAMES):
            rec = Path(tmp) / f"sim_{frames}.mcap"
            simulate_recording(rec, seed=11, frames=frames)
            rss_gb[frames], seconds = _peak_rss_gb(rec, Path(tmp) / f"out_{frames}")
            fps[frames] = frames / seconds
            rec.unlink()
    slope = (rss_gb[LONG_FRAMES] - rss_gb[SHORT_FRAMES]) / (LONG_FRAMES - SHORT_FRAMES)
    projected = rss_gb[LONG_FRAMES] + max(slope, 0.0) * (TEN_MINUTES - LONG_FRAMES)
    return [
        Row(
            AREA,
            f"whole job, {LONG_FRAMES} frames 640x480",
            "frames/s",
            fps[LONG_FRAMES],
            30.0,
            "the camera's rate",
            higher_is_better=True,
        ),
        Row(
            AREA,
            f"peak RSS, {SHORT_FRAMES} frames",
            "GB",
            rss_gb[SHORT_FRAMES],
            GOAL_RSS_GB,
            "issue 7 goal for 10 minutes",
        ),
        Row(
            AREA,
            f"peak RSS, {LONG_FRAMES} frames",
            "GB",
            rss_gb[LONG_FRAMES],
            GOAL_RSS_GB,
            "issue 7 goal for 10 minutes",
        ),
        Row(
            AREA,
            "peak RSS projected to 10 min (linear in frames)",
            "GB",
            projected,
            GOAL_RSS_GB,
            "issue 7 goal",
            goal="< 4 GB",
        ),
    ]


def _peak_rss_gb(recording: Path, out: Path) -> tuple[float, float]:
    """Run the whole job in a child process; return its peak RSS in GB and its wall time."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    t0 = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "process", "run", str(recording), "--out", str(out)],
        check=True,
        capture_output=True,
    )
    seconds = time.perf_counter() - t0
    peak_kb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    # ru_maxrss of children is the largest child so far; the runs grow, so the last one is it.
    return max(peak_kb, before) / 1024**2, seconds
