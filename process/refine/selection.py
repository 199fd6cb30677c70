"""How adaptive DBSCAN picks K from its cluster-count curve: the paper's rule and a plateau.

`literal` is PAPER.md's reading of KANN-DBSCAN: the first run of >= 3 equal cluster counts,
every cluster counted. On real-looking clouds (label bleed, wrong-class specks, missed
patches) that count moves by one or two at almost every K, because each speck is a cluster
of its own; the first "run" is then a coincidence, or there is none (issue 12).

`plateau` counts only the clusters that survive the size threshold (the objects the step
keeps) and looks for the longest window of K over which that count varies by no more than a
tolerance; it chooses the window's largest K, the paper's "minimum density threshold" of the
stable interval. Neither rule falls back silently: the note says what was chosen and why.

Measured (issue 12; phase-III F1 over target classes on generator 1 at 45k / 157k object
points and generator 2, tests/helpers_refine_sim.py, at 63k / 63k / 179k), with the rest of
the refinement at its defaults: literal 0.973 0.982 0.929 0.891 0.918; plateau, tolerance 0:
0.960 0.979 0.941 0.898 0.917; 0.1: 0.963 0.978 0.941 0.898 0.917; 0.25 (default): 0.964
0.982 0.941 0.902 0.922. The rule matters little once clusters are grouped into objects and
DBSCAN runs on voxel cells; those two steps took generator 2 from ~0.80 to ~0.92. (Those
figures predate the later defaults of issue 12: MinPts from the lower quartile, eps capped,
labelled structure; their figures are in the README, docs/refinement.md and
benchmarks/bench_refine.py.)
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

STABLE_RUN = 3  # KANN-DBSCAN: the cluster count is stable when 3 consecutive K agree
RULES = ("literal", "plateau")


def plateau_tolerance(count: int, relative: float) -> int:
    """Return how far a count may move inside a plateau: `relative` of it, at least 0."""
    return int(np.floor(relative * count + 1e-9))


def plateau_choice(
    n_big: npt.NDArray[np.int64], *, relative: float, min_run: int = STABLE_RUN
) -> tuple[int, bool, str]:
    """Return (index of the chosen K, plateau found?, note) from the counts of large clusters.

    A plateau is a window of consecutive K (all evaluated, >= 0) whose large-cluster counts
    are >= 1 and lie within `plateau_tolerance(min count, relative)` of each other. The
    longest window wins (the later one on ties) and its largest K is chosen. Without a window
    of `min_run` K: the largest K that gives a large cluster, said so in the note.
    """
    values = [int(v) for v in n_big]
    if -1 in values:
        values = values[: values.index(-1)]
    best: tuple[int, int] | None = None  # (start, end)
    for start in range(len(values)):
        low = high = values[start]
        if low < 1:
            continue
        end = start
        while end + 1 < len(values):
            v = values[end + 1]
            lo, hi = min(low, v), max(high, v)
            if v < 1 or hi - lo > plateau_tolerance(lo, relative):
                break
            low, high, end = lo, hi, end + 1
        if best is None or end - start >= best[1] - best[0]:
            best = (start, end)
    if best is not None and best[1] - best[0] + 1 >= min_run:
        start, end = best
        window = values[start : end + 1]
        counts = f"{min(window)}" if min(window) == max(window) else f"{min(window)}-{max(window)}"
        return end, True, f"plateau K={start + 1}..{end + 1}: {counts} clusters above the size"
    positive = [i for i, v in enumerate(values) if v > 0]
    if not positive:
        last = max(len(values) - 1, 0)
        return (
            last,
            False,
            f"no plateau: no K in 1..{len(values)} gives a cluster above the size; "
            f"chose K={last + 1}",
        )
    longest = 0 if best is None else best[1] - best[0] + 1
    return (
        positive[-1],
        False,
        f"no plateau: the count of clusters above the size holds for {longest} K at most "
        f"(need {min_run}); chose the largest K with one, K={positive[-1] + 1}",
    )


def stable_choice(n_clusters: npt.NDArray[np.int64]) -> tuple[int, bool, str]:
    """Return (index of the chosen K, stable?, note) from the cluster counts of K = 1, 2, ...

    The first run of >= 3 equal, non-zero counts is the stable interval and its largest K is
    chosen. Fallback when there is none: the largest K of the longest run of non-zero counts
    (the later run on ties); when no K gives a cluster, the largest K.
    """
    runs = _runs(n_clusters)
    for start, end, value in runs:
        if value > 0 and end - start + 1 >= STABLE_RUN:
            return end, True, f"stable: {value} clusters for K={start + 1}..{end + 1}"
    positive = [r for r in runs if r[2] > 0]
    if not positive:
        last = len(n_clusters) - 1
        return last, False, f"fallback: no K in 1..{last + 1} gives a cluster; chose K={last + 1}"
    start, end, value = max(positive, key=lambda r: (r[1] - r[0], r[0]))
    return (
        end,
        False,
        (
            f"fallback: no {STABLE_RUN} equal cluster counts in K=1..{len(n_clusters)}; chose the "
            f"largest K of the longest run ({value} clusters for K={start + 1}..{end + 1})"
        ),
    )


def _runs(values: npt.NDArray[np.int64]) -> list[tuple[int, int, int]]:
    """Return (first index, last index, value) of each run of equal consecutive values >= 0."""
    runs: list[tuple[int, int, int]] = []
    for i, v in enumerate(int(x) for x in values):
        if v < 0:
            break
        if runs and runs[-1][2] == v:
            runs[-1] = (runs[-1][0], i, v)
        else:
            runs.append((i, i, v))
    return runs


def stable_run_closed(n_clusters: npt.NDArray[np.int64]) -> bool:
    """Return whether the counts so far hold a stable run followed by a different count."""
    runs = _runs(n_clusters)
    return any(v > 0 and e - s + 1 >= STABLE_RUN for s, e, v in runs[:-1])
