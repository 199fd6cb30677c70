"""What grew from a screen or a small object along the level surface it stands on is that surface's.

A screen or a thing of clutter stands on something: a desk, a counter, a TV's low cabinet.
Regrowth reaches from the object's own points into the unlabelled ones around it, and where
they stand its waves run along the surface under its foot: generator 5's living rooms (fused
from ray-cast views) give a TV the bare top of the cabinet it stands on, 830-960 points of a
60k map whose truth is no object (the cabinet is furniture no class names). An object ends at
its foot: what lies level with its lowest points beyond its foot's footprint is the surface it
stands on. So the points regrowth gave a tv_monitor or clutter cluster go back to what they
were before (unlabelled) when
- they lie within `FOOT_M` over the cluster's own lowest points (its 1st height percentile;
  own: those it had before regrowth),
- outside its foot's footprint: the plan cells of `CELL_M` its own points within `FOOT_M` of
  its lowest cover, grown by `GROW_CELLS` (a screen's base plate, 10-20 cm across round its
  stand, stays: grown by one cell the rule took generator 2's plates, 25-54 points a room), and
- on a level surface: the normal of their `NORMAL_K` nearest points lies within
  `LEVEL_DEG` of up (a screen's missed lower edge is upright; a cabinet's top is level).
Standing classes (table, chair, person, plant, sofa) reach down to the floor by design and are
left; a table's growth above its top is held by regrowth's `table_top_m`.

Written here because no library bounds region growing by a support surface; the normals are a
plain eigen-decomposition of neighbourhoods (SciPy's k-d tree, graph.py).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy import ndimage

from capture.recording import Label
from process.refine.graph import kd_tree, members
from process.refine.plane_grid import plane_uv

ON_SURFACES = (Label.TV_MONITOR, Label.CLUTTER)  # classes that stand on something
FOOT_M = 0.03  # an object's foot: its own points within this of its lowest
CELL_M = 0.05  # the foot's footprint: plan cells of this side ...
GROW_CELLS = 2  # ... grown by this many cells (a base plate reaches 10 cm from a stand)
NORMAL_K = 16  # a point's normal: the least axis of its nearest this many points
LEVEL_DEG = 25.0  # ... within this of up: a level surface
MIN_OWN = 10  # a cluster with fewer own points has no foot to measure
_MARGIN_M = 0.1  # the neighbourhoods for normals are sought this far around the points


def beyond_feet(
    points: npt.NDArray[np.floating],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    grown: npt.NDArray[np.intp],
    up: npt.NDArray[np.float64],
) -> npt.NDArray[np.intp]:
    """Return the points of `grown` on the surface a screen or clutter stands on, past its foot.

    `grown`: the indices regrowth labelled; `labels`, `clusters`: after regrowth; `up`:
    gravity-up. The returned indices are to be given back.
    """
    none = np.zeros(0, np.intp)
    was_grown = np.zeros(len(labels), bool)
    was_grown[grown] = True
    rows = np.flatnonzero(np.isin(labels, ON_SURFACES) & (clusters > 0))
    if len(grown) == 0 or len(rows) == 0:
        return none
    height = np.asarray(points[rows], np.float64) @ up
    uv = plane_uv(np.asarray(points[rows], np.float32), np.append(up, 0.0))
    found = []
    for g in members(clusters[rows]):
        own, new = g[~was_grown[rows[g]]], g[was_grown[rows[g]]]
        if len(own) < MIN_OWN or len(new) == 0:
            continue
        low = float(np.percentile(height[own], 1.0))
        new = new[height[new] <= low + FOOT_M]
        if len(new) == 0:
            continue
        beyond = rows[new[~_in_footprint(uv[own[height[own] <= low + FOOT_M]], uv[new])]]
        if len(beyond):
            found.append(beyond[_level(points, beyond, up)])
    return np.sort(np.concatenate(found)) if found else none


def _in_footprint(
    foot: npt.NDArray[np.float32], query: npt.NDArray[np.float32]
) -> npt.NDArray[np.bool_]:
    """Return whether each query point (plan) lies in the foot's cells grown by `GROW_CELLS`."""
    low = np.minimum(foot.min(axis=0), query.min(axis=0))
    cell_of_foot = ((foot - low) / CELL_M).astype(np.int64)
    cell_of_query = ((query - low) / CELL_M).astype(np.int64)
    shape = np.maximum(cell_of_foot.max(axis=0), cell_of_query.max(axis=0)) + 1
    grid = np.zeros(shape, bool)
    grid[cell_of_foot[:, 0], cell_of_foot[:, 1]] = True
    grid = ndimage.binary_dilation(grid, structure=np.ones((3, 3), bool), iterations=GROW_CELLS)
    inside: npt.NDArray[np.bool_] = grid[cell_of_query[:, 0], cell_of_query[:, 1]]
    return inside


def _level(
    points: npt.NDArray[np.floating], rows: npt.NDArray[np.intp], up: npt.NDArray[np.float64]
) -> npt.NDArray[np.bool_]:
    """Return whether each point's surface is level: its neighbourhood's normal near up.

    The neighbourhood is taken among the cloud's points near them only (their box grown by
    `_MARGIN_M`): a tree of the whole map would cost more than the step.
    """
    centre = np.asarray(points[rows], np.float64)
    low, high = centre.min(axis=0) - _MARGIN_M, centre.max(axis=0) + _MARGIN_M
    near = np.asarray(points[np.all((points >= low) & (points <= high), axis=1)], np.float64)
    k = min(NORMAL_K, len(near))
    _, nb = kd_tree(near).query(centre, k)
    hood = near[nb.reshape(len(rows), k)]
    hood = hood - hood.mean(axis=1, keepdims=True)
    _, axes = np.linalg.eigh(np.einsum("nki,nkj->nij", hood, hood))
    level: npt.NDArray[np.bool_] = np.abs(axes[:, :, 0] @ up) >= np.cos(np.radians(LEVEL_DEG))
    return level
