"""A chair by its height: lower than any seat it is clutter, taller than any chair a person.

A network names a low box or bin on the floor chair whole: on fused maps of simulated
recordings a carton 39 cm tall (fresh recording 77: 1,135 points the network called floor and
chair, made one chair by regrowth) and boxes and bins 30-38 cm tall (recordings 82, 97, 98:
51-385 points a cluster), on TUM `fr1_rpy` a blue waste bin under the desk (1,110 points, 40 cm).
DBSCAN keeps each as a chair of its own. But a chair is a seat: every chair of the simulator and
of generators 1-4 has its seat 42-50 cm over the floor (real chairs' 40-52 cm), and its back
rises higher. So a chair cluster whose highest point stays under `SEAT_MIN_M` over the floor
plane is clutter, the map's class for objects of no other class, when
- it has a lid, as a box or a bin has and a chair's legs have not: its points within `TOP_M` of
  its highest cover `TOP_CELLS` connected cells of `TOP_CELL_M` in plan (the boxes 8-48 cells,
  but one of recording 98 whose lid lies in pieces; the 86 leg pieces of chairs on the 40 fresh
  recordings, whose seat the map lacks or DBSCAN split off, 1-6 cells: their seat seen only
  from the side, under a desk), and
- no chair's seat lies over it: fewer than `ABOVE_SHARE` of its point count of chair points
  higher than it within `ABOVE_M` of its plan (a swivel chair's base, a star 60 cm across, has a
  lid; its seat covers it).
A cluster made clutter keeps its id. A footstool or an ottoman under 40 cm, which the ADE20K
network's classes count as chair (`segmentation.ade20k`), becomes clutter too: there the rule
and the classes disagree.

`tall_chairs`: generator 5's network names a person chair whole in most views, standing or seated
on a sofa (44,000 points of its 14 suite clouds; clusters whose 99th height percentile over the
floor reaches 1.44-1.70 m). No chair rises that high: the simulator's and generators' backs end
at 0.8-1.0 m, an office chair's high back at 1.2-1.35 m, and on TUM `fr1_rpy` and slambook2
every chair cluster's 99th percentile stays under 1.2 m. A chair cluster whose 99th height
percentile lies between `TALL_M` and `PERSON_MAX_M` is a person, the one class of the networks'
that stands that tall where a chair would (a tall plant called chair would be named wrong
again); higher, it is a piece of the ceiling or a wall (generator 2's room 9: 145 points at
2.8 m). It runs after the votes, as `sofas.narrow_sofas` does.

Written here because no library labels by height over a plane; the floor plane is the plane
step's, the lid's pieces `plane_grid`'s.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from capture.recording import Label
from process.refine.graph import members, relabelled
from process.refine.plane_grid import connected_pieces, grid_of, over_floor

SEAT_MIN_M = 0.40  # a chair rises at least this high over the floor: its seat
TOP_M = 0.04  # a piece's lid: its points within this of its highest ...
TOP_CELL_M = 0.05  # ... cover at least TOP_CELLS connected cells of this side in plan
TOP_CELLS = 8
ABOVE_M = 0.1  # chair points higher than a piece within this of its plan ...
ABOVE_SHARE = 0.1  # ... as many as this share of its points: a seat over it
TALL_M = 1.4  # a chair whose 99th height percentile reaches this is a person ...
PERSON_MAX_M = 2.1  # ... up to this (higher: no person, a ceiling's or a wall's piece)


def low_chairs(
    points: npt.NDArray[np.floating],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    floor: npt.NDArray[np.float64] | None,
    up: npt.NDArray[np.float64],
) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.int32], npt.NDArray[np.intp]]:
    """Return (labels, clusters, relabelled indices) with chairs lower than a seat made clutter.

    `floor`: the floor plane (a, b, c, d; None: no rule); `up`: gravity-up. A relabelled
    cluster keeps its id: it stays one object.
    """
    chair = over_floor(points, labels, clusters, Label.CHAIR, floor, up)
    height, uv = chair.height, chair.uv
    clutter = []
    for g in members(clusters[chair.rows]):
        top = height[g].max()
        if top >= SEAT_MIN_M:
            continue
        if _lid_cells(uv[g][height[g] >= top - TOP_M]) < TOP_CELLS:
            continue  # legs: thin posts' ends
        lo, hi = uv[g].min(axis=0) - ABOVE_M, uv[g].max(axis=0) + ABOVE_M
        over = (height > top) & np.all((uv >= lo) & (uv <= hi), axis=1)
        over[g] = False
        if over.sum() >= ABOVE_SHARE * len(g):  # a chair's base under its seat
            continue
        clutter.append(g)
    return relabelled(labels, clusters, chair.rows, clutter, Label.CLUTTER)


def _lid_cells(uv: npt.NDArray[np.float32]) -> int:
    """Return the cells of side `TOP_CELL_M` that the largest connected piece of a lid covers.

    Connected: 8-connected on the grid, so four legs' ends are four pieces of one to four cells.
    """
    piece = connected_pieces(uv, TOP_CELL_M)
    cells = np.unique(np.column_stack([piece, grid_of(uv, TOP_CELL_M)]), axis=0)
    return int(np.bincount(cells[:, 0]).max())


def tall_chairs(
    points: npt.NDArray[np.floating],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    floor: npt.NDArray[np.float64] | None,
    up: npt.NDArray[np.float64],
) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.int32], npt.NDArray[np.intp]]:
    """Return (labels, clusters, relabelled indices) with chairs taller than a chair made person.

    A chair cluster whose 99th height percentile over the floor plane lies between `TALL_M` and
    `PERSON_MAX_M`; `floor`: the floor plane (None: no rule). Clusters keep their ids.
    """
    chair = over_floor(points, labels, clusters, Label.CHAIR, floor, up)
    tall = [
        g
        for g in members(clusters[chair.rows])
        if TALL_M <= float(np.percentile(chair.height[g], 99.0)) <= PERSON_MAX_M
    ]
    return relabelled(labels, clusters, chair.rows, tall, Label.PERSON)
