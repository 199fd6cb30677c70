"""What every benchmark returns: table rows, ours beside the reference, measured in one run."""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path


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


def peak_rss_command(peak_file: str, module: str, *args: str) -> list[str]:
    """Return the command that runs `python -m module args` and writes its peak RSS (KiB)."""
    return [sys.executable, "-m", "benchmarks.peak_rss", peak_file, module, *args]


def read_peak_gb(peak_file: str) -> float:
    """Return the peak RSS in GB that benchmarks.peak_rss wrote."""
    return int(Path(peak_file).read_text()) / 1024**2


def run_with_peak_rss(module: str, *args: str) -> tuple[float, float, str]:
    """Run `python -m module args` in a child; return (its own peak RSS in GB, seconds, stdout).

    The peak is the child's VmHWM at exit (benchmarks.peak_rss), not wait4's ru_maxrss, which
    includes this (parent) process's memory at the time of the fork.
    """
    with tempfile.TemporaryDirectory() as tmp:
        peak_file = str(Path(tmp) / "peak_kib")
        command = peak_rss_command(peak_file, module, *args)
        t0 = time.perf_counter()
        done = subprocess.run(command, capture_output=True, text=True)
        seconds = time.perf_counter() - t0
        if done.returncode != 0:
            tail = done.stderr.strip().splitlines()[-1:] or [""]
            raise RuntimeError(f"{' '.join(command)} exited with {done.returncode}: {tail[0]}")
        return read_peak_gb(peak_file), seconds, done.stdout
