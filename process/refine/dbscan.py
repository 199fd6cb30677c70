"""Step 3: adaptive DBSCAN (paper section 2.4.1 as PAPER.md reads it), on one KD-tree query.

eps_K is the mean distance to the K-th nearest neighbour (KANN), MinPts_K the mean number of
points within eps_K (the point itself included, never below 4); DBSCAN runs for K = 1, 2, ...
and K is chosen from the cluster counts by a rule of selection.py: PAPER.md's literal one (the
largest K of the first run of >= 3 equal counts) or, by default, a plateau of the count of
clusters above the size threshold.

DBSCAN is our own, on SciPy's cKDTree, rather than Open3D's `cluster_dbscan`: Open3D searches
the neighbourhoods again on every call, while here one query of 2 K_max + 1 neighbours per point
serves every candidate eps (each listed distance is binned once against the sorted eps_K), so
one DBSCAN costs a few array passes and a SciPy connected-components call. It is exact: a point
whose whole list lies within eps gets its count from a ball query, and pairs of such points,
the only edges a list can miss, come from `query_pairs`. Clusters are the connected components
of core points; a border point joins the cluster of its nearest core point.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from process.refine.graph import components, kd_tree
from process.refine.selection import STABLE_RUN, plateau_choice, stable_choice, stable_run_closed

logger = logging.getLogger(__name__)

MIN_PTS_FLOOR = 4  # the paper: MinPts >= 4 for 3-D points
QUANTILES = {"median": 0.5, "lower_quartile": 0.25}  # MinPts statistics other than the mean


@dataclass(frozen=True)
class KannCurves:
    """The candidate parameters per K and the cluster count DBSCAN gives with each (Figs. 4-5)."""

    ks: npt.NDArray[np.int64]  # (K,) 1 .. min(k_max, n - 1)
    eps_m: npt.NDArray[np.float64]  # (K,) mean K-th neighbour distance
    min_pts: npt.NDArray[np.int64]  # (K,) mean count within eps_K, at least 4
    n_clusters: npt.NDArray[np.int64]  # (K,) DBSCAN clusters; -1 where DBSCAN was not run
    n_big: npt.NDArray[np.int64] | None = None  # (K,) clusters of >= the size threshold (core)


@dataclass(frozen=True)
class DbscanChoice:
    """The chosen (K, eps, MinPts) and how it was found."""

    k: int
    eps_m: float
    min_pts: int
    stable: bool  # False: no stable run (plateau) of cluster counts, the fallback chose
    note: str
    rule: str = "literal"  # "literal" (PAPER.md) or "plateau" (selection.py)
    min_size: int = 1  # clusters with fewer points go back to label 0


def query_size(k_max: int) -> int:
    """Return the neighbours listed per point: twice K_max, so that lists rarely run short."""
    return 2 * k_max + 1


class NeighbourTable:
    """One KD-tree query of a point set, binned against sorted eps candidates, reused by DBSCAN."""

    def __init__(self, points: npt.NDArray[np.floating], *, k_query: int) -> None:
        self.points = np.asarray(points, np.float64)
        self.tree = kd_tree(self.points)
        n = len(self.points)
        q = min(n, k_query)
        dist, idx = self.tree.query(self.points, k=q, workers=-1)
        self.dist = np.asarray(dist, np.float64).reshape(n, q)  # row-sorted, column 0 = itself
        self.idx = np.asarray(idx, np.int32).reshape(n, q)
        self.last = self.dist[:, -1].copy()  # a row within eps up to here may be cut short
        self.complete = q == n  # every row lists the whole set
        self.eps = np.zeros(0)
        self.bins = np.zeros((n, 0), np.uint8)
        self.col_cut = np.zeros(0, np.int64)
        self.counts = np.zeros((0, n), np.int32)

    def __len__(self) -> int:
        return len(self.points)

    def kann_eps(self, k_eff: int) -> npt.NDArray[np.float64]:
        """Return eps_K for K = 1..k_eff: the mean over points of the K-th neighbour distance."""
        eps: npt.NDArray[np.float64] = self.dist[:, 1 : k_eff + 1].mean(axis=0)
        return eps

    def bind(self, eps: npt.NDArray[np.float64]) -> None:
        """Bin each listed distance against the (ascending) eps values and count neighbours."""
        n, n_eps = len(self), len(eps)
        bins = np.searchsorted(eps, self.dist, side="left")  # d <= eps[k]  <=>  bins <= k
        flat = (np.arange(n)[:, None] * (n_eps + 1) + bins).ravel()
        hist = np.bincount(flat, minlength=n * (n_eps + 1)).reshape(n, n_eps + 1)
        counts = np.cumsum(hist, axis=1)[:, :n_eps]
        if not self.complete:
            for k in range(n_eps):
                rows = np.flatnonzero(self.last <= eps[k])
                if len(rows):
                    counts[rows, k] = self.tree.query_ball_point(
                        self.points[rows], eps[k], return_length=True, workers=-1
                    )
        self.eps = eps
        self.bins = bins.astype(np.uint8 if n_eps < 255 else np.uint16)
        self.col_cut = np.searchsorted(bins.min(axis=0), np.arange(n_eps), side="right")
        self.counts = np.ascontiguousarray(counts.T, np.int32)  # (n_eps, n): one row per eps
        del self.dist  # the bins say all DBSCAN needs

    def min_pts(self, statistic: str = "mean") -> npt.NDArray[np.int64]:
        """Return MinPts_k per bound eps: a statistic of the neighbour counts, at least 4.

        "mean" (the paper's Eq. 5-6) makes about half of the points too sparse to be core by
        construction, and a class's sparsely labelled object (a table the network saw in a
        fifth of its pixels) all noise; "lower_quartile" lets three quarters be core.
        Rounded half up.
        """
        if statistic in QUANTILES:
            mean = np.quantile(self.counts, QUANTILES[statistic], axis=1)
        else:
            mean = self.counts.mean(axis=1)
        min_pts: npt.NDArray[np.int64] = np.maximum(MIN_PTS_FLOOR, np.floor(mean + 0.5)).astype(
            np.int64
        )
        return min_pts

    def cluster(
        self, k: int, min_pts: int
    ) -> tuple[int, npt.NDArray[np.int64], npt.NDArray[np.bool_]]:
        """Run DBSCAN at the k-th bound eps; return the cluster count, components and core mask."""
        n = len(self)
        core = self.counts[k] >= min_pts
        rows = np.flatnonzero(core)
        cut = int(self.col_cut[k])
        within = self.bins[rows, :cut] <= k
        cols = self.idx[rows, :cut][within]
        starts = np.repeat(rows, np.count_nonzero(within, axis=1))
        keep = core[cols]
        starts, cols = starts[keep], cols[keep]
        extra = self._saturated_pairs(core, k)
        if extra is not None:
            starts, cols = np.concatenate([starts, extra[0]]), np.concatenate([cols, extra[1]])
        n_components, ids = components(n, starts, cols)
        return n_components - (n - len(rows)), ids.astype(np.int64), core

    def labels(self, k: int, min_pts: int) -> npt.NDArray[np.int64]:
        """Return DBSCAN labels at the k-th bound eps: 0..C-1 per cluster, -1 for noise."""
        _, components, core = self.cluster(k, min_pts)
        out = np.full(len(self), -1, np.int64)
        out[core] = np.unique(components[core], return_inverse=True)[1]
        self._assign_border(out, core, k)
        return out

    def _saturated_pairs(
        self, core: npt.NDArray[np.bool_], k: int
    ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]] | None:
        """Return the eps-pairs among core points whose lists are cut short (both ends)."""
        if self.complete:
            return None
        full = np.flatnonzero(core & (self.last <= self.eps[k]))
        if len(full) < 2:
            return None
        pairs = kd_tree(self.points[full]).query_pairs(self.eps[k], output_type="ndarray")
        return full[pairs[:, 0]], full[pairs[:, 1]]

    def _assign_border(
        self, out: npt.NDArray[np.int64], core: npt.NDArray[np.bool_], k: int
    ) -> None:
        """Give each non-core point within eps of a core point the cluster of the nearest one."""
        border = np.flatnonzero(~core)
        cut = int(self.col_cut[k])
        neighbours = self.idx[border, :cut]
        ok = (self.bins[border, :cut] <= k) & core[neighbours]
        has = ok.any(axis=1)
        nearest = neighbours[has, ok[has].argmax(axis=1)]  # rows are sorted by distance
        out[border[has]] = out[nearest]
        if self.complete:
            return
        # a row that lies wholly within eps may have its nearest core point beyond the list
        lost = border[~has & (self.last[border] <= self.eps[k])]
        balls = self.tree.query_ball_point(self.points[lost], self.eps[k])
        for i, ball in zip(lost, balls, strict=True):
            found = np.asarray(ball, np.int64)
            found = found[core[found]]
            if len(found):
                gaps = ((self.points[found] - self.points[i]) ** 2).sum(axis=1)
                out[i] = out[found[np.argmin(gaps)]]


def estimate_parameters(
    points: npt.NDArray[np.floating],
    *,
    k_max: int,
    full_curves: bool = False,
    rule: str = "literal",
    min_size: int = 1,
    min_area_m2: float = 0.0,
    tolerance: float = 0.0,
    max_eps_m: float = 0.0,
    min_pts_statistic: str = "mean",
) -> tuple[NeighbourTable, KannCurves, DbscanChoice]:
    """Choose (eps, MinPts) by KANN and the cluster-count curve; return the table for reuse.

    `rule` "literal" is PAPER.md's first stable run of all clusters; without `full_curves`
    DBSCAN stops at the first K after it (the rest of the curve reads -1). "plateau" runs
    every K and picks from the counts of clusters with >= `min_size` core points, within a
    relative `tolerance` (selection.py). The size threshold is the larger of `min_size` and
    `min_area_m2` of surface at the cloud's density (`surface_density`). `max_eps_m` > 0
    drops the K whose eps_K exceeds it (keeping at least 3): on a class of few, scattered
    points, the 30th neighbour lies across the room and the "least strict density" joins
    specks metres apart. `min_pts_statistic` is NeighbourTable.min_pts's.
    """
    n = len(points)
    k_eff = min(k_max, n - 1)
    if k_eff < 1:
        raise ValueError(f"adaptive DBSCAN needs at least 2 points, got {n}")
    table = NeighbourTable(points, k_query=query_size(k_max))
    eps = table.kann_eps(k_eff)
    capped = ""
    if max_eps_m > 0 and eps[-1] > max_eps_m:
        k_eff = max(min(STABLE_RUN, k_eff), int(np.searchsorted(eps, max_eps_m, side="right")))
        eps = eps[:k_eff]
        capped = f"; K <= {k_eff}: eps_K beyond is over {max_eps_m:g} m"
    table.bind(eps)
    min_pts = table.min_pts(min_pts_statistic)
    min_size = max(min_size, round(min_area_m2 * surface_density(table)))
    n_clusters = np.full(k_eff, -1, np.int64)
    n_big = np.full(k_eff, -1, np.int64)
    for k in range(k_eff):
        count, components, core = table.cluster(k, int(min_pts[k]))
        n_clusters[k] = count
        n_big[k] = int((np.bincount(components[core]) >= min_size).sum()) if core.any() else 0
        if rule == "literal" and not full_curves and stable_run_closed(n_clusters[: k + 1]):
            break
    if rule == "plateau":
        index, stable, note = plateau_choice(n_big, relative=tolerance)
        note = f"{note} ({min_size} points, tolerance {tolerance:g})"
    else:
        index, stable, note = stable_choice(n_clusters)
    note += capped
    curves = KannCurves(np.arange(1, k_eff + 1), eps, min_pts, n_clusters, n_big)
    return (
        table,
        curves,
        DbscanChoice(
            index + 1, float(eps[index]), int(min_pts[index]), stable, note, rule, min_size
        ),
    )


def surface_density(table: NeighbourTable, k: int = 10) -> float:
    """Return points per m^2 of surface: the mean count within eps_K over the disc pi eps_K^2.

    K = 10 (or the largest bound K) spans a few point spacings: past the jitter of the
    sampling, short of the surface's curvature.
    """
    k = min(k, len(table.eps)) - 1
    return float(table.counts[k].mean() / (np.pi * table.eps[k] ** 2))


def adaptive_dbscan(
    points: npt.NDArray[np.floating], *, k_max: int, full_curves: bool = False
) -> tuple[npt.NDArray[np.int64], KannCurves, DbscanChoice]:
    """Return DBSCAN labels (0..C-1, -1 = noise) with adaptive parameters, curves and choice."""
    table, curves, choice = estimate_parameters(points, k_max=k_max, full_curves=full_curves)
    return table.labels(choice.k - 1, choice.min_pts), curves, choice


def dbscan(
    points: npt.NDArray[np.floating], *, eps_m: float, min_pts: int, k_query: int
) -> npt.NDArray[np.int64]:
    """Return DBSCAN labels (0..C-1, -1 = noise) with fixed parameters (method 1's classes)."""
    if len(points) == 0:
        return np.zeros(0, np.int64)
    table = NeighbourTable(points, k_query=k_query)
    table.bind(np.array([eps_m]))
    return table.labels(0, min_pts)
