"""A segment the network saw, left unlabelled by phase II, joins the one object class it touches.

The network sometimes gives a whole segment a class that cannot be right: a chair's back seen
against the floor, called floor 0.6 m above it (fused map of simulated recording seed 9: 283
points). The plane step takes "floor" above the floor away (walls.floor_said_above), and what
is left is unlabelled. Regrowth refills an object only within its box and r1 (regrowth.py), and
DBSCAN kept only the back's edge as a chair cluster, so the box is a strip and the back stays
unlabelled. Here the unlabelled points are joined into segments (points within `LINK` point
spacings), and a segment takes the class of the objects it touches when:
- the network labelled at least `SAID` of its points (it saw something there; a segment the
  network left unlabelled is furniture it has no class for, a cabinet beside a chair: without
  this test the synthetic office lost 0.044 F1, generator 5's office at 60k 0.074),
- at least `MIN_CONTACT` of its points touch object points, and `SHARE` of those are of one
  class (fewer, down to a single one, suffice where the network called most of the segment
  that class: a chair's back touching its seat's cluster at a corner, 7 contacts, 59 of its 89
  points called chair, in a fresh recording; four pieces of 20-37 points touching a chair at
  1-2 points, all chair, in four others; its "floor" above the floor counting as seen, as for
  lone objects below: a chair's base with 49 such floor and 10 chair labels), and
- that class is not table: what touches only a desk stands on it or under it (as in pieces.py).
The segment joins the cluster its contacts touch most; its points count as regrown.

A segment that touches no object at all is an object the network saw whole and DBSCAN dropped
for its size: a chair's leg or the edge of a table at the border of a fused map, seen in a few
frames, 20-120 points apart from the rest (sixteen fresh simulated recordings: 16 such segments of
50 points or more, 89 % of their points of the class the network gave them). `lone_objects` makes
such a segment an object of its own when it has at least `min_points` points (the refinement's
min_cluster_points), the network gave `SAID` of them an object class (or "floor" above the
floor, a class that cannot be right there: a seat seen against the floor, 85 chair and 90 floor
labels at 0.7 m in a fresh recording), and one class holds more than half of the object
labels: touching nothing, the segment has no object of another class to dispute it, and the
network often splits a leg between chair and table (a table's leg at a fused map's border, 115
table, 76 chair and 101 floor labels, all table). A wrong-class blob on
an object touches that object and is left to the rules above.

A segment that touches nothing and that the network saw too little of to be an object on its
own may still be part of one above it (`standing_bases`): an office chair's base, 3-27 cm over
the floor, 40 cm under its seat, that the network calls chair on 23-49 % of its points; DBSCAN
drops those labels as noise, regrowth cannot cross the gap to the seat, and under a desk the
base lies in the desk's box too, so its chair labels do not rejoin the chair (generator 5's
seed 7: six bases, 4,500 points). When the network gives `UNDER_SAID` of its points one class
that stands on the floor (regrowth.STANDING), the most of its object labels, and a cluster of
that class above it has `UNDER_SHARE` of it under its plan, it joins that cluster; so does a
segment that touches an object but was seen too little (under `SAID`) to join it. Its points
in the floor plane's RANSAC band stay out: floor that the floor's tightened band gave back
touches a base, and grown to the floor a chair the network called sofa no longer passed as a
chair's shape (a fresh generator-5 room: 0.959 -> 0.923 with them, 0.963 without).

Written here because no library adopts segments by contact; the graph's connected components
are SciPy's (graph.py).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from capture.recording import OBJECT_LABELS, Label
from process.refine.graph import components, kd_tree, knn_edges, point_spacing
from process.refine.plane_grid import over_footprint, plane_uv
from process.refine.regrowth import STANDING

NEIGHBOURS = 8  # graph edges per unlabelled point
LINK = 2.5  # unlabelled points within this many point spacings are one segment
SAID = 0.5  # share of a segment's points the network labelled (any class; lone: an object class)
MIN_CONTACT = 10  # points of a segment within LINK spacings of an object point, or any
# number where the network called most of the segment the class its contacts hold
SHARE = 0.95  # of a segment's contacts touch objects of the class it takes
UNDER_SAID = 0.15  # a segment under an object of a standing class: this share of its
# points the network gave that class (the most of its object labels) ...
UNDER_SHARE = 0.5  # ... and this share of its points under the object's plan ...
UNDER_CELL_M = 0.1  # ... (its cells of this size and their neighbours) joins that object


def adopt_orphans(
    points: npt.NDArray[np.floating],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    rows: npt.NDArray[np.intp],
    said: npt.NDArray[np.uint8],
    *,
    misnamed: npt.NDArray[np.bool_] | None = None,
    up: npt.NDArray[np.float64] | None = None,
    ground: npt.NDArray[np.bool_] | None = None,
) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.int32], npt.NDArray[np.intp]]:
    """Return (labels, clusters, adopted rows): unlabelled segments given to the class they touch.

    Args:
        points: (N, 3) positions.
        labels: (N,) classes after regrowth; object points with clusters > 0 are the objects.
        clusters: (N,) object id per point (0: none).
        rows: indices of the unlabelled points that may join an object (not structure, not an
            outlier, not kept out of regrowth).
        said: (N,) the network's labels (phase I, as recorded): 0 where it saw nothing.
        misnamed: (N,) points whose network class cannot be right there (its "floor" above
            the floor): where a segment has few contacts, they count as seen (as in
            `lone_objects`) and its object labels name the class.
        up: gravity-up; with it, a segment seen too little to join what it touches joins the
            object of a standing class above it (`_host_above`), bar its points in `ground`.
        ground: (N,) the floor plane's inliers (RANSAC's band): floor its tightened band gave
            back, which a base's segment takes along where it touches the floor.
    """
    labels, clusters = labels.copy(), clusters.copy()
    found = _unlabelled_segments(points, labels, clusters, rows, 1)
    if found is None:
        return labels, clusters, np.zeros(0, np.intp)
    held, rows, segment, dist, nearest = found
    touching = np.isfinite(dist)
    adopted: list[npt.NDArray[np.intp]] = []
    for seg in np.unique(segment[touching]):
        members = np.flatnonzero(segment == seg)
        contact = held[nearest[members[touching[members]]]]
        if np.mean(said[rows[members]] != 0) < SAID:  # every segment here has a contact
            if up is not None:  # seen in part, under its own object: a chair's base, a leg
                adopted.append(
                    _join_host(points, labels, clusters, rows[members], said, up, ground)
                )
            continue
        classes, counts = np.unique(labels[contact], return_counts=True)
        best = int(classes[np.argmax(counts)])
        if counts.max() < SHARE * len(contact) or best == Label.TABLE:
            continue
        if len(contact) < MIN_CONTACT:
            wrong = 0 if misnamed is None else int(misnamed[rows[members]].sum())
            if _majority(said[rows[members]], wrong) != best:
                continue
        ids, id_counts = np.unique(clusters[contact[labels[contact] == best]], return_counts=True)
        labels[rows[members]] = best
        clusters[rows[members]] = ids[np.argmax(id_counts)]
        adopted.append(rows[members])
    done = np.sort(np.concatenate(adopted)) if adopted else np.zeros(0, np.intp)
    return labels, clusters, done


def lone_objects(
    points: npt.NDArray[np.floating],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    rows: npt.NDArray[np.intp],
    said: npt.NDArray[np.uint8],
    *,
    min_points: int,
    misnamed: npt.NDArray[np.bool_] | None = None,
    up: npt.NDArray[np.float64] | None = None,
    ground: npt.NDArray[np.bool_] | None = None,
) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.int32], npt.NDArray[np.intp]]:
    """Return (labels, clusters, rows made objects): unlabelled segments touching no object.

    Args as `adopt_orphans`; `min_points`: the fewest points of a segment that becomes an
    object; `misnamed`: (N,) points the network gave a class that cannot be right there (its
    "floor" above the floor): they count as seen, and the class is the object labels' majority.
    Each such segment becomes a cluster of its own (ids above every id in use). With `up`
    (gravity-up), a segment the network saw too little of to be an object on its own joins the
    object of a standing class above it (`_host_above`), bar its points in `ground` (as in
    `adopt_orphans`).
    """
    labels, clusters = labels.copy(), clusters.copy()
    found = _unlabelled_segments(points, labels, clusters, rows, max(min_points, 1))
    if found is None:
        return labels, clusters, np.zeros(0, np.intp)
    _, rows, segment, dist, _ = found
    touching = np.unique(segment[np.isfinite(dist)])
    large = np.flatnonzero(np.bincount(segment) >= min_points)
    made: list[npt.NDArray[np.intp]] = []
    next_id = int(clusters.max(initial=0)) + 1
    for seg in np.setdiff1d(large, touching):
        members = rows[segment == seg]
        wrong = 0 if misnamed is None else int(misnamed[members].sum())
        best = _majority(said[members], wrong)  # touching nothing, no class disputes it
        if best:
            labels[members], clusters[members] = best, next_id
            next_id += 1
            made.append(members)
        elif up is not None:  # seen in part, under its own object: a chair's base, a leg
            made.append(_join_host(points, labels, clusters, members, said, up, ground))
    done = np.sort(np.concatenate(made)) if made else np.zeros(0, np.intp)
    return labels, clusters, done


def _join_host(
    points: npt.NDArray[np.floating],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    members: npt.NDArray[np.intp],
    said: npt.NDArray[np.uint8],
    up: npt.NDArray[np.float64],
    ground: npt.NDArray[np.bool_] | None,
) -> npt.NDArray[np.intp]:
    """Give a segment, bar its `ground` points, to the object above it (in place); return it.

    Nothing changes (and nothing is returned) where `_host_above` finds no host.
    """
    if ground is not None:
        members = members[~ground[members]]
    host = _host_above(points, labels, clusters, members, said[members], up) if len(members) else 0
    if not host:
        return np.zeros(0, np.intp)
    labels[members], clusters[members] = labels[clusters == host][0], host
    return members


def _host_above(
    points: npt.NDArray[np.floating],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    members: npt.NDArray[np.intp],
    said: npt.NDArray[np.uint8],
    up: npt.NDArray[np.float64],
) -> int:
    """Return the cluster of a standing class that a segment lies under and is part of, or 0.

    The network gave `UNDER_SAID` of the segment's points (`said`) one standing class, the
    most of its object labels; a cluster of that class, above the segment's 90th height
    percentile, has `UNDER_SHARE` of the segment's points under its plan.
    """
    seen = said[np.isin(said, OBJECT_LABELS)]
    if len(seen) < UNDER_SAID * len(said):
        return 0
    classes, counts = np.unique(seen, return_counts=True)
    best = int(classes[np.argmax(counts)])
    if 2 * counts.max() <= len(seen) or best not in STANDING:
        return 0
    level = np.array([*up, 0.0])
    height = np.asarray(points[members], np.float64) @ up
    uv = plane_uv(np.asarray(points[members], np.float32), level)
    lo, hi = uv.min(axis=0) - UNDER_CELL_M, uv.max(axis=0) + UNDER_CELL_M
    above = np.flatnonzero((labels == best) & (clusters > 0))
    above = above[np.asarray(points[above], np.float64) @ up > np.percentile(height, 90)]
    plan = plane_uv(np.asarray(points[above], np.float32), level)
    near = np.all((plan >= lo) & (plan <= hi), axis=1)
    host, share = 0, UNDER_SHARE
    for cluster in np.unique(clusters[above[near]]):
        own = plan[near][clusters[above[near]] == cluster]
        under = float(over_footprint(own, uv, UNDER_CELL_M, diagonal=True).mean())
        if under >= share:
            host, share = int(cluster), under
    return host


def _majority(said: npt.NDArray[np.uint8], misnamed: int = 0) -> int:
    """Return the class holding over half of these points' object labels, or 0.

    0 also where fewer than `SAID` of the points have an object label or are among the
    `misnamed` (a class the network gave that cannot be right there: its "floor" above the
    floor). Misnamed points carry no class: what few object labels there are name it (fresh
    recording 64: two chair bases 2-28 cm up, 110 floor and 14 chair labels, 127 and 7, both
    chair; TUM fr1_rpy: a desk's side panel, 963 floor and 12 table labels, made table).
    """
    seen = said[np.isin(said, OBJECT_LABELS)]
    if not len(seen) or len(seen) + misnamed < SAID * len(said):
        return 0
    classes, counts = np.unique(seen, return_counts=True)
    return int(classes[np.argmax(counts)]) if 2 * counts.max() > len(seen) else 0


def _unlabelled_segments(
    points: npt.NDArray[np.floating],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    rows: npt.NDArray[np.intp],
    fewest: int,
) -> (
    tuple[
        npt.NDArray[np.intp],
        npt.NDArray[np.intp],
        npt.NDArray[np.int32],
        npt.NDArray[np.float64],
        npt.NDArray[np.intp],
    ]
    | None
):
    """Return the unlabelled rows' segments and their nearest object points, or None.

    (object points, unlabelled rows, a segment id per row, distance and index of each row's
    nearest object point within LINK spacings: inf and len(objects) beyond); None when fewer
    than `fewest` rows are unlabelled or there are no objects.
    """
    held = np.flatnonzero(np.isin(labels, OBJECT_LABELS) & (clusters > 0))
    rows = rows[labels[rows] == 0]
    if len(rows) < fewest or len(held) < 2:
        return None
    objects = kd_tree(np.asarray(points[held], np.float64))
    link = LINK * point_spacing(points[held], objects)
    xyz = np.asarray(points[rows], np.float64)
    dist, nearest = objects.query(xyz, distance_upper_bound=link, workers=-1)
    return held, rows, _segments(xyz, link), dist, nearest


def _segments(xyz: npt.NDArray[np.float64], link: float) -> npt.NDArray[np.int32]:
    """Return a segment id per point: components of the graph of neighbours within link."""
    k = min(NEIGHBOURS + 1, len(xyz))
    i, j, length = knn_edges(*kd_tree(xyz).query(xyz, k, distance_upper_bound=link, workers=-1))
    ok = np.isfinite(length)
    return components(len(xyz), i[ok], j[ok])[1]
