"""The whole `semreplay-process run`: speed, map quality and peak memory against recording length.

`make bench` runs 150 and 600 simulated frames, with and without the map. The 10-minute goal is
not extrapolated from them (two peaks 450 frames apart differ by tens of MB of jitter, which a
linear projection over 18,000 frames turns into gigabytes either way); `python -m
benchmarks.bench_pipeline ten-minutes --out DIR` measures a real 10-minute recording instead
(an hour on 2 cores, see `ten_minutes`).
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.common import Row, run_with_peak_rss
from capture.sim import simulate_recording

AREA = "process run"
SHORT_FRAMES = 150
LONG_FRAMES = 600
TEN_MINUTES = 10 * 60 * 30  # frames of a 10-minute recording at 30 fps
GOAL_RSS_GB = 4.0


def run() -> list[Row]:
    """Return the pipeline's rows: speed, map quality and peak RSS at two recording lengths."""
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
            per_frame_gb[frames], _ = _peak_rss_gb(
                rec, Path(tmp) / f"odo_{frames}", "--stages", "segmentation"
            )
            if frames == LONG_FRAMES:  # the map's quality, TSDF surface beside hit voxels
                f1_tsdf = _phase_f1(Path(tmp) / f"out_{frames}")
                voxels = Path(tmp) / "voxels.toml"
                voxels.write_text('[fusion]\nsurface = "voxels"\n')
                out = Path(tmp) / "voxels"
                _peak_rss_gb(rec, out, "--no-viz", "--config", str(voxels))
                f1_voxels = _phase_f1(out)
            rec.unlink()
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
        *[
            Row(
                AREA,
                f"map F1 phase {phase} (all classes), {LONG_FRAMES} frames, TSDF surface",
                "",
                f1_tsdf[phase],
                f1_voxels[phase],
                'same job with fusion.surface = "voxels"',
                higher_is_better=True,
            )
            for phase in ("I", "III")
        ],
    ]


def _phase_f1(out: Path) -> dict[str, float]:
    """Return the F1 of every refinement phase (all classes) from a run's metrics.json."""
    phases = json.loads((out / "metrics.json").read_text())["refinement"]["phases"]
    return {name: float(phase["all"]["f1"]) for name, phase in phases.items()}


def _peak_rss_gb(recording: Path, out: Path, *args: str) -> tuple[float, float]:
    """Run the job in a fresh child process; return its peak RSS in GB and its wall time."""
    child = run_with_peak_rss("process", "run", str(recording), "--out", str(out), "--force", *args)
    return child.peak_gb, child.seconds


def ten_minutes(recording: Path | None, out: Path) -> int:
    """Measure a whole 10-minute simulated recording (~20 min to simulate, ~20 min to process).

    Not part of `make bench` (it takes an hour on 2 cores and ~24 GB of disk); run it as
    `python -m benchmarks.bench_pipeline ten-minutes [REC.mcap] --out DIR`. It writes
    DIR/rss.csv (seconds, GB) and prints the peak and the resident set at each tenth of the run.
    """
    out.mkdir(parents=True, exist_ok=True)
    if recording is None:
        recording = out / "sim_10min.mcap"
        if not recording.exists():
            t0 = time.perf_counter()
            simulate_recording(recording, seed=7, frames=TEN_MINUTES)
            print(f"simulated {TEN_MINUTES} frames in {time.perf_counter() - t0:.0f} s")
    child = run_with_peak_rss(
        "process", "run", str(recording), "--out", str(out / "run"), "--force", sample_every_s=2.0
    )
    peak, seconds, samples = child.peak_gb, child.seconds, child.samples
    with (out / "rss.csv").open("w") as f:
        f.write("seconds,rss_gb\n")
        f.writelines(f"{t:.1f},{gb:.4f}\n" for t, gb in samples)
    print(f"{recording}: process run took {seconds:.0f} s; peak RSS {peak:.2f} GB (goal < 4)")
    for k in range(1, 11 if samples else 1):
        t_k, gb_k = samples[min(len(samples) - 1, k * len(samples) // 10 - 1)]
        print(f"  {10 * k:3d} % of the run ({t_k:5.0f} s): {gb_k:.2f} GB resident")
    return 0 if peak < GOAL_RSS_GB else 1


if __name__ == "__main__":
    if len(sys.argv) < 4 or sys.argv[1] != "ten-minutes" or "--out" not in sys.argv:
        sys.exit("usage: python -m benchmarks.bench_pipeline ten-minutes [REC.mcap] --out DIR")
    where = sys.argv.index("--out")
    given = [a for i, a in enumerate(sys.argv[2:], 2) if i not in (where, where + 1)]
    sys.exit(ten_minutes(Path(given[0]) if given else None, Path(sys.argv[where + 1])))
