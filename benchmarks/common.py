"""What every benchmark returns: table rows, ours beside the reference, measured in one run."""

from __future__ import annotations

import contextlib
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import psutil


@dataclass(frozen=True, slots=True)
class Row:
    """One line of the `make bench` table.

    `ours` and `reference` are measured side by side in the same run where the reference is a
    program (e.g. Open3D's odometry); where it is a published figure (the paper's), `source`
    says so.
    `higher_is_better` orients the ratio so that a ratio > 1 always means we are better.
    """

    area: str
    metric: str
    unit: str
    ours: float
    reference: float
    source: str
    higher_is_better: bool = False
    goal: str = ""

    @property
    def ratio(self) -> float:
        """Return how many times better we are than the reference (> 1 = better)."""
        if self.ours == 0 or self.reference == 0:
            return float("inf") if (self.ours == 0) != self.higher_is_better else 0.0
        return self.ours / self.reference if self.higher_is_better else self.reference / self.ours


def best_of(fn: Callable[[], object], *, repeats: int = 3) -> float:
    """Return the best wall time in seconds of `repeats` calls of fn."""
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


@dataclass(frozen=True, slots=True)
class ChildRun:
    """What run_with_peak_rss measured of a child process."""

    peak_gb: float  # its own high-water mark (VmHWM at exit)
    seconds: float
    stdout: str
    samples: list[tuple[float, float]]  # (seconds, resident GB), if sampling was asked for


def run_with_peak_rss(module: str, *args: str, sample_every_s: float | None = None) -> ChildRun:
    """Run `python -m module args` in a child and measure its own peak RSS.

    The peak is the child's VmHWM at exit (benchmarks.peak_rss), not wait4's ru_maxrss, which
    includes this (parent) process's memory at the time of the fork. With sample_every_s the
    resident set is also sampled while the child runs.
    """
    with tempfile.TemporaryDirectory() as tmp:
        peak_file = Path(tmp) / "peak_kib"
        command = [sys.executable, "-m", "benchmarks.peak_rss", str(peak_file), module, *args]
        t0 = time.perf_counter()
        child = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        watched = psutil.Process(child.pid)
        samples: list[tuple[float, float]] = []
        while True:
            try:  # communicate() keeps what it read when it times out
                stdout, stderr = child.communicate(timeout=sample_every_s)
                break
            except subprocess.TimeoutExpired:
                with contextlib.suppress(psutil.Error):
                    samples.append((time.perf_counter() - t0, watched.memory_info().rss / 1024**3))
        seconds = time.perf_counter() - t0
        if child.returncode != 0:
            tail = stderr.strip().splitlines()[-1:] or [""]
            raise RuntimeError(f"{' '.join(command)} exited with {child.returncode}: {tail[0]}")
        peak_gb = int(peak_file.read_text()) / 1024**2
        return ChildRun(peak_gb, seconds, stdout, samples)
