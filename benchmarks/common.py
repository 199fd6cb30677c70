"""What every benchmark returns: table rows, ours beside the reference, measured in one run."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass


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
