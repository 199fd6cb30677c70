"""Labels at the seams of touching objects follow the smooth surface they lie on.

A network's label bleeds a few centimetres across the contact of two objects: a seated
person's label onto the chair's seat, a chair's onto the person's back, a desk's onto a
monitor's foot. DBSCAN keeps the bleed with the cluster it touches and regrowth keeps it too.
Here the object points are joined into smooth surfaces: neighbours whose normals agree, that
lie in each other's tangent plane, both on locally flat ground (low surface variation, so a
surface does not creep round an arm or a bottle lying on a table). A point whose class is not
its surface's majority, lying within `seam_vote_m` of a point of that majority class, takes it
when:
- the majority holds at least `MAJORITY` of the surface, and
- its own cluster lies mostly elsewhere (a fringe of an object beyond this surface), not
  mostly on it (a book or a keyboard lying flat on a desk is an object of its own), and
- it does not stand on a table when the class is table: above a desk's top, over its
  footprint (raised.py), only level points (a stretch of the top, a second desk's top 1.5 cm
  higher) may take it. A box on a desk whose front lies in one plane with the desk's front
  panel shares the panel's surface, and its lower side had taken the desk's label.

Written here because neither Open3D nor SciPy has smooth-surface region growing (PCL's
RegionGrowing is not a dependency); the graph's connected components are SciPy's (graph.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import open3d as o3d

from capture.recording import OBJECT_LABELS, Label
from process.refine.cells import class_cells
from process.refine.graph import components, kd_tree

NEIGHBOURS = 10  # graph edges per point
NORMAL_NEIGHBOURS = 16  # points of each local covariance (normal and surface variation)
MAJORITY = 0.6  # a surface's class holds this share of its points
FRINGE = 0.5  # a point flips only if less than this share of its cluster is on the surface
MIN_SURFACE = 50  # points a surface needs to vote
LEVEL_DEG = 25.0  # above a table's top, a point whose normal is this near up may still take table


@dataclass(frozen=True)
class SeamVote:
    """The labels after the vote and the points it relabelled (indices into the input)."""

    labels: npt.NDArray[np.uint8]
    relabelled: npt.NDArray[np.intp]
    # the object points' NEIGHBOURS + 1 nearest (distances, indices), in the order of
    # np.flatnonzero(np.isin(labels, OBJECT_LABELS)); None when the vote ran on cells or not
    # at all. The vote changes only object classes, so the piece vote reuses them (pieces.py).
    neighbours: tuple[npt.NDArray[np.float64], npt.NDArray[np.intp]] | None = None


def seam_vote(
    points: npt.NDArray[np.floating],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    *,
    seam_m: float,
    angle_deg: float,
    flatness: float,
    max_points: int = 400_000,
    standing: npt.NDArray[np.intp] | None = None,
    up: npt.NDArray[np.float64] | None = None,
) -> SeamVote:
    """Relabel object points at class seams by the majority of the smooth surface they lie on.

    Args:
        points: (N, 3) positions.
        labels: (N,) class per point; only object classes vote or change.
        clusters: (N,) object id per point (0: none), for the fringe test.
        seam_m: a point changes only within this distance of its surface's majority class.
        angle_deg: neighbours whose normals differ by more are not on one surface.
        flatness: points of larger surface variation (l0 / (l0 + l1 + l2)) join no surface.
        max_points: past this many object points the vote runs on the centroids of each
            class's points per voxel (the finest voxel giving about this many), and every
            point takes its centroid's verdict: the graph's memory stays bounded.
        standing: indices of the points above a table's top, over its footprint (raised.py),
            with `up`: those not level never take table (a cell, past `max_points`, when most
            of its points are).
        up: gravity-up, for `standing`.
    """
    out = labels.copy()
    objects = np.flatnonzero(np.isin(labels, OBJECT_LABELS))
    if (
        len(objects) < max(MIN_SURFACE, NORMAL_NEIGHBOURS + 1)
        or len(np.unique(labels[objects])) < 2
    ):
        return SeamVote(out, np.zeros(0, np.intp))
    xyz = np.asarray(points[objects], np.float32)
    own, ids = labels[objects], clusters[objects]
    group = np.arange(len(objects))
    capped = len(objects) > max_points
    if capped:
        xyz, own, ids, group = class_cells(xyz, own, ids, max_points)
    on_table = np.zeros(len(xyz), bool)
    if standing is not None and len(standing) and up is not None:
        share = np.bincount(group, np.isin(objects, standing).astype(np.float64))
        on_table = share > 0.5 * np.bincount(group)
    xyz64 = np.asarray(xyz, np.float64)
    neighbours = kd_tree(xyz64).query(xyz64, NEIGHBOURS + 1, workers=-1)
    new = _vote(xyz64, own, ids, neighbours, seam_m, angle_deg, flatness, on_table, up)[group]
    flip = new != labels[objects]
    out[objects[flip]] = new[flip]
    return SeamVote(out, objects[flip], None if capped else neighbours)


def _vote(
    xyz: npt.NDArray[np.float64],
    own: npt.NDArray[np.uint8],
    ids: npt.NDArray[np.int32],
    neighbours: tuple[npt.NDArray[np.float64], npt.NDArray[np.intp]],
    seam_m: float,
    angle_deg: float,
    flatness: float,
    on_table: npt.NDArray[np.bool_],
    up: npt.NDArray[np.float64] | None,
) -> npt.NDArray[np.uint8]:
    """Return the labels after the vote, for points each of one class and one cluster.

    `on_table`: the points above a table's top (with `up`); of them only level ones take table.
    """
    surface, normals = _surfaces(xyz, neighbours, angle_deg=angle_deg, flatness=flatness)
    major, share, size = _majority(surface, own)
    candidate = (own != major[surface]) & (share[surface] >= MAJORITY)
    candidate &= (size[surface] >= MIN_SURFACE) & (_on_surface_share(ids, surface) < FRINGE)
    if up is not None and on_table.any():
        level = np.abs(normals @ up) > np.cos(np.radians(LEVEL_DEG))
        candidate &= ~(on_table & ~level & (major[surface] == Label.TABLE))
    out = own.copy()
    for target in np.unique(major[surface][candidate]):
        rows = np.flatnonzero(candidate & (major[surface] == target))
        near, _ = kd_tree(xyz[own == target]).query(xyz[rows], distance_upper_bound=seam_m)
        out[rows[np.isfinite(near)]] = target
    return out


def _surfaces(
    xyz: npt.NDArray[np.float64],
    neighbours: tuple[npt.NDArray[np.float64], npt.NDArray[np.intp]],
    *,
    angle_deg: float,
    flatness: float,
) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.float64]]:
    """Return per point its smooth surface and its normal.

    Surfaces are the components of the graph of flat points and their coplanar neighbours.
    """
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(xyz))
    search = o3d.geometry.KDTreeSearchParamKNN(NORMAL_NEIGHBOURS)
    cloud.estimate_covariances(search)
    # Open3D's normals from the covariances it holds (no second search): the direction of least
    # spread, by its closed-form 3x3 solver, a tenth of the time of NumPy's batched eigh
    cloud.estimate_normals(search)
    covariances, normals = np.asarray(cloud.covariances), np.asarray(cloud.normals)
    least = np.einsum("ni,nij,nj->n", normals, covariances, normals)  # smallest eigenvalue
    trace = np.trace(covariances, axis1=1, axis2=2)
    flat = least / np.maximum(trace, 1e-18) < flatness
    dist, nb = neighbours  # each point's NEIGHBOURS + 1 nearest, itself first
    spacing = float(np.median(dist[:, 1]))
    # per row (a point and its neighbours) rather than per edge: the point's own normal and
    # position broadcast instead of being gathered once per edge
    rows = np.flatnonzero(flat)
    near = nb[rows, 1:]
    ok = (dist[rows, 1:] < 4 * spacing) & flat[near]
    own = normals[rows][:, None, :]
    ok &= np.abs((normals[near] * own).sum(axis=2)) > np.cos(np.radians(angle_deg))
    ok &= np.abs(((xyz[near] - xyz[rows][:, None, :]) * own).sum(axis=2)) < spacing  # tangent
    i = np.repeat(rows, np.count_nonzero(ok, axis=1))
    return components(len(xyz), i, near[ok])[1], normals


def _majority(
    surface: npt.NDArray[np.int32], labels: npt.NDArray[np.uint8]
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64], npt.NDArray[np.int64]]:
    """Return per surface its most common class, that class's share and the surface's size."""
    key = surface.astype(np.int64) * 256 + labels
    pairs, counts = np.unique(key, return_counts=True)
    ids, classes = pairs // 256, pairs % 256
    order = np.lexsort((-counts, ids))  # per surface, its largest class first
    first = order[np.unique(ids[order], return_index=True)[1]]
    n = int(surface.max()) + 1
    major, top = np.zeros(n, np.int64), np.zeros(n, np.int64)
    major[ids[first]], top[ids[first]] = classes[first], counts[first]
    size = np.bincount(surface, minlength=n)
    return major, top / np.maximum(size, 1), size


def _on_surface_share(
    clusters: npt.NDArray[np.int32], surface: npt.NDArray[np.int32]
) -> npt.NDArray[np.float64]:
    """Return per point the share of its cluster's points on its surface (0: no cluster)."""
    _, cluster_row = np.unique(clusters, return_inverse=True)
    _, pair_row, pair_count = np.unique(
        cluster_row.astype(np.int64) * (int(surface.max()) + 1) + surface,
        return_inverse=True,
        return_counts=True,
    )
    share = pair_count[pair_row] / np.bincount(cluster_row)[cluster_row]
    return np.where(clusters > 0, share, 0.0)
