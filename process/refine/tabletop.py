"""After regrowth: small objects standing on a table that DBSCAN left as specks.

DBSCAN's MinPts is one density for a whole class: a mug or a box of clutter on a desk, a few
3 cm cells across, has no core cell, and its points go to 0. Regrowth keeps them off the table
(`table_top_m`), but no object of their class is near to take them back. Here the points still
0 that the network gave a class that stands on desks (ON_TABLES) are grouped, connected at half
that class's r1; a group of at least `min_points` whose lowest point lies on a table object's
top surface (`regrowth.table_tops`; from 3 cm below it to r1 above) and whose median lies over
that table becomes a new cluster of its class. On fused maps of simulated recordings every such
group was clutter in the ground truth; a wrong-class blob elsewhere (on a ceiling, a chair at
desk height labelled table) is not on a table's top, or not of such a class, and stays 0.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from capture.recording import Label
from process.refine.graph import radius_components
from process.refine.regrowth import frame, table_tops

_BELOW_TOP_M = 0.03  # a group's foot may sink this far into the top (plane noise)
# what stands on desks; a plant- or person-labelled blob on a desk was clutter (gen-2 room 5,
# gen-1 seed 0: 41 and 32 points), the network's confusion rather than a missed object
ON_TABLES = (Label.TV_MONITOR, Label.CLUTTER)


def tabletop_objects(
    points: npt.NDArray[np.float32],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    prior: npt.NDArray[np.uint8],
    *,
    r1_m: dict[int, float],
    up: npt.NDArray[np.float64],
    min_points: int,
    first_id: int,
) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.int32], npt.NDArray[np.intp]]:
    """Return labels and clusters with the groups on table tops added, and their indices.

    Args:
        points: (N, 3) the object cloud.
        labels: (N,) class per point after regrowth, 0 = none.
        clusters: (N,) cluster id per point, 0 = none.
        prior: (N,) the network's labels (phase I).
        r1_m: class label -> r1 (the class's chosen eps); a class without one adds nothing.
        up: gravity-up in the cloud's frame.
        min_points: the fewest points of a group (the refinement's min_cluster_points).
        first_id: the new clusters' ids count up from this (above every id in use).
    """
    labels, clusters = labels.copy(), clusters.copy()
    xyz = points.astype(np.float64) @ frame(up).T
    tops = _table_boxes(xyz, labels, clusters)
    if not tops:
        return labels, clusters, np.zeros(0, np.intp)
    open_ = np.flatnonzero((labels == 0) & np.isin(prior, ON_TABLES))
    added: list[npt.NDArray[np.intp]] = []
    next_id = max(first_id, int(clusters.max(initial=0)) + 1)
    for label in (int(c) for c in np.unique(prior[open_])):
        if label not in r1_m:
            continue
        members = open_[prior[open_] == label]
        group = radius_components(xyz[members], r1_m[label] / 2)
        for g in np.flatnonzero(np.bincount(group) >= min_points):
            idx = members[group == g]
            if _on_a_top(xyz[idx], tops, r1_m[label]):
                labels[idx], clusters[idx] = label, next_id
                next_id += 1
                added.append(idx)
    found = np.sort(np.concatenate(added)) if added else np.zeros(0, np.intp)
    return labels, clusters, found


def _table_boxes(
    xyz: npt.NDArray[np.float64], labels: npt.NDArray[np.uint8], clusters: npt.NDArray[np.int32]
) -> list[tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]]:
    """Return (low, high) in the up frame of every table cluster, high at its top surface."""
    desk = labels == Label.TABLE
    ids = np.unique(clusters[desk & (clusters > 0)])
    if len(ids) == 0:
        return []
    out = []
    tops = table_tops(xyz[:, 2], np.where(desk, clusters, 0), ids)
    for cid, top in zip(ids, tops, strict=True):
        mine = xyz[desk & (clusters == cid)]
        high = mine.max(axis=0)
        high[2] = top  # its surface, not labels bled onto what stands on it
        out.append((mine.min(axis=0), high))
    return out


def _on_a_top(
    group: npt.NDArray[np.float64],
    tops: list[tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]],
    reach_m: float,
) -> bool:
    """Return whether the group's foot lies on a table's top and its median over that table."""
    foot = float(group[:, 2].min())
    centre = np.median(group[:, :2], axis=0)
    for low, high in tops:
        level = high[2] - _BELOW_TOP_M <= foot <= high[2] + reach_m
        if level and bool(np.all((centre >= low[:2]) & (centre <= high[:2]))):
            return True
    return False
