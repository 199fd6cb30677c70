"""Step 2: Statistical Outlier Removal (Open3D); after regrowth, the strays that rejoin."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from capture.recording import Label
from process.refine.graph import kd_tree, point_spacing, radius_components
from process.refine.regrowth import frame

LINK = 2.0  # a stray with another plant-labelled point this many point spacings away is a leaf
STEM_SHARE = 0.5  # a stem rises within this share of its pot's half-width of the pot's middle
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
    up: npt.NDArray[np.float64] | None = None,
    crown_min: int = 1,
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
    are right, and 1,953 of 2,005 on nine of generator 4). With `up`, the plant-labelled
    strays the waves leave, alone or not, join a plant as its crown when they form a group of
    at least `crown_min` points over it (`_crowns`), and then the unlabelled strays over the
    middle of its pot as its stem (`_stems`). `labels` and `clusters` (all N points) are
    updated in place; returns the indices that rejoined.
    """
    plant = int(Label.PLANT)
    mine = waiting = strays[network[strays] == plant]
    if plant not in r1_m or len(waiting) == 0:
        return np.zeros(0, np.intp)
    tree = kd_tree(points[network == plant])
    spacing = point_spacing(tree.data, tree, sample=_PROBES)
    company = tree.query(points[waiting], 2, distance_upper_bound=LINK * spacing)[0]
    waiting = waiting[np.isfinite(company[:, 1])]  # the stray itself is its first neighbour
    hosts = np.flatnonzero((labels == plant) & (clusters > 0))  # the first wave's frontier
    joined = [_waves(points, waiting, hosts, labels, clusters, r1_m[plant], max_waves)]
    left = mine[labels[mine] == 0]  # the waves' leftovers and the lone ones: a crown's leaves
    if up is not None and len(left):
        rotate = frame(up)
        crowned = _crowns(points, left, labels, clusters, r1_m[plant], rotate, crown_min)
        joined.append(crowned)
        bare = strays[(network[strays] == 0) & (labels[strays] == 0)]
        for cluster in np.unique(clusters[crowned]):
            pot = np.setdiff1d(np.flatnonzero(clusters == cluster), crowned, assume_unique=True)
            stem = _stems(points, bare, labels, clusters, pot, cluster, r1_m[plant], rotate)
            joined.append(stem)
    return np.sort(np.concatenate(joined))


def _waves(
    points: npt.NDArray[np.float32],
    waiting: npt.NDArray[np.intp],
    hosts: npt.NDArray[np.intp],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    r1_m: float,
    max_waves: int,
) -> npt.NDArray[np.intp]:
    """Grow plant `hosts` over `waiting` in waves within r1; return who joined (in place).

    A joining point takes the cluster of its nearest host; each wave reaches from the points
    the last one joined.
    """
    joined: list[npt.NDArray[np.intp]] = [np.zeros(0, np.intp)]
    for _ in range(max_waves):
        if len(hosts) == 0 or len(waiting) == 0:
            break
        distance, nearest = kd_tree(points[hosts]).query(points[waiting], distance_upper_bound=r1_m)
        hit = np.isfinite(distance)
        if not hit.any():
            break
        rows = waiting[hit]
        labels[rows] = Label.PLANT
        clusters[rows] = clusters[hosts[nearest[hit]]]
        joined.append(rows)
        waiting, hosts = waiting[~hit], rows
    return np.concatenate(joined)


