"""A face one class's label bled onto across a gap takes the class of the object it belongs to.

A network's label bleeds a few centimetres across a gap onto the surface beyond it: the back of
a seated person's torso, 4 cm in front of the chair's back, takes the chair's label whole, and
the front of the chair's back the person's. DBSCAN's eps bridges the gap, so the bled face is
part of the other object's cluster; the seam vote (seams.py) leaves it, its own majority being
the wrong class. At the scale of the point spacing, though, the face is a piece of its own:
points of one class linked within `LINK` spacings. Such a piece takes the class of the points
it touches when:
- it is not the largest piece of its cluster and class (an object is its largest piece; a bled
  face hangs on it across the gap),
- `SHARE` of its contacts (neighbours of another class) are of one class, and they are many for
  its size (`CONTACT` times the square root of its points: along its rim, not at one spot),
- its contacts spread over it along each of its principal axes as its points do (`ENCLOSED`):
  a face bordered on every side, not a box whose foot stands on something,
- the piece it touches most is at least 1 / `RATIO` times its size, and
- neither class is table. What touches only a table is an object on it or under it (generator
  5, fused from ray-cast views: books on desks and chairs pushed under them, 15,000 chair and
  13,000 clutter points would have become table in 14 clouds); and a stretch of a cluttered
  desk's top between the things on it is bordered by them all round (TUM fr1_rpy: 369 points
  of the desk would have become clutter).

A bled face can also be a piece of its own, the largest of its cluster, or as large as the piece
it touches: the front of a chair's back, 3-4 cm behind a seated person, that the person's label
covers whole (generator 4's kitchen at 60k: 884 points). It is still taken, bordered all round
as above, when it is flat and lies between the two: points of its own class within `GAP_M` on
one side of it, of the class bordering it on the other (`_between`). The chair a person sits on
lies under them, with no more of the person beneath it; a cushion has no more of its class
behind it. Where the bleed swapped both faces, the person's back labelled chair and the chair's
front person, the chair's front has no person behind it until the person's back is given back:
the vote runs twice, the second time for faces between two classes only (generator 4's office
at 200k: 1,838 points of the chair's front, 0.940 -> 0.9496). A second pass of the first rule
would run on: pieces the first freed of a contact of another class become bordered (a seated
person's legs on a sofa, generator 4's living room at 60k: 271 points).

Written here because no library votes over such pieces; the graph's connected components are
SciPy's (graph.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from capture.recording import OBJECT_LABELS, Label
from process.refine.cells import class_cells
from process.refine.graph import class_pieces, kd_tree

NEIGHBOURS = 10  # graph edges per point
LINK = 2.5  # points of one class within this many point spacings are one piece
MIN_POINTS = 25  # smaller pieces keep their class (a cup on a chair's seat)
SHARE = 0.95  # of a piece's contacts are of the class it takes
CONTACT = 3.0  # contacts >= CONTACT * sqrt(points of the piece)
ENCLOSED = 0.6  # contacts' spread / the piece's spread, along each principal axis, at least
RATIO = 0.5  # a piece at most this share of the size of the piece it touches most
GAP_M = 0.06  # a face between its class and another's: both within this of it (_between) ...
FLAT = 0.01  # ... its least variance at most this share of its total (a face, not a body)
NEAR_SHARE = 0.2  # ... each class with at least this share of its size near it
SIDE_SHARE = 0.8  # ... and at least this share of those on its one side


@dataclass(frozen=True)
class PieceVote:
    """The labels after the vote and the points it relabelled (indices into the input)."""

    labels: npt.NDArray[np.uint8]
    relabelled: npt.NDArray[np.intp]


def piece_vote(
    points: npt.NDArray[np.floating],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    *,
    max_points: int = 400_000,
    neighbours: tuple[npt.NDArray[np.float64], npt.NDArray[np.intp]] | None = None,
) -> PieceVote:
    """Relabel the pieces of one class that another class's object holds on all sides.

    Args:
        points: (N, 3) positions.
        labels: (N,) class per point; only object classes form pieces or change.
        clusters: (N,) cluster id per point (0: none; a piece without one is left).
        max_points: past this many object points the vote runs on the centroids of each
            class's points per voxel (cells.class_cells), and every point takes its
            centroid's verdict: the graph's memory stays bounded.
        neighbours: the object points' nearest (distances, indices, NEIGHBOURS + 1 or more
            columns, itself first) in the order of their indices, if already at hand (the seam
            vote's, seams.SeamVote): used when the vote runs on the points, not on cells.
    """
    out = labels.copy()
    objects = np.flatnonzero(np.isin(labels, OBJECT_LABELS))
    if len(objects) <= NEIGHBOURS or len(np.unique(labels[objects])) < 2:
        return PieceVote(out, np.zeros(0, np.intp))
    xyz = np.asarray(points[objects], np.float32)
    own, ids = labels[objects], clusters[objects]
    group = np.arange(len(objects))
    if len(objects) > max_points:
        xyz, own, ids, group = class_cells(xyz, own, ids, max_points)
        neighbours = None
    xyz64 = np.asarray(xyz, np.float64)
    k = min(NEIGHBOURS, len(xyz64) - 1)
    if neighbours is None or len(neighbours[0]) != len(xyz64) or neighbours[0].shape[1] <= k:
        neighbours = kd_tree(xyz64).query(xyz64, k + 1, workers=-1)
    dist, nb = neighbours[0][:, : k + 1], neighbours[1][:, : k + 1]
    first = _vote(xyz64, own, ids, dist, nb)
    # the second pass sees the faces the first gave back (the module's docstring)
    new = _vote(xyz64, first, ids, dist, nb, between_only=True) if (first != own).any() else first
    new = new[group]
    flip = new != labels[objects]
    out[objects[flip]] = new[flip]
    return PieceVote(out, objects[flip])


def _vote(
    xyz: npt.NDArray[np.float64],
    own: npt.NDArray[np.uint8],
    ids: npt.NDArray[np.int32],
    dist: npt.NDArray[np.float64],
    nb: npt.NDArray[np.intp],
    *,
    between_only: bool = False,
) -> npt.NDArray[np.uint8]:
    """Return the labels after the vote, for points each of one class and one cluster.

    `dist` and `nb` hold each point's nearest neighbours, itself first; `between_only`: only
    faces between two classes (`_between`) change.
    """
    i, j, count, piece = class_pieces(dist, nb, own, LINK)
    same = own[i] == own[j]
    size = np.bincount(piece, minlength=count)
    cluster = _main_cluster(piece, ids, count)
    label = np.zeros(count, np.uint8)
    label[piece] = own
    # the largest piece of each (cluster, class) is the object itself
    key = cluster.astype(np.int64) * 256 + label
    _, key_row = np.unique(key, return_inverse=True)
    largest = np.zeros(key_row.max() + 1, np.int64)
    np.maximum.at(largest, key_row, size)
    main = size >= largest[key_row]
    # contacts: edges to points of another class
    ci, cj = i[~same], j[~same]
    other, share, total = _top_contact(piece[ci], own[cj], count)
    to_top = own[cj] == other[piece[ci]]
    beside = np.zeros(count, np.int64)  # the largest piece of the top class it touches
    np.maximum.at(beside, piece[ci][to_top], size[piece[cj][to_top]])
    bordered = (cluster > 0) & (size >= MIN_POINTS) & (share >= SHARE)
    bordered &= total >= CONTACT * np.sqrt(size)
    bordered &= (other != Label.TABLE) & (label != Label.TABLE)
    bled = bordered & ~main & (size <= RATIO * beside)  # a face hanging on another object
    touching = np.zeros(len(xyz), bool)
    touching[ci[to_top]] = True
    out = own.copy()
    order = np.argsort(piece, kind="stable")  # each piece's rows, without a pass per piece
    start = np.concatenate([[0], np.cumsum(size)])
    for p in np.flatnonzero(bordered):
        rows = order[start[p] : start[p + 1]]
        if not _enclosed(xyz[rows], touching[rows]):
            continue
        if (bled[p] and not between_only) or _between(xyz, rows, own == label[p], own == other[p]):
            out[rows] = other[p]
    return out


def _between(
    xyz: npt.NDArray[np.float64],
    rows: npt.NDArray[np.intp],
    own_class: npt.NDArray[np.bool_],
    other_class: npt.NDArray[np.bool_],
) -> bool:
    """Return whether the piece (rows of xyz) is a flat face with its class on one side.

    Its own class's other points within `GAP_M` of it lie on one side of its plane, the other
    class's on the other side, each `NEAR_SHARE` of its size or more and `SIDE_SHARE` of them
    on that side.
    """
    face = xyz[rows]
    centred = face - face.mean(axis=0)
    variance, axes = np.linalg.eigh(centred.T @ centred / len(face))
    if variance[0] > FLAT * variance.sum():
        return False
    normal = axes[:, 0]
    low, high = face.min(axis=0) - GAP_M, face.max(axis=0) + GAP_M
    around = np.all((xyz >= low) & (xyz <= high), axis=1)
    around[rows] = False
    tree = kd_tree(face)
    sides = []
    for members in (own_class & around, other_class & around):
        pts = xyz[members]
        dist, near = tree.query(pts, distance_upper_bound=GAP_M)
        found = np.isfinite(dist)
        offset = (pts[found] - face[near[found]]) @ normal
        n = np.count_nonzero(found)
        if n < NEAR_SHARE * len(face):
            return False
        sides.append(np.count_nonzero(offset > 0) / n)
    own_front, other_front = sides
    return bool(
        (own_front >= SIDE_SHARE and other_front <= 1 - SIDE_SHARE)
        or (own_front <= 1 - SIDE_SHARE and other_front >= SIDE_SHARE)
    )


def _main_cluster(
    piece: npt.NDArray[np.int32], ids: npt.NDArray[np.int32], count: int
) -> npt.NDArray[np.int64]:
    """Return per piece the cluster that holds most of its points."""
    pairs, n = np.unique(piece.astype(np.int64) * (int(ids.max()) + 1) + ids, return_counts=True)
    of_piece, cluster = pairs // (int(ids.max()) + 1), pairs % (int(ids.max()) + 1)
    order = np.lexsort((-n, of_piece))
    first = order[np.unique(of_piece[order], return_index=True)[1]]
    out = np.zeros(count, np.int64)
    out[of_piece[first]] = cluster[first]
    return out


def _top_contact(
    piece: npt.NDArray[np.int32], label: npt.NDArray[np.uint8], count: int
) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.float64], npt.NDArray[np.int64]]:
    """Return per piece its most touched class, that class's share of its contacts, and all."""
    total = np.bincount(piece, minlength=count)
    other, share = np.zeros(count, np.uint8), np.zeros(count)
    if len(piece) == 0:
        return other, share, total
    pairs, n = np.unique(piece.astype(np.int64) * 256 + label, return_counts=True)
    of_piece = pairs // 256
    order = np.lexsort((-n, of_piece))
    first = order[np.unique(of_piece[order], return_index=True)[1]]
    other[of_piece[first]] = pairs[first] % 256
    share[of_piece[first]] = n[first] / total[of_piece[first]]
    return other, share, total


def _enclosed(xyz: npt.NDArray[np.float64], touching: npt.NDArray[np.bool_]) -> bool:
    """Return whether the touching points spread along each principal axis as the piece does."""
    centred = xyz - xyz.mean(axis=0)
    _, axes = np.linalg.eigh(np.cov(centred.T))
    spread = (centred @ axes).std(axis=0)
    rim = (centred[touching] @ axes).std(axis=0)
    return bool(np.all(rim >= ENCLOSED * np.maximum(spread, 1e-9)))
