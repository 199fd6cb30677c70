"""The whole `semreplay-process run`: frames per second and peak memory against recording length."""

from __future__ import annotations

import os
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
        per_frame_gb: dict[int, float] = {}
        fps: dict[int, float] = {}
        for frames in (SHORT_FRAMES, LONG_FRAMES):
            rec = Path(tmp) / f"sim_{frames}.mcap"
            simulate_recording(rec, seed=11, frames=frames)
            rss_gb[frames], seconds = _peak_rss_gb(rec, Path(tmp) / f"out_{frames}")
            fps[frames] = frames / seconds
            # Without fusion there is no map: what is left grows with the frames, if anything.
            # Two peaks bound that growth from above (the end of a run also costs memory).
            per_frame_gb[frames], _ = _peak_rss_gb(
                rec, Path(tmp) / f"odo_{frames}", "--stages", "segmentation"
            )
            rec.unlink()
    slope = (per_frame_gb[LONG_FRAMES] - per_frame_gb[SHORT_FRAMES]) / (LONG_FRAMES - SHORT_FRAMES)
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
        *[
            Row(
                AREA,
                f"peak RSS without the map (--stages segmentation), {n} frames",
                "GB",
                per_frame_gb[n],
                GOAL_RSS_GB,
                "issue 7 goal for 10 minutes",
            )
            for n in (SHORT_FRAMES, LONG_FRAMES)
        ],
        Row(
            AREA,
            "peak RSS at 10 min, upper bound (no-map growth extrapolated linearly)",
            "GB",
            projected,
            GOAL_RSS_GB,
            "issue 7 goal",
            goal="< 4 GB",
        ),
    ]


def _peak_rss_gb(recording: Path, out: Path, *args: str) -> tuple[float, float]:
    """Run the job in a fresh child process; return its peak RSS in GB and its wall time."""
    command = [sys.executable, "-m", "process", "run", str(recording), "--out", str(out), *args]
    t0 = time.perf_counter()
    child = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _, status, usage = os.wait4(child.pid, 0)  # this child's own peak, not the largest so far
    seconds = time.perf_counter() - t0
    child.returncode = os.waitstatus_to_exitcode(status)
    if child.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} exited with {child.returncode}")
    return usage.ru_maxrss / 1024**2, seconds
