"""Voxel cells that SOR and DBSCAN run on, and the small clusters that belong to an object."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

_MIN_VOXEL_M = 0.005  # capped_cells starts here when asked for points (voxel 0)
_INSIDE_SHARE = 0.5  # a sparse cluster this much inside a denser one's box yields to it
_BOX_PERCENTILE = 1.0  # ... the box between these percentiles of the denser one's points


def voxel_cells(
    points: npt.NDArray[np.float32], voxel_m: float
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.intp]]:
    """Return the centroid of each occupied voxel and each point's voxel (voxel_m 0: points).

    Adaptive DBSCAN runs on these cells: K = 1..K_max then spans the same distances in metres
    at any density (at 7 mm spacing, K = 30 reaches only ~3 cm and splits every object along
    each missed stripe), and a million-point class costs what a 2 cm map costs. Cells come in
    the lexicographic order of their (x, y, z) voxel indices.
    """
    if voxel_m <= 0 or len(points) == 0:
        return points, np.arange(len(points))
    keys = np.floor(points / np.float32(voxel_m)).astype(np.int64)
    keys -= keys.min(axis=0)
    span = keys.max(axis=0) + 1
    if float(np.prod(span.astype(np.float64))) < 2.0**62:
        # one int64 per point, in the same order as the rows: a 1-D sort, not a row sort
        packed = (keys[:, 0] * span[1] + keys[:, 1]) * span[2] + keys[:, 2]
        del keys
        _, cell_of, counts = np.unique(packed, return_inverse=True, return_counts=True)
    else:
        _, cell_of, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    cell_of = cell_of.reshape(-1)
    sums = np.stack([np.bincount(cell_of, points[:, a], len(counts)) for a in range(3)], 1)
    return (sums / counts[:, None]).astype(np.float32), cell_of


def capped_cells(
    points: npt.NDArray[np.float32], voxel_m: float, max_cells: int
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.intp], float]:
    """Return voxel_cells at `voxel_m`, or at the smallest coarser voxel giving <= max_cells.

    The voxel grows only when the cells outnumber `max_cells` (a multi-million-point cloud,
    or a volume rather than a surface): the steps on the cells then cost what `max_cells`
    points cost, at any size of cloud, and every point takes its cell's result.
    Returns the cells, each point's cell and the voxel used.
    """
    cells, cell_of = voxel_cells(points, voxel_m)
    while len(cells) > max_cells:
        # cells fall with the square of the voxel on surfaces, faster in volumes
        voxel_m = max(voxel_m, _MIN_VOXEL_M) * max(1.1, math.sqrt(len(cells) / max_cells))
        cells, cell_of = voxel_cells(points, voxel_m)
    return cells, cell_of, voxel_m


def attached_clusters(
    cells: npt.NDArray[np.float32],
    cluster_of: npt.NDArray[np.int64],
    big: npt.NDArray[np.bool_],
    gap_m: float,
) -> npt.NDArray[np.bool_]:
    """Return the clusters below the size threshold whose box comes within `gap_m` of a big one's.

    The size threshold is meant for specks: a mislabelled blob of a few cells far from any
    object of its class. A small cluster of the class within an object's reach (a chair leg
    that a thin TSDF surface broke off the seat, a plant's sparse leaves) is a piece of that
    object (regrowth groups clusters into objects by the same `gap_m`), and is kept.
    """
    n = len(big)
    out = np.zeros(n, bool)
    if not big.any() or big.all():
        return out
    member = cluster_of >= 0
    row, xyz = cluster_of[member], cells[member].astype(np.float64)
    low = np.full((n, 3), np.inf)
    high = np.full((n, 3), -np.inf)
    np.minimum.at(low, row, xyz)
    np.maximum.at(high, row, xyz)
    small = np.flatnonzero(~big & np.isfinite(low[:, 0]))
    b_low, b_high = low[big] - gap_m, high[big] + gap_m
    for i in small:  # few big clusters per class: a box test against each
        touch = np.all((low[i] <= b_high) & (high[i] >= b_low), axis=1)
        out[i] = bool(touch.any())
    return out


def sparse_inside_others(
    points: npt.NDArray[np.float32],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    sparse: npt.NDArray[np.int64],
) -> npt.NDArray[np.int64]:
    """Return the sparse clusters lying mostly inside a dense cluster's box of another class.

    A sparse cluster (no point dense enough at the paper's MinPts) on its own is an object the
    network labelled in few views; inside an object of another class, it is the network's
    confusion at that object's edge, and gives way (regrowth relabels it). Inside means at
    least `_INSIDE_SHARE` of its points within the dense cluster's box, taken between the
    `_BOX_PERCENTILE` and 100 - `_BOX_PERCENTILE` percentiles of its points: a mug standing on
    a table touches the table's box only at its foot, and a few table-labelled specks on top
    of the mug would otherwise stretch the box over it. The dense cluster must have at least
    the sparse one's points: each class's density is measured at its own eps, and a class the
    network gave only a few dozen points gets a wide eps that makes any blob of them dense (a
    fused simulated map: 48 plant points on a chair's back, clustered at 14 cm into a blob 42 cm
    across, took the 137-point cluster of the chair's seat and legs, and regrowth then made the
    whole chair plant; seed 38, phase I 0.901 -> III 0.875).
    """
    ids = np.unique(clusters[clusters > 0])
    member = clusters > 0
    row = np.searchsorted(ids, clusters[member])
    xyz = points[member].astype(np.float64)
    low = np.full((len(ids), 3), np.inf)
    high = np.full((len(ids), 3), -np.inf)
    np.minimum.at(low, row, xyz)
    np.maximum.at(high, row, xyz)
    label = np.zeros(len(ids), np.uint8)
    label[row] = labels[member]
    is_sparse = np.isin(ids, sparse)
    size = np.bincount(row, minlength=len(ids))
    dense = ~is_sparse
    boxes: dict[int, npt.NDArray[np.float64]] = {}  # robust (2, 3) box per dense cluster
    out = []
    for i in np.flatnonzero(is_sparse):
        other = dense & (label != label[i]) & (size >= size[i])
        overlap = np.all((low[i] <= high[other]) & (high[i] >= low[other]), axis=1)
        mine = xyz[row == i]
        for j in np.flatnonzero(other)[overlap]:
            if j not in boxes:
                boxes[j] = np.percentile(xyz[row == j], [_BOX_PERCENTILE, 100 - _BOX_PERCENTILE], 0)
            inside = np.all((mine >= boxes[j][0]) & (mine <= boxes[j][1]), axis=1)
            if inside.mean() >= _INSIDE_SHARE:
                out.append(int(ids[i]))
                break
    return np.array(out, np.int64)


def class_cells(
    xyz: npt.NDArray[np.float32],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    max_points: int,
) -> tuple[
    npt.NDArray[np.float32], npt.NDArray[np.uint8], npt.NDArray[np.int32], npt.NDArray[np.intp]
]:
    """Return per (voxel, class) the centroid, class and first cluster, and each point's row.

    The finest voxel giving at most `max_points` cells (capped_cells); the steps that build a
    neighbour graph over all object points (seams.py, pieces.py) run on these past that size.
    """
    _, cell_of, _ = capped_cells(xyz, 0.0, max_points)
    key = cell_of.astype(np.int64) * 256 + labels
    _, first, group = np.unique(key, return_index=True, return_inverse=True)
    group = group.reshape(-1)
    counts = np.bincount(group).astype(np.float64)[:, None]
    centroids = np.column_stack([np.bincount(group, weights=xyz[:, k]) for k in range(3)])
    return (centroids / counts).astype(np.float32), labels[first], clusters[first], group
