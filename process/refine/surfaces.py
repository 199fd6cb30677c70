"""Table surfaces: a large level plane at a desk's height above the floor is a table top.

Real-image networks call much of a white desk "wall" or clutter: on TUM `fr1_rpy` the desk is
a level plane 0.74 m above the floor whose points the network labels wall, clutter and table
by turns, and the plane step left it to the objects as it is neither floor nor ceiling. Here
a plane that is level (within `table_tolerance_deg` of gravity) and not structural is
cut into connected pieces (gaps over ~10 cm separate); a piece whose median height above the
floor plane lies in `table_heights_m` and whose surface, at the cloud's density, reaches
`table_min_area_m2` is a table surface. Its points labelled structure, clutter or nothing
become table; those the network gives another object class (a monitor's foot, a chair's arm,
a person's hand) keep it, and so do the points of `table_other_cell_m` cells labelled more
chair, person, plant or sofa than desk (structure, table, clutter): the level top of a sofa's
back beside a table joins the table's piece, and its unlabelled points are the sofa's to
regrow (simulator's room 2 at 1.2 cm: 1,272 sofa points made table). A chair seat (0.45 m)
lies below the range, a shelf board (1.6 m) above it, and a tray or a book is too small.
A piece's area is its points over the cloud's density; a desk seen from across the room is
sparser than the cloud's mean (on fused maps of simulated recordings three such desks measure
0.15-0.20 m^2 so, 0.28-0.38 m^2 at their own density), so a piece the network calls table more
than any other object is measured at its own density where that is lower.

A desk stands against a wall, and the infinite plane crosses the wall in a band a few
centimetres high: the plane's points within `plane_distance_m` of a wall plane are left out
first, so the band stays wall.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from capture.recording import OBJECT_LABELS, Label
from process.refine.config import RefineConfig
from process.refine.graph import kd_tree
from process.refine.plane_grid import (
    DENSITY_RADIUS_M,
    PIECE_CELL_M,
    connected_pieces,
    grid_of,
    over_footprint,
    plane_uv,
)
from process.refine.walls import facing, main_floor, wall_band

if TYPE_CHECKING:
    from process.refine.planes import Plane

_FOOTPRINT_CELL_M = 0.05  # cells of a table top's footprint (_on_a_body)
_BODY_MARGIN_M = 0.1  # a body under a top is counted this far over the floor and under the top
TO_TABLE = (Label.UNLABELLED, Label.CEILING, Label.FLOOR, Label.WALL, Label.CLUTTER)


def table_surfaces(
    points: npt.NDArray[np.float32],
    planes: tuple[Plane, ...],
    up: npt.NDArray[np.float64] | None,
    labels: npt.NDArray[np.uint8] | None,
    cfg: RefineConfig,
    density_per_m2: float,
) -> tuple[tuple[Plane, ...], npt.NDArray[np.bool_]]:
    """Return the planes (table surfaces noted, with why) and the mask of points made table.

    `up` is gravity-up (None: unknown, no surface); `labels` the network's labels (None: the
    mask marks every point of the surfaces).
    """
    to_table = np.zeros(len(points), bool)
    if not cfg.table_surfaces or up is None or not planes:
        return planes, to_table
    heights = points @ up.astype(np.float32)
    floor = main_floor(planes)
    if floor is None:
        note = "no floor plane: a table surface is found by its height above the floor"
        return tuple(p if p.label else replace(p, note=note) for p in planes), to_table
    floor_m = floor.height_m
    centre = points.mean(axis=0, dtype=np.float64)
    walls = []  # (model facing the room, how far in front its own points reach)
    for wall in (p for p in planes if p.label == Label.WALL):
        model = facing(wall.model, centre)
        walls.append((model, wall_band(points, wall, model, cfg)))
    loose = None  # points no object class and no structural plane holds: a cabinet's sides
    if labels is not None:
        loose = labels < Label.TABLE
        for plane in planes:
            loose[plane.removed] = False
    out = []
    for plane in planes:
        if plane.label:
            out.append(plane)
            continue
        surface, note = _surface(
            points, plane, up, heights, floor_m, walls, cfg, density_per_m2, labels, loose
        )
        top = surface
        if labels is not None:
            other = _other_cells(points, surface, plane, labels, cfg.table_other_cell_m)
            surface = surface[~other & np.isin(labels[surface], TO_TABLE)]
        to_table[surface] = True
        note = f"{plane.note}; {note}" if plane.note else note  # e.g. why it is no wall
        out.append(
            replace(plane, note=note, table_points=len(surface), top=top if len(top) else None)
        )
    return tuple(out), to_table


def _other_cells(
    points: npt.NDArray[np.float32],
    surface: npt.NDArray[np.intp],
    plane: Plane,
    labels: npt.NDArray[np.uint8],
    cell_m: float,
) -> npt.NDArray[np.bool_]:
    """Return the surface points in cells labelled more chair, person, plant or sofa than desk.

    Desk labels: structure, table and clutter. A monitor or a plant pot on a desk is labelled
    its class where it stands, but the desk around it is the desk's: monitors do not count.
    """
    if len(surface) == 0 or cell_m <= 0:
        return np.zeros(len(surface), bool)
    ij = grid_of(plane_uv(points[surface], plane.model), cell_m)
    flat = np.ravel_multi_index((ij[:, 0], ij[:, 1]), tuple(ij.max(axis=0) + 1))
    lab = labels[surface]
    other = np.bincount(flat, (lab >= Label.CHAIR) & (lab <= Label.SOFA))
    desk = np.bincount(flat, (lab > 0) & ((lab <= Label.TABLE) | (lab == Label.CLUTTER)))
    return (other > desk)[flat]


def _surface(
    points: npt.NDArray[np.float32],
    plane: Plane,
    up: npt.NDArray[np.float64],
    heights: npt.NDArray[np.float32],
    floor_m: float,
    walls: list[tuple[npt.NDArray[np.float64], float]],
    cfg: RefineConfig,
    density: float,
    labels: npt.NDArray[np.uint8] | None,
    loose: npt.NDArray[np.bool_] | None,
) -> tuple[npt.NDArray[np.intp], str]:
    """Return the inliers of the plane's pieces that are table surfaces, and why (or why not)."""
    none = np.zeros(0, np.intp)
    tilt = math.degrees(math.acos(min(1.0, abs(float(plane.model[:3] @ up)))))
    if tilt > cfg.table_tolerance_deg:
        return none, f"not level ({tilt:.0f} deg from gravity)"
    idx = plane.indices
    for wall, band in walls:  # the band where the plane crosses a wall stays wall: a thick
        # wall (raw depth) reaches farther than plane_distance_m into the room, and its points
        # at a desk's height would join a desk and a cabinet along it into one piece
        offset = points[idx] @ wall[:3].astype(np.float32) + wall[3]
        idx = idx[(offset > band) | (offset < -cfg.plane_distance_m)]
    if len(idx) == 0 or not density > 0:
        return none, "no surface left off the walls"
    pieces = connected_pieces(plane_uv(points[idx], plane.model), PIECE_CELL_M)
    low, high = cfg.table_heights_m
    kept, seen, bare = [], [], []
    kept_m2: list[float] = []
    for piece in range(int(pieces.max()) + 1):
        members = idx[pieces == piece]
        above = float(np.median(heights[members])) - floor_m
        area = len(members) / density
        if low <= above <= high and area < cfg.table_min_area_m2 and _said_table(labels, members):
            # a desk seen from across the room is sparser than the cloud's mean: a piece the
            # network calls table is measured at its own density where that is lower
            area = len(members) / min(density, own_density(points[members], plane.model))
        seen.append((area, above))
        if not (low <= above <= high and area >= cfg.table_min_area_m2):
            continue
        if (
            labels is not None
            and loose is not None
            and _on_a_body(points, members, plane, heights, floor_m, labels, loose, cfg)
        ):
            bare.append((area, above))
        else:
            kept.append(members)
            kept_m2.append(area)
    if kept:
        area = sum(kept_m2)
        above = float(np.median(heights[np.concatenate(kept)])) - floor_m
        return np.concatenate(kept), (
            f"table surface: level, {above:.2f} m above the floor (range {low:g}-{high:g}),"
            f" {area:.2f} m^2 in {len(kept)} piece(s) (>= {cfg.table_min_area_m2:g})"
        )
    if bare:
        area, above = max(bare)
        return none, (
            f"not a table surface: {area:.2f} m^2 at {above:.2f} m above the floor, under"
            f" {cfg.table_min_object_share:g} of it labelled an object, on a solid body"
            " (a counter or a cabinet)"
        )
    area, above = max(seen)
    return none, (
        f"not a table surface: largest piece {area:.2f} m^2 at {above:.2f} m above the floor"
        f" (needs {low:g}-{high:g} m and >= {cfg.table_min_area_m2:g} m^2)"
    )


