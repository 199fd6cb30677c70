"""Step 2: Statistical Outlier Removal (Open3D); after regrowth, the strays that rejoin."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from capture.recording import Label

LINK = 2.0  # a stray with another plant-labelled point this many point spacings away is a leaf
_PROBES = 2000  # points whose nearest neighbour gives the spacing


def sor_inliers(
    points: npt.NDArray[np.float32], *, nb_neighbors: int, std_ratio: float
) -> npt.NDArray[np.bool_]:
    """Return the mask of points that SOR keeps.

    A point is an outlier when its mean distance to its `nb_neighbors` nearest neighbours exceeds
    the mean of those distances over the cloud by `std_ratio` standard deviations. A cloud with
    no more than `nb_neighbors` points has no statistics to speak of and is kept whole.
    """
    keep = np.ones(len(points), bool)
    if len(points) <= nb_neighbors:
        return keep
    import open3d as o3d

    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points.astype(np.float64)))
    _, inliers = cloud.remove_statistical_outlier(nb_neighbors, std_ratio)
    keep[:] = False
    keep[np.asarray(inliers, np.intp)] = True
    return keep


def rejoin_strays(
    points: npt.NDArray[np.float32],
    strays: npt.NDArray[np.intp],
    network: npt.NDArray[np.uint8],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    r1_m: dict[int, float],
    *,
    max_waves: int = 50,
) -> npt.NDArray[np.intp]:
    """Give a plant's strays back to it: its sparse foliage is no noise.

    SOR takes a plant's leaves for noise, and DBSCAN the sprigs it keeps (generator 4's offices
    and living rooms at 60k-200k object points: 130-1,100 plant points per room, 99 % of the
    object points SOR removed there, labelled plant by the network); regrowth reaches only
    inside the box of what DBSCAN kept. `strays` are such points: SOR's outliers and the
    network-labelled points still 0 after regrowth. One the network calls plant, with another
    plant-labelled point within LINK point spacings (the median spacing of the points the
    network calls plant: a leaf, not a lone flying pixel at a depth edge), joins the nearest
    refined plant point within r1 (the class's eps), in waves, so a sprig reaches back along
    its stem. Only plants: the strays of other classes are the network's speckle and flying
    pixels (generators 1, 3 and 5, a TSDF map and a recording's map: 1,000 of 5,300 such
    points were right), and so is a lone plant label (generator 3 room 0: 114 of 138 plant
    strays were flying pixels; with the company rule 102 of 143 rejoined on five such clouds
    are right, and 1,953 of 2,005 on nine of generator 4). `labels` and `clusters` (all N
    points) are updated in place; returns the indices that rejoined.
    """
    plant = int(Label.PLANT)
    waiting = strays[network[strays] == plant]
    if plant not in r1_m or len(waiting) == 0:
        return np.zeros(0, np.intp)
    tree = cKDTree(points[network == plant])
    probe = np.linspace(0, tree.n - 1, min(tree.n, _PROBES)).astype(np.intp)
    spacing = float(np.median(tree.query(tree.data[probe], 2)[0][:, 1]))
    company = tree.query(points[waiting], 2, distance_upper_bound=LINK * spacing)[0]
    waiting = waiting[np.isfinite(company[:, 1])]  # the stray itself is its first neighbour
    joined: list[npt.NDArray[np.intp]] = []
    hosts = np.flatnonzero((labels == plant) & (clusters > 0))  # the first wave's frontier
    for _ in range(max_waves):
        if len(hosts) == 0 or len(waiting) == 0:
            break
        distance, nearest = cKDTree(points[hosts]).query(
            points[waiting], distance_upper_bound=r1_m[plant]
        )
        hit = np.isfinite(distance)
        if not hit.any():
            break
        rows = waiting[hit]
        labels[rows] = plant
        clusters[rows] = clusters[hosts[nearest[hit]]]
        joined.append(rows)
        waiting, hosts = waiting[~hit], rows  # later waves reach from the last one's points
    return np.sort(np.concatenate(joined)) if joined else np.zeros(0, np.intp)