def _crowns(
    points: npt.NDArray[np.float32],
    waiting: npt.NDArray[np.intp],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    r1_m: float,
    rotate: npt.NDArray[np.float64],
    min_points: int,
) -> npt.NDArray[np.intp]:
    """Join the plant strays beyond r1 of any plant that form a crown over one; return them.

    A tall plant whose stem the network missed keeps only its pot after DBSCAN, and its sparse
    foliage, more than r1 above the pot, has no refined point to reach back to (generator 4's
    living rooms at 200k object points: 690-1,270 plant-labelled points a room, 99.8 % of them
    plant). The strays, linked at r1, form groups; a group whose plan centre lies over a
    refined plant's plan box (grown by r1) and that reaches above that plant's top is its
    crown, and joins its cluster. Not a group wholly below the top: there the strays hug a
    whole plant's flanks, and were flying pixels at its silhouette (generator 3's rooms 0 and
    7: 153 of 171 such points truth 0). Not a group of fewer than `min_points` (the class's
    cluster size): the 1-4 plant labels scattered over a room, flying pixels and speckle
    (generator 1's office and generator 5's living room: 13 and 17 such groups, 2 of their
    40 and 28 points plant); generator 4's crowns are 15-350 points.
    `rotate` turns the points into a frame with z up (regrowth.frame).
    """
    plant = int(Label.PLANT)
    xyz = points[waiting].astype(np.float64) @ rotate.T
    group = radius_components(xyz, r1_m)
    refined = np.flatnonzero((labels == plant) & (clusters > 0))
    ids, row = np.unique(clusters[refined], return_inverse=True)
    if len(ids) == 0:
        return np.zeros(0, np.intp)
    mine = points[refined].astype(np.float64) @ rotate.T
    low = np.full((len(ids), 3), np.inf)
    high = np.full((len(ids), 3), -np.inf)
    np.minimum.at(low, row, mine)
    np.maximum.at(high, row, mine)
    count = np.bincount(group).astype(np.float64)
    centre = np.column_stack([np.bincount(group, xyz[:, i]) / count for i in (0, 1)])
    top = np.full(len(count), -np.inf)
    np.maximum.at(top, group, xyz[:, 2])
    over = np.all(
        (centre[:, None] > low[None, :, :2] - r1_m) & (centre[:, None] < high[None, :, :2] + r1_m),
        axis=2,
    )  # (groups, plants)
    over &= (top[:, None] > high[None, :, 2]) & (count[:, None] >= min_points)
    middle = (low[:, :2] + high[:, :2]) / 2  # of several, the plant whose plan centre is nearest
    gap = np.where(over, np.linalg.norm(centre[:, None] - middle[None], axis=2), np.inf)
    host = np.where(over.any(axis=1), np.argmin(gap, axis=1), -1)[group]
    rows: npt.NDArray[np.intp] = waiting[host >= 0]
    labels[rows], clusters[rows] = plant, ids[host[host >= 0]]
    return rows


def _stems(
    points: npt.NDArray[np.float32],
    bare: npt.NDArray[np.intp],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    pot: npt.NDArray[np.intp],
    cluster: int,
    r1_m: float,
    rotate: npt.NDArray[np.float64],
    max_waves: int = 50,
) -> npt.NDArray[np.intp]:
    """Grow a crowned plant's cluster over the unlabelled strays of its stem; return them.

    The stem the network missed joins the pot to its crown (generator 4's tall plants: up to a
    metre of it, 0.5-1 % of a living room's object points), and regrowth, which ran before the
    crown joined, did not reach it. `bare` points (label 0 and no network label, not behind a
    wall, not on a bare face) between the plant's lowest and highest point, over the middle of
    its `pot` (the cluster's points before the crown: within STEM_SHARE of its half-width of
    its plan centre), join in waves within r1 of the plant's points. Only over the middle:
    over the whole plant's box the waves climbed a wall the pot stands against that RANSAC
    had found no plane in (generator 3's room 2: 1,677 wall points); over the middle, all
    4,829 points that joined on 25 fresh generator-4 living rooms were plant, and none joined
    on generator 3's rooms.
    """
    mine = np.flatnonzero(clusters == cluster)
    xyz = points[mine].astype(np.float64) @ rotate.T
    low, high = xyz.min(axis=0), xyz.max(axis=0)
    base = points[pot].astype(np.float64) @ rotate.T
    corner, far = base[:, :2].min(axis=0), base[:, :2].max(axis=0)
    candidates = points[bare].astype(np.float64) @ rotate.T
    inside = (candidates[:, 2] >= low[2]) & (candidates[:, 2] <= high[2])
    off = np.linalg.norm(candidates[:, :2] - (corner + far) / 2, axis=1)
    inside &= off <= STEM_SHARE * float(np.min(far - corner)) / 2
    waiting = bare[inside & (labels[bare] == 0)]
    return _waves(points, waiting, mine, labels, clusters, r1_m, max_waves)
