"""The paper's adaptive DBSCAN written literally (O(n^2), K = 1..n-1), small test clouds, and
the checks every vote after regrowth shares."""

from __future__ import annotations

import dataclasses
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from process.cloud import LabelledCloud
from process.refine import RefineConfig, RefineResult, refine
from process.refine.job import refinement_metrics
from viz.logger import NullLogger

UP = np.array([0.0, 0.0, 1.0])  # gravity-up of the small test clouds
FLOOR_Z0 = np.array([0.0, 0.0, -1.0, 0.0])  # the plane z = 0, its normal down as RANSAC may give it


def literal_dbscan(
    dist: npt.NDArray[np.float64], eps: float, min_pts: int
) -> npt.NDArray[np.int64]:
    """Return DBSCAN labels (-1 noise) by Ester et al.'s expansion on a full distance matrix."""
    n = len(dist)
    labels = np.full(n, -2, np.int64)  # -2 unvisited, -1 noise
    cluster = -1
    for p in range(n):
        if labels[p] != -2:
            continue
        neighbours = np.flatnonzero(dist[p] <= eps)
        if len(neighbours) < min_pts:
            labels[p] = -1
            continue
        cluster += 1
        labels[p] = cluster
        seeds = deque(int(q) for q in neighbours)
        while seeds:
            q = seeds.popleft()
            if labels[q] == -1:
                labels[q] = cluster  # border point
            if labels[q] != -2:
                continue
            labels[q] = cluster
            reach = np.flatnonzero(dist[q] <= eps)
            if len(reach) >= min_pts:
                seeds.extend(int(r) for r in reach)
    return labels


@dataclass(frozen=True)
class Literal:
    """The literal computation's curves over K = 1..n-1 and the chosen index (K - 1)."""

    eps: list[float]
    min_pts: list[int]
    n_clusters: list[int]
    chosen: int | None  # None: no stable run


def literal_parameters(points: npt.NDArray[np.floating]) -> Literal:
    """Return the paper's Eq. 1-6 for K = 1..n-1 and the first stable run's largest K."""
    p = np.asarray(points, np.float64)
    dist = np.sqrt(((p[:, None, :] - p[None, :, :]) ** 2).sum(axis=2))  # Eq. 1-2
    ordered = np.sort(dist, axis=1)  # column 0 = the point itself (D_0)
    n = len(p)
    eps_list, min_pts_list, counts = [], [], []
    for k in range(1, n):
        eps = float(ordered[:, k].mean())  # Eq. 3-4
        mean_count = float((dist <= eps).sum(axis=1).mean())  # Eq. 5-6, the point included
        min_pts = max(4, int(np.floor(mean_count + 0.5)))
        labels = literal_dbscan(dist, eps, min_pts)
        eps_list.append(eps)
        min_pts_list.append(min_pts)
        counts.append(int(labels.max()) + 1)
    chosen = None  # index of the largest K of the first run of >= 3 equal, non-zero counts
    i = 0
    while i < len(counts) and chosen is None:
        j = i
        while j + 1 < len(counts) and counts[j + 1] == counts[i]:
            j += 1
        if counts[i] > 0 and j - i + 1 >= 3:
            chosen = j
        i = j + 1
    return Literal(eps_list, min_pts_list, counts, chosen)


def blobs(
    seed: int, *, sizes: tuple[int, ...], spread: float = 0.05, noise: int = 5
) -> npt.NDArray[np.float64]:
    """Return Gaussian blobs (one per size) 0.5 m apart plus uniform noise points."""
    rng = np.random.default_rng(seed)
    parts = [rng.normal((0.5 * i, 0.2 * (i % 2), 0.0), spread, (m, 3)) for i, m in enumerate(sizes)]
    parts.append(rng.uniform(-0.3, 0.5 * len(sizes), (noise, 3)))
    return np.concatenate(parts)


def grid_patch(
    x: tuple[float, float], y: tuple[float, float], *, z: float = 0.0, step: float = 0.02
) -> npt.NDArray[np.float32]:
    """Return a horizontal grid of points over [x0, x1) x [y0, y1) at height z."""
    gx, gy = np.meshgrid(np.arange(x[0], x[1] - 1e-9, step), np.arange(y[0], y[1] - 1e-9, step))
    return np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, z)]).astype(np.float32)


def labelled(points: npt.NDArray[np.floating], labels: npt.ArrayLike) -> LabelledCloud:
    """Return a grey cloud with the given labels (a scalar is broadcast)."""
    pts = np.asarray(points, np.float32)
    lab = np.broadcast_to(np.asarray(labels, np.uint8), (len(pts),)).copy()
    return LabelledCloud(pts, np.full((len(pts), 3), 128, np.uint8), lab)


class RecordingLogger(NullLogger):
    """A logger that records each call as (method, first argument, keyword arguments)."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, object, dict[str, Any]]] = []

    def __getattribute__(self, method: str) -> Any:
        if not method.startswith(("log_", "set_")):
            return object.__getattribute__(self, method)
        calls = object.__getattribute__(self, "calls")

        def record(first: object = None, *_: object, **kwargs: Any) -> None:
            calls.append((method, first, kwargs))

        return record


def clustered(
    parts: list[npt.NDArray[np.floating]], labels: npt.ArrayLike
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.uint8], npt.NDArray[np.int32]]:
    """Return (points, labels, clusters): the parts as one cloud, part i labelled `labels[i]`
    (one label: all of them) and in cluster i + 1."""
    sizes = [len(p) for p in parts]
    names = np.broadcast_to(np.asarray(labels, np.uint8), (len(parts),))
    clusters = np.repeat(np.arange(1, len(parts) + 1, dtype=np.int32), sizes)
    return np.concatenate(parts).astype(np.float32), np.repeat(names, sizes), clusters


def box_on_floor(x: float, y: float, size: float, height: float) -> npt.NDArray[np.float32]:
    """The four sides and the top of a box standing on the floor, at 1 cm spacing."""
    face = grid_patch((0.0, size), (0.0, height), step=0.01)
    front, side = face[:, [0, 2, 1]], face[:, [2, 0, 1]]
    top = grid_patch((0.0, size), (0.0, size), z=height, step=0.01)
    dy, dx = np.array([0.0, size, 0.0], np.float32), np.array([size, 0.0, 0.0], np.float32)
    sides = [front, front + dy, side, side + dx, top]
    return (np.concatenate(sides) + np.array([x, y, 0.0], np.float32)).astype(np.float32)


def counted_shown_and_switched_off(
    cloud: LabelledCloud,
    result: RefineResult,
    kept: npt.NDArray[np.intp],
    field: str,
    metric: str,
    switch: str,
) -> None:
    """The rule's points (`field` of the result) are counted in metrics.json (`metric`) and
    shown with the votes in the .rrd; with the rule off (`switch`, off in `paper()`), the `kept`
    points keep the class DBSCAN gave them and the rule moves nothing."""
    moved = getattr(result, field)
    assert refinement_metrics(result, gt_cloud=None)["points"][metric] == len(moved)
    shown = {tuple(p) for p in result.seam_cloud().points.tolist()}  # the .rrd's votes entity
    assert {tuple(p) for p in cloud.points[kept].tolist()} <= shown
    rule_off: dict[str, Any] = {switch: False}
    off = refine(cloud, dataclasses.replace(RefineConfig(), **rule_off), up=UP)
    assert (off.labels_iii[kept] == result.labels_ii[kept]).all() and len(getattr(off, field)) == 0
    assert not getattr(RefineConfig.paper(), switch)
