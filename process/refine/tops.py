"""A table's top is the table's: a stretch the network called a seat, and its table left 0.

A network confuses a desk's top, seen from above at a slant, with a seat or a lap: on fused maps
of simulated recordings it labels a 0.3 x 0.45 m stretch of a desk chair (fresh recording 85:
176 points, with the boxes on it), and on generators 2 and 4 whole stretches of meeting and
office tables chair, sofa or person (100-1,500 points a cluster). DBSCAN keeps each as an object
of its own and the later votes keep it: its surface is its own majority. The plane step found
the top (`surfaces.table_surfaces`) but leaves a cell the network calls a seat more than a desk
to that class, for a sofa's back whose level top joins a table's piece is the sofa's.

The two differ in where the rest of their object lies: a sofa's or a chair's cluster is mostly
off the top (its body stands under or beside it; its top edge is a strip), a stretch of the
desk lies mostly on it. A chair, person or sofa cluster with at least `TOP_SHARE` of its points
on a table's top gives those points to the table: to the table object that most of them within
`JOIN_M` of one lie near (its rim touches the rest of the desk), else to a table object of their
own. Its points off the top keep their class (a forearm on the desk stands above its band).
A level surface the plane step took for a table's top but whose objects are mostly something
else (`TABLE_SHARE`) is no table's: a sofa's broad seat (generator 4's living room at 500k).

A desk seen from afar is sparse in a fused map: DBSCAN drops its points as noise, and regrowth,
which fills an object only near its box, does not reach them (fresh recording 79: 241 points of
a desk's top 4-50 cm from the table's cluster; 85, 90: 34-82). The plane step found them on a
table's top. `left_on_tops`: the points of a table's top that the network itself calls table,
left unlabelled at the end where regrowth could have labelled them (no SOR outlier, nothing
behind a wall), join the table object holding most of that top. Not what the plane step made
table: on generator 3's room 5 that took 813 points of a wall's band at the desk's height, which
the later steps had left out. Taking the whole plane's inliers instead of the top took more on
the fresh recordings, but on generator 4 also a plant's points at the desk's height (293).
Written here because no library relabels by such a share; the table tops are the plane step's.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from capture.recording import OBJECT_LABELS, Label
from process.refine.graph import kd_tree

TOP_SHARE = 0.5  # of a cluster's points on a table's top
TABLE_SHARE = 0.5  # a top is a table's where table holds over this share of its object points
JOIN_M = 0.1  # the points join the table object nearest within this
SEATS = (Label.CHAIR, Label.PERSON, Label.SOFA)  # what a desk's top is taken for


def tops_called_seats(
    points: npt.NDArray[np.floating],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    tops: list[npt.NDArray[np.intp]],
) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.int32], npt.NDArray[np.intp]]:
    """Return (labels, clusters, relabelled indices) with table tops called a seat made table.

    `tops`: each table surface's points (`Plane.top`: its inliers, whatever their labels).
    """
    out_labels, out_clusters = labels.copy(), clusters.copy()
    none = np.zeros(0, np.intp)
    if not tops:
        return out_labels, out_clusters, none
    on_top = np.zeros(len(labels), bool)
    for top in tops:  # a level surface whose objects are mostly a seat is the seat's (a sofa's)
        said = labels[top][np.isin(labels[top], OBJECT_LABELS)]
        on_top[top] |= np.count_nonzero(said == Label.TABLE) > TABLE_SHARE * len(said)
    seat = np.isin(labels, SEATS) & (clusters > 0)
    if not (seat & on_top).any():
        return out_labels, out_clusters, none
    size = np.bincount(clusters[seat])
    on = np.bincount(clusters[seat & on_top], minlength=len(size))
    taken = np.flatnonzero((on > 0) & (on >= TOP_SHARE * size))
    rows = np.flatnonzero(seat & on_top & np.isin(clusters, taken))
    if len(rows) == 0:
        return out_labels, out_clusters, none
    host = np.zeros(len(rows), np.int32)  # the table object each point lies near (0: none)
    table = np.flatnonzero((labels == Label.TABLE) & (clusters > 0))
    if len(table):
        tree = kd_tree(np.asarray(points[table], np.float64))
        dist, nearest = tree.query(
            np.asarray(points[rows], np.float64), distance_upper_bound=JOIN_M
        )
        near = np.isfinite(dist)
        host[near] = clusters[table[nearest[near]]]
    next_id = int(clusters.max()) + 1
    for cluster in taken:  # one object each: the table most of its rim touches, else its own
        mine = clusters[rows] == cluster
        touching = host[mine][host[mine] > 0]
        if len(touching):
            out_clusters[rows[mine]] = np.bincount(touching).argmax()
        else:
            out_clusters[rows[mine]], next_id = next_id, next_id + 1
    out_labels[rows] = Label.TABLE
    return out_labels, out_clusters, rows


def left_on_tops(
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    tops: list[npt.NDArray[np.intp]],
    network: npt.NDArray[np.uint8],
    open_: npt.NDArray[np.bool_],
) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.int32], npt.NDArray[np.intp]]:
    """Return (labels, clusters, relabelled indices) with a top's table points left 0 made table.

    `tops`: each table surface's points (`Plane.top`); `network`: the network's labels
    (phase I); `open_`: the points that may take a label (regrowth's: not SOR's outliers, not
    behind a wall, not on a bare face). The points join the table object holding most of their
    top.
    """
    out_labels, out_clusters = labels.copy(), clusters.copy()
    changed = []
    for top in tops:
        table = top[(labels[top] == Label.TABLE) & (clusters[top] > 0)]
        if len(table) == 0:
            continue
        rows = top[(labels[top] == 0) & (network[top] == Label.TABLE) & open_[top]]
        rows = rows[out_labels[rows] == 0]  # not taken by an earlier top
        if len(rows):
            out_labels[rows] = Label.TABLE
            out_clusters[rows] = np.bincount(clusters[table]).argmax()
            changed.append(rows)
    return (
        out_labels,
        out_clusters,
        np.sort(np.concatenate(changed)) if changed else np.zeros(0, np.intp),
    )
