"""A table's legs the network called chair, and a chair's seat it called table.

Legs: chair clusters under a top, from the floor to it.

On fused maps of simulated recordings the network labels a table's legs and side panels chair
in whole segments (fresh seed 10: 1,036 table points in four clusters of 140-400 points, each a
leg or a panel standing under the top). DBSCAN keeps them as chairs of their own and nothing
after it undoes a whole segment. But a table is its top and what lies below it, and a chair
does not stand in a table's footprint reaching exactly up to its top: a chair pushed under a
table leaves its back outside or rises above the top, a stool stays well under it. A chair
cluster is a leg of the table when
- `INSIDE` of its points lie over the top's footprint (its `CELL_M` cells and their neighbours),
- its centre in plan lies under the top's outline (the convex hull of the top's points in plan):
  the footprint's margin of one cell let a chair's leg pass that stood beside a desk's front
  edge, its centre 4 and 26 mm outside the top (fresh recordings 69 and 71, 111 and 70 points;
  the legs taken on the 32 fresh recordings 60-91 and the 152 held-out clouds stand 9-600 mm
  inside it),
- none rises above the top's band,
- it is thin in plan, as a leg is: its points spread at most `THIN_M` (one standard deviation)
  in every direction (the recordings' legs 2-6 cm; a chair's seat 10-17 cm: on generators 2
  and 3 whole chairs pushed under desks, their backs below the top, were taken for legs, and
  one whose seat the network missed, a back 16 cm and 4 cm across),
- it is smaller than the table cluster holding the top, and
- it spans the leg's height as a leg or a leg's piece does, one of:
  - its highest reaches within `REACH_M` of the top or it touches the table (the lower part of
    a leg whose upper part the network called table), and its lowest within `RAISED_M` of the
    floor plane (a leg whose foot the network missed, or the floor plane's band took: fresh
    recordings 39 and 45, 169-175 points from 17-22 cm up to the top);
  - it stands on the floor (lowest within `FLOOR_M`) as a prism, no 5 cm slice of it wider
    than `PRISM` times its median slice (a post, not a stool's seat on its column), with
    nothing of another object class above it under the top within `ABOVE_M` of its plan
    (fewer than `ABOVE_SHARE` of its points): a leg's lower piece whose upper part the network
    called wall or nothing (fresh recordings 10, 15, 41: 122-413 points up to 29-58 cm), not a
    chair's leg or a swivel chair's column, which stand under a seat or a seated person
    (generator 3: eight chairs' columns and legs under desks were taken without that test).
It then takes the table's label and object. So does a post the network called table that
DBSCAN dropped as noise and regrowth did not reach (a leg between a fused map's gaps, 15-55 cm up
and 12-20 cm short of its top: fresh recordings 40 and 44, 122-127 points; given `prior`): thin,
over the footprint and under the outline, its highest point within `POST_UPPER_M` under the top,
a prism `POST_TALL` times as tall as it is wide, with nothing of another object above it. A
bin's side under a desk that the network called table (fresh recording 45: 62 points, 25 cm
tall) ends too far under the top, a box's face is no post. Written here because no library
relabels by such a footprint test; the footprint grid is the raised vote's (`plane_grid`), the
outline SciPy's convex hull.

Seats (`seats_called_table`): a table cluster that is a level sheet (at most `SHEET_M` thick)
no higher than `SEAT_M` over the floor plane and at most `SEAT_MAX_M` across, touching a chair
(`MIN_CONTACT` points within `LINK` chair point spacings), is that chair's seat: a table's top
stands higher, and a low table is larger or stands apart (fresh recordings 36 and 41: a seat of
545 points the network called table whole beside its chair's back, and a piece of one of 80;
no table of the suite's 58 clouds, the 24 fresh recordings or 50 fresh generator clouds is one).
A sheet lying flat in the floor's band is floor before any seat is looked for (steps.py runs
`flat.flat_on_floor` first): the floor under a chair that the network calls table touches the
chair's feet (held-out recording 22: 617 floor points made the seat of the chair over them).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy.spatial import ConvexHull, QhullError, cKDTree

from capture.recording import OBJECT_LABELS, Label
from process.refine.graph import kd_tree, members, point_spacing, radius_components
from process.refine.plane_grid import over_footprint, plane_uv

CELL_M = 0.05  # footprint grid of the top
INSIDE = 0.9  # share of a cluster's points over the footprint
BAND_M = 0.03  # nothing of it higher than this above the top's upper face
REACH_M = 0.1  # ... and its highest point at most this far under it
FLOOR_M = 0.15  # its lowest point at most this far above the floor
RAISED_M = 0.3  # ... or this far, when it reaches the top
PRISM = 2.0  # a standing piece that does not reach the top: widest slice / median slice
SLICE_M = 0.05  # ... of this height
ABOVE_M = 0.1  # ... and nothing of another object above it within this of its plan
ABOVE_SHARE = 0.1  # ... as many points as this share of its own
SEAT_M = 0.55  # a table cluster no higher than this over the floor ...
SHEET_M = 0.08  # ... and at most this thick ...
SEAT_MAX_M = 0.8  # ... and this across (its plan's diagonal) ...
MIN_CONTACT = 10  # ... with this many points touching a chair is the chair's seat
POST_UPPER_M = 0.3  # a post the network called table and DBSCAN dropped reaches this close
POST_TALL = 2.0  # ... under the top, at least this many times as tall as its plan is wide
MIN_POST = 10  # ... of this many points
LINK = 2.5  # a lower piece of a leg touches the table: a point within this many point spacings
THIN_M = 0.08  # a leg is thin: the spread of its points in plan along their widest direction


def _spread(uv: npt.NDArray[np.float32]) -> float:
    """Return the standard deviation of plan points along their widest direction."""
    if len(uv) < 3:
        return 0.0
    return float(np.sqrt(max(np.linalg.eigvalsh(np.cov(np.asarray(uv, np.float64).T))[-1], 0.0)))


def _prism(heights: npt.NDArray[np.float32], uv: npt.NDArray[np.float32]) -> bool:
    """Return whether the piece is a post: no SLICE_M slice of it much wider than the median.

    Fewer than three slices of five points or more: no (too short to tell).
    """
    widths = []
    for low in np.arange(float(heights.min()), float(heights.max()), SLICE_M):
        in_slice = (heights >= low) & (heights < low + SLICE_M)
        if in_slice.sum() >= 5:
            widths.append(_spread(uv[in_slice]))
    return len(widths) >= 3 and max(widths) <= PRISM * float(np.median(widths))


def _outline(uv: npt.NDArray[np.float32]) -> npt.NDArray[np.float64] | None:
    """Return the half-planes (a, b, c; inside: a u + b v + c <= 0) of the points' convex hull.

    None when the points span no area (fewer than three, or on a line).
    """
    try:
        return np.asarray(ConvexHull(np.asarray(uv, np.float64)).equations, np.float64)
    except QhullError:
        return None


def _under_outline(outline: npt.NDArray[np.float64] | None, uv: npt.NDArray[np.float32]) -> bool:
    """Return whether the points' centre in plan lies within the outline (none: no)."""
    if outline is None:
        return False
    centre = np.asarray(uv, np.float64).mean(axis=0)
    return bool(np.all(outline[:, :2] @ centre + outline[:, 2] <= 0.0))


