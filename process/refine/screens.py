"""A thin upright panel, raised off the floor, that the network calls clutter is a screen.

A network names a monitor or a TV clutter whole in most views: generator 5's network (its
"confusion" errors) does so for 1-3 screens of most of its offices and meeting rooms (a screen
on a desk, 1,200-11,600 points a cluster; a TV on a wall, 1,500-5,100), and DBSCAN keeps each
as clutter. A screen's shape is its own among the objects a room holds: a panel a few
centimetres deep (its stand behind it included), 0.4-2 m wide, 0.25-1.2 m tall, standing on a
desk, a cabinet or a wall, its face a full rectangle. So a clutter cluster becomes tv_monitor
when
- it is a thin upright panel: along the horizontal direction it spreads least in (its normal),
  its 2nd-98th percentile depth is at most `THICK_M`; across, its width lies in `WIDE_M`; along
  up, its height lies in `TALL_M`;
- its face is flat and fills its rectangle: the densest slab `FACE_M` deep along the normal
  holds at least `FACE_SHARE` of its points (screens on generator 5 0.57-0.92, wall TVs the
  least) and covers at least `FACE_FILL` of the panel's cells of `FACE_CELL_M` (width by
  height). Screens' faces cover
  0.61-1.00 of theirs on generator 5 (wall TVs, whose cluster carries wall points, the least)
  and TUM `fr1_rpy`'s one monitor the network names right 0.93; a picture beside a plant that
  the network calls clutter there, 0.55 m by 0.49, covers 0.41; a wall's strip 0.10;
- it stands off the floor: its 1st height percentile over the floor plane is at least
  `RAISED_M` (a box seen from one side only, against a wall, is a panel too, but on the floor).
A cluster made tv_monitor keeps its id. An upright board on a stand or a shelf of books of a
screen's size would be named screen too; on the real maps (TUM `fr1_rpy`, slambook2) no
cluster is. It runs after the votes, as the other rules by an object's size do.

Written here because no library labels a cluster by its shape; the extents are percentiles of
plain projections (NumPy), the plan's axes the floor plane's (`plane_grid`).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from capture.recording import Label
from process.refine.graph import members, relabelled
from process.refine.plane_grid import over_floor

THICK_M = 0.09  # a screen's depth, its stand included (2nd-98th percentile) at most ...
WIDE_M = (0.4, 2.0)  # ... its width along the floor ...
TALL_M = (0.25, 1.2)  # ... and its height, within these
FACE_M = 0.03  # its face: the densest slab this deep along its normal ...
FACE_CELL_M = 0.05  # ... covers, in cells of this side ...
FACE_FILL = 0.55  # ... at least this share of the panel's width by height ...
FACE_SHARE = 0.5  # ... and holds this share of its points (a flat face, not a volume)
RAISED_M = 0.25  # its 1st height percentile over the floor reaches this: it stands on something
MIN_POINTS = 50  # fewer points make no panel
_TURNS = 90  # directions in plan (2 degrees apart) the face is looked for along
_PCT = (2.0, 98.0)  # the extents' percentiles: a few stray points do not widen a panel


def flat_screens(
    points: npt.NDArray[np.floating],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    floor: npt.NDArray[np.float64] | None,
    up: npt.NDArray[np.float64],
) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.int32], npt.NDArray[np.intp]]:
    """Return (labels, clusters, relabelled indices) with clutter panels made tv_monitor.

    `floor`: the floor plane (a, b, c, d; None: no rule); `up`: gravity-up. Clusters keep ids.
    """
    clutter = over_floor(points, labels, clusters, Label.CLUTTER, floor, up)
    screens = [
        g
        for g in members(clusters[clutter.rows])
        if len(g) >= MIN_POINTS
        and float(np.percentile(clutter.height[g], 1.0)) >= RAISED_M
        and is_screen(clutter.uv[g], clutter.height[g])
    ]
    return relabelled(labels, clusters, clutter.rows, screens, Label.TV_MONITOR)


def is_screen(uv: npt.NDArray[np.float32], height: npt.NDArray[np.float32]) -> bool:
    """Whether points (plan coordinates, heights) make a thin upright panel with a full face.

    The face is the upright slab `FACE_M` deep that holds the most points, over `_TURNS`
    directions in plan (a Hough vote: a principal axis would tilt towards whatever stands beside
    or behind the face); the panel's normal is that slab's.
    """
    plan = (uv - uv.mean(axis=0)).astype(np.float64)
    turn = np.linspace(0.0, np.pi, _TURNS, endpoint=False)
    normals = np.stack([np.cos(turn), np.sin(turn)])
    depth = np.sort(plan @ normals, axis=0)  # (N, turns), each column sorted
    held = np.stack([np.searchsorted(col, col + FACE_M, side="right") for col in depth.T], 1)
    held -= np.arange(len(plan))[:, None]
    best = int(np.argmax(held.max(axis=0)))
    start = depth[int(np.argmax(held[:, best])), best]
    normal = normals[:, best]
    depth_of = plan @ normal
    across = plan @ np.array([-normal[1], normal[0]])
    if _extent(depth_of) > THICK_M:
        return False
    if not WIDE_M[0] <= _extent(across) <= WIDE_M[1]:
        return False
    if not TALL_M[0] <= _extent(height) <= TALL_M[1]:
        return False
    slab = (depth_of >= start) & (depth_of <= start + FACE_M)
    if slab.mean() < FACE_SHARE:
        return False
    return _face_fill(slab, np.column_stack([across, height])) >= FACE_FILL


def _extent(values: npt.NDArray[np.floating]) -> float:
    low, high = np.percentile(values, _PCT)
    return float(high - low)


def _face_fill(slab: npt.NDArray[np.bool_], face_uv: npt.NDArray[np.floating]) -> float:
    """Return the share of the panel's cells (width by height) that the face's points cover."""
    low, high = np.percentile(face_uv, _PCT, axis=0)
    shape = np.maximum(np.ceil((high - low) / FACE_CELL_M).astype(np.int64), 1)
    inside = np.all((face_uv >= low) & (face_uv <= high), axis=1) & slab
    cells = np.minimum(((face_uv[inside] - low) / FACE_CELL_M).astype(np.int64), shape - 1)
    covered = len(np.unique(cells, axis=0)) if len(cells) else 0
    return covered / float(np.prod(shape))
