"""`semreplay-process batch`: recordings per hour for a batch of small recordings, on this machine.

Four simulated recordings (30 frames, 320x240, the whole job with recording.rrd) processed three
ways, each a fresh command as a user would type it:
- one `process run` after another (what people did before `batch`): the reference of the pool;
- `batch` on the local process pool (default --jobs);
- `batch --executor ray` starting its own local Ray instance (the start is part of the time).
Small recordings show the per-task overhead (imports, worker start); on long recordings both
executors approach (cores / cores a task uses) times the sequential rate.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from benchmarks.common import Row
from capture.sim import simulate_recording

AREA = "process batch"
RECORDINGS = 4
FRAMES = 30
SIZE = (320, 240)


def run() -> list[Row]:
    """Return recordings/hour: local pool vs one run after another, Ray vs local pool."""
    with tempfile.TemporaryDirectory() as tmp:
        recs = Path(tmp) / "recs"
        recs.mkdir()
        for seed in range(RECORDINGS):
            simulate_recording(
                recs / f"sim{seed}.mcap",
                seed=20 + seed,
                frames=FRAMES,
                width=SIZE[0],
                height=SIZE[1],
            )
        sequential = _per_hour(lambda: _one_after_another(recs, Path(tmp) / "seq"))
        local = _per_hour(lambda: _process("batch", str(recs), "--out", str(Path(tmp) / "local")))
        ray = _per_hour(
            lambda: _process(
                "batch", str(recs), "--out", str(Path(tmp) / "ray"), "--executor", "ray"
            )
        )
    batch = f"{RECORDINGS} recordings of {FRAMES} frames {SIZE[0]}x{SIZE[1]}, whole job"
    return [
        Row(
            AREA,
            f"recordings/hour, local pool, {batch}",
            "rec/h",
            local,
            sequential,
            "`process run` one after another, same recordings",
            higher_is_better=True,
        ),
        Row(
            AREA,
            f"recordings/hour, Ray (local instance, its start included), {batch}",
            "rec/h",
            ray,
            local,
            "the local pool, same batch",
            higher_is_better=True,
        ),
    ]


def _per_hour(job: Callable[[], object]) -> float:
    """Return recordings per hour of one call of job."""
    t0 = time.perf_counter()
    job()
    return RECORDINGS * 3600.0 / (time.perf_counter() - t0)


def _one_after_another(recs: Path, out: Path) -> None:
    for rec in sorted(recs.glob("*.mcap")):
        _process("run", str(rec), "--out", str(out / rec.stem))


def _process(*args: str) -> None:
    """Run `python -m process ARGS` in a child; raise with its last line if it fails."""
    done = subprocess.run(
        [sys.executable, "-m", "process", *args], capture_output=True, text=True, check=False
    )
    if done.returncode != 0:
        tail = done.stderr.strip().splitlines()[-1:] or [""]
        raise RuntimeError(f"process {' '.join(args)} exited with {done.returncode}: {tail[0]}")