def _touches(xyz: npt.NDArray[np.float32], tree: cKDTree, link: float) -> bool:
    """Return whether any of the points lies within `link` of the tree's points."""
    return bool(np.isfinite(tree.query(xyz, distance_upper_bound=link)[0]).any())


def legs_under_tables(
    points: npt.NDArray[np.floating],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    tops: list[tuple[npt.NDArray[np.float64], npt.NDArray[np.intp]]],
    floor: npt.NDArray[np.float64] | None,
    up: npt.NDArray[np.float64],
    prior: npt.NDArray[np.uint8] | None = None,
) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.int32], npt.NDArray[np.intp]]:
    """Return (labels, clusters, relabelled indices) with table legs labelled chair made table.

    `tops`: per table surface its plane and points; `floor`: the floor plane (None: no rule);
    `prior`: the network's labels, if given: its table-labelled posts left 0 become legs too.
    """
    out_labels, out_clusters = labels.copy(), clusters.copy()
    if floor is None or not tops:
        return out_labels, out_clusters, np.zeros(0, np.intp)
    pts = np.asarray(points, np.float32)
    floor = floor if float(floor[:3] @ up) >= 0 else -floor
    above_floor = pts @ floor[:3].astype(np.float32) + np.float32(floor[3])
    dropped = [] if prior is None else _dropped_pieces(pts, labels, prior)
    chair = np.flatnonzero((labels == Label.CHAIR) & (clusters > 0))
    if len(chair) == 0 and not dropped:
        return out_labels, out_clusters, np.zeros(0, np.intp)
    chair = chair[np.argsort(clusters[chair], kind="stable")]  # grouped by cluster
    starts = np.flatnonzero(np.r_[len(chair) > 0, np.diff(clusters[chair]) != 0])
    groups = np.split(chair, starts[1:])
    sizes = np.diff(np.r_[starts, len(chair)])
    lowest = np.minimum.reduceat(above_floor[chair], starts) if len(chair) else np.zeros(0)
    changed: list[npt.NDArray[np.intp]] = []
    taken = np.zeros(len(starts), bool)
    for model, surface in tops:
        model = model if float(model[:3] @ up) >= 0 else -model
        offset = pts @ model[:3].astype(np.float32) + np.float32(model[3])
        top = float(np.percentile(offset[surface], 75))  # its upper face (raised.py's reading)
        highest = np.maximum.reduceat(offset[chair], starts) if len(chair) else lowest
        candidates = np.flatnonzero(~taken & (highest <= top + BAND_M) & (lowest <= RAISED_M))
        table = out_clusters[surface][out_labels[surface] == Label.TABLE]
        table = table[table > 0]
        if (len(candidates) == 0 and not dropped) or len(table) == 0:
            continue
        host = int(np.bincount(table).argmax())
        host_points = pts[out_clusters == host]
        host_tree = kd_tree(host_points)
        link = LINK * point_spacing(host_points, host_tree)
        uv_top = plane_uv(pts[surface], model)
        outline = _outline(uv_top)
        under = _Under(pts, out_labels, out_clusters, offset, top, model)
        for k in candidates[sizes[candidates] < len(host_points)]:
            members = groups[k]
            uv = plane_uv(pts[members], model)
            if _spread(uv) > THIN_M:  # a seat: a chair pushed right under the table
                continue
            if over_footprint(uv_top, uv, CELL_M, diagonal=True).mean() < INSIDE:
                continue
            if not _under_outline(outline, uv):  # a chair's leg beside the top's edge
                continue
            reaches = highest[k] >= top - REACH_M or _touches(pts[members], host_tree, link)
            if not reaches:
                if lowest[k] > FLOOR_M or not _prism(above_floor[members], uv):
                    continue
                if under.sat_on(members, uv):
                    continue
            out_labels[members], out_clusters[members] = Label.TABLE, host
            changed.append(members)
            taken[k] = True
        for members in dropped:
            if (out_labels[members] != 0).any():  # taken under an earlier top
                continue
            high = float(offset[members].max())
            if high > top + BAND_M or high < top - POST_UPPER_M:
                continue
            uv = plane_uv(pts[members], model)
            if (
                _spread(uv) > THIN_M
                or over_footprint(uv_top, uv, CELL_M, diagonal=True).mean() < INSIDE
                or not _under_outline(outline, uv)
            ):
                continue
            height = above_floor[members]
            if not _prism(height, uv) or np.ptp(height) < POST_TALL * np.ptp(uv, axis=0).max():
                continue
            if under.sat_on(members, uv):
                continue
            out_labels[members], out_clusters[members] = Label.TABLE, host
            changed.append(members)
    relabelled = np.unique(np.concatenate(changed)) if changed else np.zeros(0, np.intp)
    return out_labels, out_clusters, relabelled


