"""What structural planes give back: objects hung on a wall, and object points just off a plane.

Objects hung on a wall: the points of a wall plane that stand in front of a parallel wall.

RANSAC's best plane through a wall with a television on it can tilt to take both: on the
simulator's room 5 (2.5 cm) a plane 1.4 degrees off the wall took 2,460 wall and 2,815
television points, and a second plane the rest of that wall. A television 0.8 m tall on a
wall also rises as high as a wall does, so it passes the wall test by itself. Where two wall
planes are parallel (within `horizontal_tolerance_deg`) and lie within `wall_object_depth_m`
of each other, the one behind (farther from the room's centre) is the wall; the points the
other took that stand more than `plane_distance_m` in front of it are given back to the
objects: DBSCAN and regrowth decide what they are. A pillar or a niche's face given back
costs nothing: no object class grows over points the network does not call an object.

Object points just off a plane: RANSAC takes every point within `plane_distance_m` (2 cm),
and with it the lowest 2 cm of every chair leg, plant pot and box on the floor and the back
of a screen 1.5 cm off its wall. Where the plane's own points are tighter than that (a
simulated or a good map: 3 mm noise), its band shrinks to `structure_band_sigmas` robust
standard deviations of their distances (1.4826 x MAD; never under a quarter of
`plane_distance_m`), and the points farther into the room are given back to the objects. A
noisy map keeps the full 2 cm. The Gaussian tail of the plane's own points goes too (0.1 %
at 3 sigma): the network calls them structure or nothing, so they stay out of the objects
unless an object's regrowth reaches them.

What the network calls floor well above the floor plane: on maps fused from simulated
recordings the network calls chair seats and legs floor (0.05-0.8 m up); of the points it
labels floor more than `floor_label_max_m` above the floor plane, 99 % are objects on five
such maps. They count as unlabelled: regrowth may give them to the object around them.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from capture.recording import Label
from process.refine.config import RefineConfig

if TYPE_CHECKING:
    from process.refine.planes import Plane


def objects_on_walls(
    points: npt.NDArray[np.float32], planes: tuple[Plane, ...], cfg: RefineConfig
) -> tuple[Plane, ...]:
    """Return the planes, each wall's points in front of a parallel wall behind it given back."""
    walls = [i for i, p in enumerate(planes) if p.label == Label.WALL and len(p.removed)]
    if cfg.wall_object_depth_m <= 0 or len(walls) < 2:
        return planes
    centre = points.mean(axis=0, dtype=np.float64)
    parallel = math.cos(math.radians(cfg.horizontal_tolerance_deg))
    out = list(planes)
    for a in walls:
        front = np.zeros(len(planes[a].removed), bool)
        behind: list[int] = []
        xyz = points[planes[a].removed].astype(np.float64)
        for b in walls:
            model = _facing(planes[b].model, centre)
            if a == b or abs(float(planes[a].model[:3] @ model[:3])) < parallel:
                continue
            offset = xyz @ model[:3] + model[3]  # > 0: in front of wall b, into the room
            if not 0 < float(np.median(offset)) <= cfg.wall_object_depth_m:
                continue  # not in front of b, or too far in front to hang on it
            front |= (offset > cfg.plane_distance_m) & (offset <= cfg.wall_object_depth_m)
            behind.append(b)
        if front.any():
            note = (
                f"{int(front.sum())} points stand {cfg.plane_distance_m:g}-"
                f"{cfg.wall_object_depth_m:g} m in front of the parallel wall(s) {behind}:"
                " objects on a wall, given back to the objects"
            )
            out[a] = replace(
                planes[a], removed=planes[a].removed[~front], on_wall=int(front.sum()), note=note
            )
    return tuple(out)


def _facing(
    model: npt.NDArray[np.float64], centre: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]:
    """Return the plane's model signed so that the room's centre lies on its positive side."""
    return model if float(model[:3] @ centre + model[3]) >= 0 else -model


def tighten_bands(
    points: npt.NDArray[np.float32], planes: tuple[Plane, ...], cfg: RefineConfig
) -> tuple[Plane, ...]:
    """Return the planes, each structural one's points beyond its own noise band given back."""
    if cfg.structure_band_sigmas <= 0 or not planes:
        return planes
    centre = points.mean(axis=0, dtype=np.float64)
    out = []
    for plane in planes:
        if not plane.label or len(plane.removed) < 10:
            out.append(plane)
            continue
        model = _facing(plane.model, centre)
        offset = points[plane.removed].astype(np.float64) @ model[:3] + model[3]
        median = float(np.median(offset))
        sigma = 1.4826 * float(np.median(np.abs(offset - median)))
        band = max(median + cfg.structure_band_sigmas * sigma, cfg.plane_distance_m / 4)
        off = offset > band
        if band >= cfg.plane_distance_m or not off.any():
            out.append(plane)
            continue
        note = f"band {band * 100:.1f} cm: {int(off.sum())} points farther into the room given back"
        note = f"{plane.note}; {note}" if plane.note else note
        out.append(replace(plane, removed=plane.removed[~off], off_band=int(off.sum()), note=note))
    return tuple(out)


def floor_said_above(
    heights: npt.NDArray[np.float32] | None,
    planes: tuple[Plane, ...],
    labels: npt.NDArray[np.uint8] | None,
    structural: npt.NDArray[np.bool_],
    cfg: RefineConfig,
) -> npt.NDArray[np.bool_] | None:
    """Return the points labelled floor, off the planes, over `floor_label_max_m` above it."""
    floors = [p for p in planes if p.label == Label.FLOOR and len(p.removed)]
    if heights is None or labels is None or not floors or cfg.floor_label_max_m <= 0:
        return None
    floor_m = max(floors, key=lambda p: len(p.removed)).height_m
    above = heights > floor_m + cfg.floor_label_max_m
    said: npt.NDArray[np.bool_] = (labels == Label.FLOOR) & above & ~structural
    return said
