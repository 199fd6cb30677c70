"""Neighbour graphs over points: the k-NN edge list and its connected components.

The seam vote (seams.py), the piece vote (pieces.py), orphan adoption (orphans.py) and the
object grouping (objects.py) each link points or clusters and take the components: SciPy's.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

SPACING_SAMPLE = 20_000  # points whose nearest neighbour gives the point spacing


def point_spacing(
    points: npt.NDArray[np.floating], tree: cKDTree | None = None, *, sample: int = SPACING_SAMPLE
) -> float:
    """Return the median distance from an even sample of the points to their nearest other one.

    `tree`, if given, is a k-d tree of these points (it is built otherwise); about `sample`
    points, every k-th, are asked.
    """
    if len(points) < 2:
        return 0.0
    tree = cKDTree(np.asarray(points, np.float64)) if tree is None else tree
    probe = np.asarray(points[:: max(1, len(points) // sample)], np.float64)
    return float(np.median(tree.query(probe, 2)[0][:, 1]))


def knn_edges(
    dist: npt.NDArray[np.float64], nb: npt.NDArray[np.intp]
) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp], npt.NDArray[np.float64]]:
    """Return (i, j, length) of every point's edges to its neighbours (itself first in nb)."""
    k = nb.shape[1] - 1
    return np.repeat(np.arange(len(nb)), k), nb[:, 1:].ravel(), dist[:, 1:].ravel()


def components(
    n: int, i: npt.NDArray[np.intp], j: npt.NDArray[np.intp]
) -> tuple[int, npt.NDArray[np.int32]]:
    """Return (count, component id per node) of the undirected graph of n nodes, edges i-j."""
    graph = coo_matrix((np.ones(len(i)), (i, j)), shape=(n, n))
    count, ids = connected_components(graph.tocsr(), directed=False)
    return int(count), np.asarray(ids, np.int32)


def radius_components(points: npt.NDArray[np.floating], radius: float) -> npt.NDArray[np.int32]:
    """Return a component id per point: the components of the graph of pairs within `radius`."""
    pairs = cKDTree(points).query_pairs(radius, output_type="ndarray")
    return components(len(points), pairs[:, 0], pairs[:, 1])[1]


def class_pieces(
    dist: npt.NDArray[np.float64],
    nb: npt.NDArray[np.intp],
    labels: npt.NDArray[np.uint8],
    link_spacings: float,
) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp], int, npt.NDArray[np.int32]]:
    """Return the k-NN edges (i, j) shorter than `link_spacings` point spacings, and the pieces.

    A piece is a component of the edges between points of one label; the spacing is the
    median distance to the nearest neighbour (`dist[:, 1]`). Returns (i, j, count, piece).
    """
    link = link_spacings * float(np.median(dist[:, 1]))
    i, j, length = knn_edges(dist, nb)
    i, j = i[length < link], j[length < link]
    same = labels[i] == labels[j]
    count, piece = components(len(nb), i[same], j[same])
    return i, j, count, piece