def _dropped_pieces(
    pts: npt.NDArray[np.float32], labels: npt.NDArray[np.uint8], prior: npt.NDArray[np.uint8]
) -> list[npt.NDArray[np.intp]]:
    """Return the pieces of what the network calls table and the refinement left 0.

    Linked within `LINK` point spacings of the cloud; `MIN_POST` points or more.
    """
    left = np.flatnonzero((labels == 0) & (prior == Label.TABLE))
    if len(left) < MIN_POST:
        return []
    groups = [left[g] for g in members(radius_components(pts[left], LINK * point_spacing(pts)))]
    return [g for g in groups if len(g) >= MIN_POST]


class _Under:
    """Other objects' points under a top, listed when first asked (most tops ask nothing).

    `labels` and `clusters` are the rule's own arrays, read as they change: a piece made table
    after the list was taken is no other object.
    """

    def __init__(
        self,
        pts: npt.NDArray[np.float32],
        labels: npt.NDArray[np.uint8],
        clusters: npt.NDArray[np.int32],
        offset: npt.NDArray[np.float32],
        top: float,
        model: npt.NDArray[np.float64],
    ) -> None:
        self.pts, self.labels, self.clusters = pts, labels, clusters
        self.offset, self.top, self.model = offset, top, model
        self.rows: npt.NDArray[np.intp] | None = None
        self.uv = np.zeros((0, 2), np.float32)

    def sat_on(self, members: npt.NDArray[np.intp], uv: npt.NDArray[np.float32]) -> bool:
        """Return whether another object lies above the piece: a seat or a sitter on a leg.

        Within `ABOVE_M` of its plan, as many points as `ABOVE_SHARE` of the piece's.
        """
        if self.rows is None:
            labels, offset = self.labels, self.offset
            self.rows = np.flatnonzero(
                np.isin(labels, OBJECT_LABELS) & (labels != Label.TABLE) & (offset < self.top)
            )
            self.uv = plane_uv(self.pts[self.rows], self.model)
        rows, uv_rows = self.rows, self.uv
        near = np.all(
            (uv_rows >= uv.min(axis=0) - ABOVE_M) & (uv_rows <= uv.max(axis=0) + ABOVE_M), axis=1
        )
        above = near & (self.offset[rows] > self.offset[members].max())
        above &= (self.labels[rows] != Label.TABLE) & (
            self.clusters[rows] != self.clusters[members[0]]
        )
        return bool(above.sum() >= ABOVE_SHARE * len(members))


