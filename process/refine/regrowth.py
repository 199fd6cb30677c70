"""Step 4: regrowth of unlabelled points around each cluster (paper section 2.4.2, PAPER.md).

A point with label 0 joins a cluster when it lies within r1 (the eps chosen for the cluster's
class) of a point already in the cluster and within r2 (half the diagonal of the cluster's
axis-aligned bounding box, Eq. 7-8) of the cluster's centroid. Growth runs in waves, each wave
testing the remaining unlabelled points against the points that joined in the previous one,
until no point joins. A point that two clusters reach in the same wave goes to the nearer one:
the cluster of its nearest qualifying frontier point.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

_CANDIDATES = 8  # frontier points examined per unlabelled point and wave, nearest first


@dataclass(frozen=True)
class Regrowth:
    """Labels and clusters after regrowth, and what grew."""

    labels: npt.NDArray[np.uint8]  # (N,)
    clusters: npt.NDArray[np.int32]  # (N,)
    regrown: npt.NDArray[np.intp]  # indices of the points that joined a cluster
    r2_m: dict[int, float]  # cluster id -> r2
    waves: int


def regrow(
    points: npt.NDArray[np.float32],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    *,
    r1_m: dict[int, float],
) -> Regrowth:
    """Grow every cluster (clusters > 0) over the points with label 0.

    Args:
        points: (N, 3) the object cloud.
        labels: (N,) class per point, 0 = unlabelled (the candidates).
        clusters: (N,) cluster id per point, 0 = none; every cluster has one class.
        r1_m: class label -> r1 (the class's chosen eps).
    """
    labels, clusters = labels.copy(), clusters.copy()
    ids = np.unique(clusters[clusters > 0])
    if len(ids) == 0:
        return Regrowth(labels, clusters, np.zeros(0, np.intp), {}, 0)
    table = _cluster_table(points, labels, clusters, ids, r1_m)
    lookup = np.searchsorted(ids, clusters)  # row of each clustered point in the table
    frontier = np.flatnonzero(clusters > 0)
    open_ = np.flatnonzero(labels == 0)
    grown: list[npt.NDArray[np.intp]] = []
    waves = 0
    while len(frontier) and len(open_):
        joined, row = _wave(points, frontier, lookup[frontier], open_, table)
        if len(joined) == 0:
            break
        labels[joined], clusters[joined] = table.label[row], ids[row].astype(np.int32)
        lookup[joined] = row
        grown.append(joined)
        open_ = np.setdiff1d(open_, joined, assume_unique=True)
        frontier, waves = joined, waves + 1
    regrown = np.concatenate(grown) if grown else np.zeros(0, np.intp)
    r2 = {int(i): float(r) for i, r in zip(ids, table.r2, strict=True)}
    return Regrowth(labels, clusters, np.sort(regrown), r2, waves)


@dataclass(frozen=True)
class _Clusters:
    label: npt.NDArray[np.uint8]  # (C,) class of each cluster
    centroid: npt.NDArray[np.float64]  # (C, 3)
    r1: npt.NDArray[np.float64]  # (C,)
    r2: npt.NDArray[np.float64]  # (C,) half the AABB diagonal


def _cluster_table(
    points: npt.NDArray[np.float32],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    ids: npt.NDArray[np.int32],
    r1_m: dict[int, float],
) -> _Clusters:
    member = np.flatnonzero(clusters > 0)
    row = np.searchsorted(ids, clusters[member])
    count = np.bincount(row, minlength=len(ids)).astype(np.float64)
    xyz = points[member].astype(np.float64)
    centroid = (
        np.stack([np.bincount(row, xyz[:, a], len(ids)) for a in range(3)], 1) / count[:, None]
    )
    low = np.full((len(ids), 3), np.inf)
    high = np.full((len(ids), 3), -np.inf)
    np.minimum.at(low, row, xyz)
    np.maximum.at(high, row, xyz)
    label = np.zeros(len(ids), np.uint8)
    label[row] = labels[member]
    r1 = np.array([r1_m.get(int(c), 0.0) for c in label])
    return _Clusters(label, centroid, r1, np.linalg.norm(high - low, axis=1) / 2)


def _wave(
    points: npt.NDArray[np.float32],
    frontier: npt.NDArray[np.intp],
    frontier_row: npt.NDArray[np.intp],
    open_: npt.NDArray[np.intp],
    table: _Clusters,
) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """Return the open points that join in this wave and the cluster row each joins."""
    k = min(_CANDIDATES, len(frontier))
    reach = float(table.r1.max())
    distance, nearest = cKDTree(points[frontier]).query(
        points[open_], k=k, distance_upper_bound=reach, workers=-1
    )
    distance, nearest = distance.reshape(len(open_), k), nearest.reshape(len(open_), k)
    near = np.flatnonzero(np.isfinite(distance[:, 0]))  # anything within the largest r1
    distance, nearest = distance[near], nearest[near]
    hit = np.isfinite(distance)
    rows = np.where(hit, frontier_row[np.minimum(nearest, len(frontier) - 1)], 0)
    to_centroid = np.linalg.norm(points[open_[near]][:, None, :] - table.centroid[rows], axis=2)
    ok = hit & (distance <= table.r1[rows]) & (to_centroid <= table.r2[rows])
    joins = ok.any(axis=1)
    first = ok[joins].argmax(axis=1)  # nearest qualifying frontier point
    return open_[near[joins]], rows[joins, first]
