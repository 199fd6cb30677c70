"""Table labels raised above a table's top go to the object they belong to.

A network's table label bleeds a few centimetres up whatever stands on a desk: a monitor's base
plate, 1 cm thick, and the foot of its stand come out table, and so do forearms resting on the
desk. DBSCAN then joins them to the desk (they touch it), and neither the seam vote (the plate
is flat, its majority table) nor the piece vote (no gap: it sits on the desk) takes them away.
Yet a table is its top and what lies below it: a point above the top's own noise band is
something standing on it. Here the table-labelled points above a table surface (the plane step's,
surfaces.py), over its footprint, are joined into pieces (within `LINK` point spacings), and a
piece takes the class of the object it touches when
- `SHARE` of its contacts (neighbours of another object class, above the top too) are of that
  class, and they are many for its size (`CONTACT` times the square root of its points), and
- it is at most `RATIO` times the size of that class's points it is linked to (a shelf the
  network rightly calls table, above a desk, is larger than the monitor standing on it).
A piece touching nothing but table (a box the network called table whole) stays table.

The other way round, a monitor stands on a desk, never under its top: the network's monitor
label bleeds around a monitor's foot onto the desk and through the top onto its underside. The
points labelled monitor below a top's noise band, down to `SLAB_M` under it and over its
footprint, are the desk's (generator 4's offices at 60k object points, 5 fresh seeds: 1,893 such
points were desk, 51 monitor). So are those level with the desk: within `LEVEL_SIGMAS` of the
desk's plane refitted by least squares on its band (RANSAC's plane through both faces of a thin
top tilts by millimetres over a desk), while a monitor's base plate, 1.2 cm thick, stands 3.5-5
noise sigmas above it (the five offices: desk points labelled monitor 2,945 -> 173; monitor points
labelled table 2,320 -> 3,192, mostly plates' rims and their bottom faces, which the generator
keeps level with the desk). A top whose band strays from one plane (more than `LEVEL_OFF` of its
points beyond `LEVEL_SIGMAS`: a fused map's warped desk; TUM `fr1_rpy`'s three tops 28-47 %,
generator 4's 7-17 %) has no level and sinks nothing. Clutter stays: a shelf board at desk
height passes for a table's top, and the books on the shelf under it are clutter (generator 3's
rooms 1 and 2: 415 and 354 points).

Written here because no library relabels over such pieces; the graph is SciPy's (graph.py).
Measured on generator 4's office at 200k object points (issue 12): see docs/refinement.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from scipy import ndimage
from scipy.stats import median_abs_deviation

from capture.recording import OBJECT_LABELS, Label
from process.refine.graph import class_pieces, kd_tree
from process.refine.plane_grid import PIECE_CELL_M, connected_pieces, grid_of, plane_uv

NEIGHBOURS = 10  # graph edges per point
LINK = 2.5  # points within this many point spacings are linked
MIN_POINTS = 10  # smaller pieces keep their label
SHARE = 0.9  # of a piece's contacts are of the class it takes
CONTACT = 1.0  # contacts >= CONTACT * sqrt(points of the piece)
RATIO = 1.0  # a piece at most this many times the linked points of the class it takes
BAND_SIGMAS = 3.0  # the top's noise band: this many robust standard deviations of its offsets
MIN_BAND_M = 0.005  # ... at least this
REACH_M = 0.5  # points up to this far above the top are looked at
SLAB_M = 0.06  # ... and down to this far under it: a desk's top is thinner
CELL_M = 0.05  # footprint grid of the top
SHEET_M = 0.01  # a level piece thinner than this is a stretch of a top (_level_sheet) ...
FLAT_ON_TABLES = (Label.TV_MONITOR, Label.CLUTTER)  # ... unless it joins what lies flat on desks
SHEET_TILT_DEG = 25.0
SIGMA_PROBES = 2000  # points of a top whose offsets from their neighbours' give its noise
MIN_TOP_POINTS = 100  # a top's piece with fewer points has no measurable top or noise
LEVEL_SIGMAS = 2.0  # a point this near the refitted desk plane is level with it
LEVEL_REFITS = 3  # least-squares refits of the desk plane, each on the points level with the last
LEVEL_OFF = 0.2  # a top with more of its band beyond LEVEL_SIGMAS is not one plane: no level


@dataclass(frozen=True)
class RaisedVote:
    """The labels and clusters after the vote, and the points relabelled (indices)."""

    labels: npt.NDArray[np.uint8]
    clusters: npt.NDArray[np.int32]
    relabelled: npt.NDArray[np.intp]
    sunk: int = 0  # of them, monitor points under a top made table
    above: npt.NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, np.intp))
    # every point above a top's band over its footprint: what stands on a table (any label)


def raised_off_tables(
    points: npt.NDArray[np.floating],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    tops: list[tuple[npt.NDArray[np.float64], npt.NDArray[np.intp]]],
    up: npt.NDArray[np.float64],
) -> RaisedVote:
    """Relabel table pieces standing above table tops by the object they touch.

    Args:
        points: (N, 3) positions.
        labels: (N,) classes (phase III so far).
        clusters: (N,) object ids (0: none).
        tops: per table surface, its plane (a, b, c, d) and the indices of its points.
        up: gravity-up.
    """
    out_labels, out_clusters = labels.copy(), clusters.copy()
    changed: list[npt.NDArray[np.intp]] = []
    above: list[npt.NDArray[np.intp]] = []
    sunk = 0
    for model, surface in tops:
        if len(surface) < MIN_POINTS:
            continue
        # the surface's own points above its band count too: RANSAC's band (plane_distance_m)
        # takes a base plate 1 cm up into the top
        rows, under = _above(points, model, surface, up)
        above.append(rows)
        under = under[out_labels[under] == Label.TV_MONITOR]
        if len(under):
            desk = out_clusters[surface][out_labels[surface] == Label.TABLE]
            desk = desk[desk > 0]  # into the cluster holding most of this top
            out_labels[under] = Label.TABLE
            out_clusters[under] = np.bincount(desk).argmax() if len(desk) else 0
            changed.append(under)
            sunk += len(under)
        rows = rows[np.isin(out_labels[rows], OBJECT_LABELS)]
        xyz = np.asarray(points[rows], np.float64)
        flips = _vote(xyz, out_labels[rows], out_clusters[rows], up)
        for target, cluster, members in flips:
            out_labels[rows[members]] = target
            out_clusters[rows[members]] = cluster
            changed.append(rows[members])
    relabelled = np.unique(np.concatenate(changed)) if changed else np.zeros(0, np.intp)
    on_top = np.unique(np.concatenate(above)) if above else np.zeros(0, np.intp)
    return RaisedVote(out_labels, out_clusters, relabelled, sunk, on_top)


def _above(
    points: npt.NDArray[np.floating],
    model: npt.NDArray[np.float64],
    surface: npt.NDArray[np.intp],
    up: npt.NDArray[np.float64],
) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """Return the points above the top's band over one of its pieces, and those under it.

    Above: up to REACH_M over the band; under: down to SLAB_M below the band, or level with the
    desk (_level).

    Per connected piece of the surface (a desk): its top is the upper quartile of its points'
    offsets from the plane, as RANSAC's 2 cm band takes both faces of a thin desk top seen
    from above and below; the noise is the robust spread of each point's offset from its own
    nearest neighbours' (a local measure, blind to the two faces and to a slight tilt).
    """
    model = model if float(model[:3] @ up) >= 0 else -model  # offsets grow upwards
    offset = np.asarray(points, np.float32) @ model[:3].astype(np.float32) + np.float32(model[3])
    uv_surface = plane_uv(np.asarray(points[surface], np.float32), model)
    piece = connected_pieces(uv_surface, PIECE_CELL_M)
    # every piece's top lies within RANSAC's band (a few cm) of the plane
    near_top = np.flatnonzero((offset > -0.05 - SLAB_M) & (offset <= REACH_M + 0.05))
    uv_near, h = plane_uv(np.asarray(points[near_top], np.float32), model), offset[near_top]
    out, under = [], []
    for k in range(int(piece.max()) + 1):
        in_piece = piece == k
        members = surface[in_piece]
        if len(members) < MIN_TOP_POINTS:
            continue
        own = offset[members].astype(np.float64)
        xyz = np.asarray(points[members], np.float64)
        probe = np.linspace(0, len(members) - 1, min(len(members), SIGMA_PROBES)).astype(np.intp)
        _, near = kd_tree(xyz).query(xyz[probe], NEIGHBOURS + 1)
        local = own[probe] - np.median(own[near], axis=1)
        sigma = float(median_abs_deviation(local, scale="normal"))
        top = float(np.percentile(own, 75))
        width = max(BAND_SIGMAS * sigma, MIN_BAND_M)
        band, below = top + width, top - width  # the band's upper and lower edges
        uv_own = uv_surface[in_piece]
        low, high = uv_own.min(axis=0) - CELL_M, uv_own.max(axis=0) + CELL_M
        pick = (h <= top + REACH_M) & (h >= top - SLAB_M)
        pick[pick] &= np.all((uv_near[pick] >= low) & (uv_near[pick] <= high), axis=1)
        rows, uv_rows = near_top[pick], uv_near[pick]
        if len(rows) == 0:
            continue
        ij = grid_of(np.concatenate([uv_own, uv_rows]), CELL_M)
        shape = tuple(int(v) + 1 for v in ij.max(axis=0))
        footprint = np.zeros(shape, bool)
        footprint[ij[: len(members), 0], ij[: len(members), 1]] = True
        footprint = ndimage.binary_closing(footprint, np.ones((3, 3), bool))  # under objects
        inside = footprint[ij[len(members) :, 0], ij[len(members) :, 1]]
        rows, h_rows = rows[inside], offset[rows[inside]].astype(np.float64)
        in_band = (h_rows >= below) & (h_rows <= band)
        out.append(rows[h_rows > band])
        under.append(rows[(h_rows < below) | _level(uv_rows[inside], h_rows, in_band, sigma)])
    none = np.zeros(0, np.intp)
    return (
        np.unique(np.concatenate(out)) if out else none,
        np.unique(np.concatenate(under)) if under else none,
    )


def _level(
    uv: npt.NDArray[np.float32],
    h: npt.NDArray[np.float64],
    in_band: npt.NDArray[np.bool_],
    sigma: float,
) -> npt.NDArray[np.bool_]:
    """Return which points of the band lie level with the desk: near its refitted plane.

    The plane h = a u + b v + c is fitted by least squares on the band, then LEVEL_REFITS times
    on the band's points within LEVEL_SIGMAS of the last fit (a base plate or a keyboard on the
    desk drops out). None is level when the band is not one plane (LEVEL_OFF).
    """
    level = np.zeros(len(h), bool)
    design = np.column_stack([uv.astype(np.float64), np.ones(len(h))])
    near = in_band
    for _ in range(LEVEL_REFITS + 1):
        if near.sum() < MIN_TOP_POINTS:
            return level
        coef, *_ = np.linalg.lstsq(design[near], h[near], rcond=None)
        near = in_band & (np.abs(h - design @ coef) <= LEVEL_SIGMAS * sigma)
    if 1.0 - near.sum() / in_band.sum() > LEVEL_OFF:
        return level
    return near


def _vote(
    xyz: npt.NDArray[np.float64],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    up: npt.NDArray[np.float64],
) -> list[tuple[int, int, npt.NDArray[np.intp]]]:
    """Return (class, cluster, rows) for each table piece that goes to the object it touches."""
    table = labels == Label.TABLE
    if table.sum() < MIN_POINTS or table.all() or len(xyz) <= NEIGHBOURS:
        return []
    dist, nb = kd_tree(xyz).query(xyz, NEIGHBOURS + 1, workers=-1)
    i, j, _, piece = class_pieces(dist, nb, labels, LINK)  # pieces of one class
    # contacts of table pieces with other classes' points
    contact = table[i] & ~table[j]
    ci, cj = i[contact], j[contact]
    flips = []
    for p in np.unique(piece[table]):
        members = np.flatnonzero((piece == p) & table)
        if len(members) < MIN_POINTS:
            continue
        touching = cj[piece[ci] == p]
        if len(touching) < CONTACT * np.sqrt(len(members)):
            continue
        classes, counts = np.unique(labels[touching], return_counts=True)
        target = int(classes[np.argmax(counts)])
        if counts.max() < SHARE * len(touching):
            continue
        if target not in FLAT_ON_TABLES and _level_sheet(xyz[members], up):
            continue
        linked = np.unique(piece[touching[labels[touching] == target]])
        size = int(np.isin(piece, linked).sum())
        if len(members) > RATIO * size:
            continue
        ids, votes = np.unique(clusters[touching[labels[touching] == target]], return_counts=True)
        flips.append((target, int(ids[np.argmax(votes)]), members))
    return flips


def _level_sheet(xyz: npt.NDArray[np.float64], up: npt.NDArray[np.float64]) -> bool:
    """Return whether the piece is a level sheet: a stretch of a table's top, not on it.

    Its thickness (twice the spread along its least axis) under SHEET_M and that axis within
    SHEET_TILT_DEG of up: a second table's top 1-2 cm higher than the plane's (generator 4,
    kitchen: 2,239 points of it took the class of the person leaning on it). Asked only when
    the piece would join a person, chair, plant or sofa: those have no flat sheet lying on a
    desk, while a keyboard, a book or a monitor's base plate is one (FLAT_ON_TABLES).
    """
    centred = xyz - xyz.mean(axis=0)
    values, vectors = np.linalg.eigh(centred.T @ centred / len(xyz))
    thin = 2.0 * np.sqrt(max(float(values[0]), 0.0)) < SHEET_M
    return bool(thin and abs(float(vectors[:, 0] @ up)) > np.cos(np.radians(SHEET_TILT_DEG)))