def seats_called_table(
    points: npt.NDArray[np.floating],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    floor: npt.NDArray[np.float64] | None,
    up: npt.NDArray[np.float64],
) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.int32], npt.NDArray[np.intp]]:
    """Return (labels, clusters, relabelled indices) with chairs' seats labelled table made chair.

    `floor`: the floor plane (None: no rule). The seat joins the chair object it touches most.
    """
    out_labels, out_clusters = labels.copy(), clusters.copy()
    none = np.zeros(0, np.intp)
    chair = np.flatnonzero((labels == Label.CHAIR) & (clusters > 0))
    tables = np.flatnonzero((labels == Label.TABLE) & (clusters > 0))
    if floor is None or len(chair) < 2 or len(tables) == 0:
        return out_labels, out_clusters, none
    pts = np.asarray(points, np.float32)
    floor = floor if float(floor[:3] @ up) >= 0 else -floor
    height = pts[tables] @ floor[:3].astype(np.float32) + np.float32(floor[3])  # per table point
    seats = np.unique(clusters[tables[height <= SEAT_M]])
    if len(seats) == 0:
        return out_labels, out_clusters, none
    chair_tree = kd_tree(pts[chair])
    link = LINK * point_spacing(pts[chair], chair_tree)
    changed = []
    for seat in seats:
        mine = clusters[tables] == seat
        members, h = tables[mine], height[mine]
        if h.max() > SEAT_M or h.max() - h.min() > SHEET_M:
            continue
        uv = plane_uv(pts[members], floor)
        if np.linalg.norm(uv.max(axis=0) - uv.min(axis=0)) > SEAT_MAX_M:
            continue
        dist, nearest = chair_tree.query(pts[members], distance_upper_bound=link)
        touching = nearest[np.isfinite(dist)]
        if len(touching) < MIN_CONTACT:
            continue
        ids, counts = np.unique(clusters[chair[touching]], return_counts=True)
        out_labels[members], out_clusters[members] = Label.CHAIR, ids[np.argmax(counts)]
        changed.append(members)
    return out_labels, out_clusters, np.sort(np.concatenate(changed)) if changed else none