def _said_table(labels: npt.NDArray[np.uint8] | None, members: npt.NDArray[np.intp]) -> bool:
    """Return whether table is the class the network gives most of the piece's object points."""
    if labels is None:
        return False
    said = labels[members]
    said = said[np.isin(said, OBJECT_LABELS)]
    return len(said) > 0 and int(np.bincount(said).argmax()) == Label.TABLE


def own_density(points: npt.NDArray[np.float32], model: npt.NDArray[np.float64]) -> float:
    """Return a plane piece's density per m^2 in the plane: the cloud's measure, on its own points.

    The mean count of its points within `DENSITY_RADIUS_M` of each, over that disc (planes.py
    measures the whole cloud so, from random points and in 3-D).
    """
    uv = np.asarray(plane_uv(points, model), np.float64)
    counts = kd_tree(uv).query_ball_point(uv, DENSITY_RADIUS_M, return_length=True)
    return float(np.mean(counts) / (math.pi * DENSITY_RADIUS_M**2))


def _on_a_body(
    points: npt.NDArray[np.float32],
    members: npt.NDArray[np.intp],
    plane: Plane,
    heights: npt.NDArray[np.float32],
    floor_m: float,
    labels: npt.NDArray[np.uint8],
    loose: npt.NDArray[np.bool_],
    cfg: RefineConfig,
) -> bool:
    """Return whether a level piece the network leaves bare tops a solid body down to the floor.

    A table stands on legs: under its top lie chairs and little else. A kitchen counter or a
    cabinet is a box: its front and sides fill the footprint's edge from the top to the floor.
    Counted are the loose points (no object class, no structural plane) from 10 cm above the
    floor to 10 cm under the top whose cell of `_FOOTPRINT_CELL_M` in the plane lies in or
    next to the piece's, per point of the piece and per metre of that band: a box's front grows
    with its height, so a TV's low cabinet (0.5 m) has less of it than a counter and had passed
    for a table under a fixed ratio (generator 5's living room: 1.4 times its top, 8,400 points
    made table and its front regrown as table). Tables reach 1.8 per metre (a table the network
    missed whole, generator 2, seed 13), counters and cabinets 3.5-6.3 (generator 5).
    """
    if float(np.mean(labels[members] >= Label.TABLE)) >= cfg.table_min_object_share:
        return False
    low, high = floor_m + _BODY_MARGIN_M, float(np.median(heights[members])) - _BODY_MARGIN_M
    band = np.flatnonzero(loose & (heights > low) & (heights < high))
    if len(band) == 0:
        return False
    own, under = (plane_uv(points[i], plane.model) for i in (members, band))
    count = int(over_footprint(own, under, _FOOTPRINT_CELL_M).sum())
    return count > cfg.table_solid_per_m * len(members) * (high - low)
