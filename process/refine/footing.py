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

Written here because no library bounds region growing by a support surface; the normals are
Open3D's, the footprint's grid `plane_grid.over_footprint`'s.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import open3d as o3d

from capture.recording import Label
from process.refine.graph import members
from process.refine.plane_grid import over_footprint, plane_uv

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
        foot = uv[own[height[own] <= low + FOOT_M]]
        inside = over_footprint(foot, uv[new], CELL_M, diagonal=True, grow=GROW_CELLS)
        beyond = rows[new[~inside]]
        if len(beyond):
            found.append(beyond[_level(points, beyond, up)])
    return np.sort(np.concatenate(found)) if found else none


def _level(
    points: npt.NDArray[np.floating], rows: npt.NDArray[np.intp], up: npt.NDArray[np.float64]
) -> npt.NDArray[np.bool_]:
    """Return whether each point's surface is level: its normal within `LEVEL_DEG` of up.

    The normals are Open3D's, of the `NORMAL_K` nearest points, estimated over the cloud's
    points near them only (their box grown by `_MARGIN_M`): normals of the whole map would cost
    more than the step.
    """
    centre = points[rows]
    low, high = centre.min(axis=0) - _MARGIN_M, centre.max(axis=0) + _MARGIN_M
    near = np.flatnonzero(np.all((points >= low) & (points <= high), axis=1))
    cloud = o3d.geometry.PointCloud(
        o3d.utility.Vector3dVector(np.asarray(points[near], np.float64))
    )
    cloud.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(NORMAL_K))
    normals = np.asarray(cloud.normals)[np.searchsorted(near, rows)]
    level: npt.NDArray[np.bool_] = np.abs(normals @ up) >= np.cos(np.radians(LEVEL_DEG))
    return level
