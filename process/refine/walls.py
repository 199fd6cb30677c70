"""What structural planes give back: objects hung on a wall, and object points just off a plane.

Objects hung on a wall: the points of a wall plane that stand in front of a parallel wall.

RANSAC's best plane through a wall with a television on it can tilt to take both: on the
simulator's room 5 (2.5 cm) a plane 1.4 degrees off the wall took 2,460 wall and 2,815
television points, and a second plane the rest of that wall. A television 0.8 m tall on a
wall also rises as high as a wall does, so it passes the wall test by itself. Where two wall
planes are parallel (within `horizontal_tolerance_deg`) and lie within `wall_object_depth_m`
of each other, the one behind (farther from the room's centre) is the wall; the points the
other took that stand more than `plane_distance_m` in front of it, within its extent, are
given back to the objects (a wall in front of a door recess is not on the door; a layer over
half of the wall or more is the wall fused twice, not an object on it): DBSCAN and regrowth
decide what they are. A layer that rises as high as the walls do is none: what hangs
on a wall leaves wall above or below it, while a pillar's face or a raw-depth wall's front
layer spans the wall's height, and regrowth would give it to what stands before it.

Object points just off a plane: RANSAC takes every point within `plane_distance_m` (2 cm),
and with it the lowest 2 cm of every chair leg, plant pot and box on the floor and the back
of a screen 1.5 cm off its wall. Where the plane's own points are tighter than that (a
simulated or a good map: 3 mm noise), its band shrinks to `structure_band_sigmas` robust
standard deviations of their distances (1.4826 x MAD; never under a quarter of
`plane_distance_m`), and the points farther into the room are given back to the objects. A
noisy map keeps the full 2 cm. The Gaussian tail of the plane's own points goes too (0.1 %
at 3 sigma): the network calls them structure or nothing, so they stay out of the objects
unless an object's regrowth reaches them.

A noisy wall's tail: on a map fused from raw depth the wall's own points spread past RANSAC's
2 cm band (generator 5: robust sigma 0.9-1.5 cm, depth noise growing with the square of the
distance), and the tail, which the network calls wall or nothing, is left off the plane; an
object's regrowth then takes it (generator 5's office at 60k object points: 6,800 wall points
regrown as clutter and table). Where a wall's own points spread so that `wall_noise_sigmas`
robust standard deviations pass `plane_distance_m`, the wall takes in the points on no plane
that the network calls no object, within that many sigmas of it (at most three
`plane_distance_m`) and over its own extent (its 10 cm cells and their neighbours).

A wall's own surface behind what stands before it: a sofa's back 2 cm before a wall lies in
RANSAC's 2 cm band, and the network's sofa label bleeds onto the wall behind it, so the plane
step keeps the whole sofa-labelled region for the objects (a wide object region) and regrowth
gives the wall there to the sofa (generator 4's living rooms: 1,100-1,200 wall points per room).
On a thin wall (its band tightened, as above) the plane is refitted by least squares on the
points it removed as bare wall, dropping those off it (`REFITS`): the points the plane kept
that lie within that wall's band, with a point the network calls a standing class (table,
chair, person, plant, sofa) up to `FRONT_M` before them in their cell or the next
(`BEHIND_CELL_M`), are the wall behind that object, and the wall takes them in
(`walls_behind_objects`). What hangs on a wall, a screen, may lie within the band (generator 4's
wall TV: its back face 5 mm off the wall) and is left alone. A noisy wall's band (its refit's, at
most `WIDE_CAP` plane distances) cannot tell a sofa's back 2 cm before it, so there only a
plant's foliage counts as standing before it (`NOISY_FRONT`): foliage never lies flat on a wall,
and the network's plant label bleeds onto the wall right behind it (generator 5's rooms at 60k,
walls fused from raw depth with a robust sigma of 0.9-1.5 cm: +0.003 to +0.009).

Points behind a wall: an object in front of a wall never grows through it. Where a wall has a
door or window recess, the recess's back and jambs stand 5-15 cm behind the wall plane, unlabelled
(generator 3: a desk beside a door regrew 4,200 such points as table, sofa and monitor). Points
more than `wall_keep_out_m` behind a wall plane, within the wall's extent, join no object in
regrowth. The network's own labels there stand (through an open door: the next room's chairs).

What the network calls floor well above the floor plane: on maps fused from simulated
recordings the network calls chair seats and legs floor (0.05-0.8 m up); of the points it
labels floor more than `floor_label_max_m` above the floor plane, 99 % are objects on five
such maps. They count as unlabelled: regrowth may give them to the object around them.

Lower down, between RANSAC's band over the floor plane (`plane_distance_m`) and
`floor_label_max_m`, the network's "floor" is mostly the feet of chairs and tables standing on
it (eight fresh simulated recordings, off the planes: 645 object points 4-10 cm up, 71 floor
points; 390 and 1,271 at 2-4 cm, the fused floor's upper voxel layer). There regrowth may take
them into the object they touch (`floor_band_regrows`); what no object reaches keeps the
network's floor label (the eight recordings: 739 points changed, 629 to their true class, 12
right before; +0.000 to +0.0044 F1 each).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
from scipy.stats import median_abs_deviation

from capture.recording import Label
from process.refine.config import RefineConfig
from process.refine.graph import kd_tree
from process.refine.plane_grid import grid_of, over_footprint, plane_uv
from process.refine.regrowth import STANDING

if TYPE_CHECKING:
    from process.refine.planes import Plane


def objects_on_walls(
    points: npt.NDArray[np.float32],
    planes: tuple[Plane, ...],
    cfg: RefineConfig,
    heights: npt.NDArray[np.float32] | None = None,
) -> tuple[Plane, ...]:
    """Return the planes, each wall's points in front of a parallel wall behind it given back.

    With `heights` (along gravity-up), a layer as tall as the walls is no object (_full_height).
    """
    if cfg.wall_object_depth_m <= 0:
        return planes
    out = list(planes)
    room_m = _walls_height(heights, planes)
    for a, pairs in _parallel_walls(points, planes, cfg):
        front = np.zeros(len(planes[a].removed), bool)
        behind: list[int] = []
        xyz = points[planes[a].removed]
        for b, model in pairs:
            offset = xyz.astype(np.float64) @ model[:3] + model[3]  # > 0: in front of wall b
            if not 0 < float(np.median(offset)) <= cfg.wall_object_depth_m:
                continue  # not in front of b, or too far in front to hang on it
            # ... within b's extent (a wall stands in front of a door recess, not on it), and
            # covering less than half of b (ON_WALL_AREA_SHARE)
            uv, wall = plane_uv(xyz, model), plane_uv(points[planes[b].removed], model)
            given = (offset > cfg.plane_distance_m) & (offset <= cfg.wall_object_depth_m)
            given &= _within_extent(uv, wall)
            # ... standing proud of b's own noise band: a thick wall (raw depth, no TSDF) comes
            # out as parallel planes a few centimetres apart, and its front layer is no object
            # (generator 5's front layers lie 2.8-3.1 cm before bands of 2.8-4.1 cm; a screen
            # stands 5-10 cm proud of a 3 mm-noise wall's 1 cm band)
            proud = given.any() and np.median(offset[given]) >= wall_band(
                points, planes[b], model, cfg
            )
            if proud and _full_height(heights, planes[a].removed[given], room_m):
                continue  # the wall's own face: a pillar's, a thick wall's front layer
            if proud and _area_m2(uv[given]) < ON_WALL_AREA_SHARE * _area_m2(wall):
                front |= given
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


def wall_band(
    points: npt.NDArray[np.float32], wall: Plane, model: npt.NDArray[np.float64], cfg: RefineConfig
) -> float:
    """Return how far in front of `model` (the wall, signed) the wall's own points reach.

    The median of its inliers' distances plus `structure_band_sigmas` robust sigmas, and half
    `plane_distance_m` more; at least `plane_distance_m` (all of it without a band).
    """
    if cfg.structure_band_sigmas <= 0 or len(wall.indices) < 10:
        return cfg.plane_distance_m
    own = points[wall.indices].astype(np.float64) @ model[:3] + model[3]
    band = _noise_band(own, cfg.structure_band_sigmas) + cfg.plane_distance_m / 2
    return max(band, cfg.plane_distance_m)


def _noise_band(offset: npt.NDArray[np.float64], sigmas: float) -> float:
    """Return the median of a plane's point distances plus `sigmas` robust sigmas (1.4826 MAD)."""
    return float(np.median(offset)) + sigmas * float(median_abs_deviation(offset, scale="normal"))


# What hangs on a wall covers less than this share of the wall's area. A layer that covers
# more is the wall itself fused twice: on TUM fr1_rpy odometry's drift leaves the back wall as
# two planes 5-12 cm apart that cross, and the front one (9,600 inliers) stood in front of the
# other over 2.37 of its 2.40 m^2 in one draw of RANSAC and not in another, so a wall's worth of
# points went to the objects or not by chance. Objects hung on walls on the development clouds
# cover 1-21 % of their wall (televisions, boards), wall layers of generator 3 29-43 %.
ON_WALL_AREA_SHARE = 0.5
FULL_HEIGHT = 0.9  # a layer spanning this share of the walls' height is a face of the wall


def _walls_height(heights: npt.NDArray[np.float32] | None, planes: tuple[Plane, ...]) -> float:
    """Return the tallest wall's span of heights (1st to 99th percentile; nan: unknown)."""
    if heights is None:
        return math.nan
    walls = [p.removed for p in planes if p.label == Label.WALL and len(p.removed)]
    spans = [float(np.ptp(np.percentile(heights[w], [1.0, 99.0]))) for w in walls]
    return max(spans, default=math.nan)


def _full_height(
    heights: npt.NDArray[np.float32] | None, layer: npt.NDArray[np.intp], room_m: float
) -> bool:
    """Return whether a layer before a wall rises as high as the walls do: the wall's own face.

    What hangs on a wall (a television, a whiteboard) leaves wall above or below it; a layer
    spanning FULL_HEIGHT of the tallest wall's heights is a pillar's or a chimney breast's face
    or the front layer of a wall fused from raw depth (generator 5's office at 60k object
    points: a layer 4.7 m wide, floor to ceiling, 5.5 cm before its wall, was given back and
    regrown as clutter, 3,900 points).
    """
    if heights is None or len(layer) == 0 or math.isnan(room_m):
        return False
    low, high = np.percentile(heights[layer], [1.0, 99.0])
    return bool(high - low >= FULL_HEIGHT * room_m)


def furniture_fronts(
    points: npt.NDArray[np.float32],
    heights: npt.NDArray[np.float32] | None,
    planes: tuple[Plane, ...],
    cfg: RefineConfig,
) -> tuple[Plane, ...]:
    """Return the planes, walls that are a cabinet's or bookcase's front made no structure.

    A wall reaches as high as the wall behind it; a tall cabinet against a wall rises past
    `wall_min_height_m` too (generator 3: a 1.8 m bookcase front, 13,400 points, taken as wall),
    but stands `wall_object_depth_m`-`furniture_depth_m` in front of a larger parallel wall and
    ends more than `furniture_top_gap_m` below that wall's top.
    """
    if heights is None or cfg.furniture_depth_m <= 0:
        return planes
    out = list(planes)
    for a, pairs in _parallel_walls(points, planes, cfg):
        median = np.median(points[planes[a].removed].astype(np.float64), axis=0)
        top_a = float(np.percentile(heights[planes[a].removed], 99))
        for b, model in pairs:
            depth = float(median @ model[:3] + model[3])
            gap = float(np.percentile(heights[planes[b].removed], 99)) - top_a
            if (
                len(planes[b].removed) > len(planes[a].removed)
                and cfg.wall_object_depth_m < depth <= cfg.furniture_depth_m
                and gap > cfg.furniture_top_gap_m
            ):
                note = (
                    f"not a wall: {depth:.2f} m in front of wall {b} and {gap:.2f} m below its"
                    " top (furniture), given back to the objects"
                )
                out[a] = replace(planes[a], label=0, removed=planes[a].removed[:0], note=note)
                break
    return tuple(out)


def _parallel_walls(
    points: npt.NDArray[np.float32], planes: tuple[Plane, ...], cfg: RefineConfig
) -> Iterator[tuple[int, list[tuple[int, npt.NDArray[np.float64]]]]]:
    """Yield each wall and the other walls parallel to it, each facing the room's centre."""
    walls = [i for i, p in enumerate(planes) if p.label == Label.WALL and len(p.removed)]
    if len(walls) < 2:
        return
    centre = points.mean(axis=0, dtype=np.float64)
    parallel = math.cos(math.radians(cfg.horizontal_tolerance_deg))
    faced = {b: facing(planes[b].model, centre) for b in walls}
    for a in walls:
        normal = planes[a].model[:3]
        yield (
            a,
            [
                (b, faced[b])
                for b in walls
                if b != a and abs(float(normal @ faced[b][:3])) >= parallel
            ],
        )


def _within_extent(
    uv: npt.NDArray[np.float32], wall: npt.NDArray[np.float32]
) -> npt.NDArray[np.bool_]:
    """Return which points (u, v on a wall's plane) lie within the wall's extent.

    The extent: the box of the wall's own points (`wall`, u, v) along it and up it (a plane
    extended past a wall's ends would cut through a room).
    """
    inside: npt.NDArray[np.bool_] = np.all(
        (uv >= wall.min(axis=0)) & (uv <= wall.max(axis=0)), axis=1
    )
    return inside


def _area_m2(uv: npt.NDArray[np.float32], cell_m: float = 0.1) -> float:
    """Return the area of the plane's 10 cm cells that hold points."""
    return len(np.unique(grid_of(uv, cell_m), axis=0)) * cell_m**2


def facing(
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
        model = facing(plane.model, centre)
        offset = points[plane.removed].astype(np.float64) @ model[:3] + model[3]
        band = max(_noise_band(offset, cfg.structure_band_sigmas), cfg.plane_distance_m / 4)
        off = offset > band
        if band >= cfg.plane_distance_m or not off.any():
            out.append(plane)
            continue
        note = f"band {band * 100:.1f} cm: {int(off.sum())} points farther into the room given back"
        note = f"{plane.note}; {note}" if plane.note else note
        out.append(replace(plane, removed=plane.removed[~off], off_band=int(off.sum()), note=note))
    return tuple(out)


WIDE_CAP = 3.0  # a noisy wall's band: at most this many plane_distance_m
EXTENT_CELL_M = 0.1  # a plane's extent: its cells of this size and their neighbours


def widen_bands(
    points: npt.NDArray[np.float32],
    planes: tuple[Plane, ...],
    labels: npt.NDArray[np.uint8] | None,
    cfg: RefineConfig,
) -> tuple[Plane, ...]:
    """Return the planes, each noisy wall with the tail of its noise off every plane taken in.

    The tail: points on no plane that the network (`labels`) calls structure or nothing,
    within `wall_noise_sigmas` robust sigmas of the wall's inliers' median distance.
    """
    if labels is None or cfg.wall_noise_sigmas <= 0 or not planes:
        return planes
    free = labels < Label.TABLE
    for plane in planes:
        free[plane.indices] = False
        free[plane.removed] = False
    out = []
    for plane in planes:
        band = _wall_noise(points, plane, cfg)
        if band is None:
            out.append(plane)
            continue
        median, width = band
        taken = near_plane(points, plane, np.flatnonzero(free), width, centre=median)
        if len(taken) == 0:
            out.append(plane)
            continue
        free[taken] = False
        note = f"band {width * 100:.1f} cm: {len(taken)} points of its noise taken in"
        out.append(replace(_taken_in(plane, taken, note), noise_taken=len(taken)))
    return tuple(out)


def near_plane(
    points: npt.NDArray[np.float32],
    plane: Plane,
    candidates: npt.NDArray[np.intp],
    width: float,
    *,
    centre: float = 0.0,
) -> npt.NDArray[np.intp]:
    """Return the candidates within `width` of `centre` along the plane's normal, over its extent.

    The extent: the `EXTENT_CELL_M` cells of the points it removes as structure, and their
    neighbours (corners too).
    """
    offset = points[candidates].astype(np.float64) @ plane.model[:3] + plane.model[3]
    candidates = candidates[np.abs(offset - centre) <= width]
    own, uv = (plane_uv(points[i], plane.model) for i in (plane.removed, candidates))
    inside: npt.NDArray[np.intp] = candidates[over_footprint(own, uv, EXTENT_CELL_M, diagonal=True)]
    return inside


def _taken_in(plane: Plane, taken: npt.NDArray[np.intp], note: str) -> Plane:
    """Return the plane with `taken` among the points it removes as structure, noted and counted."""
    note = f"{plane.note}; {note}" if plane.note else note
    return replace(plane, removed=np.union1d(plane.removed, taken), note=note)


def _wall_noise(
    points: npt.NDArray[np.float32], plane: Plane, cfg: RefineConfig
) -> tuple[float, float] | None:
    """Return a noisy wall's (median distance, band half-width); None for any other plane."""
    if plane.label != Label.WALL or len(plane.removed) < 10:
        return None
    own = points[plane.indices].astype(np.float64) @ plane.model[:3] + plane.model[3]
    median = float(np.median(own))
    sigma = float(median_abs_deviation(own, scale="normal"))
    width = min(cfg.wall_noise_sigmas * sigma, WIDE_CAP * cfg.plane_distance_m)
    return (median, width) if width > cfg.plane_distance_m else None


def wall_bands(
    points: npt.NDArray[np.float32], planes: tuple[Plane, ...], cfg: RefineConfig
) -> list[tuple[npt.NDArray[np.float64], float]]:
    """Return each wall's plane, signed towards the room's centre, with its band (`wall_band`)."""
    walls = [plane for plane in planes if plane.label == Label.WALL]
    if not walls:  # and an empty cloud has no centre
        return []
    centre = points.mean(axis=0, dtype=np.float64)
    models = [facing(plane.model, centre) for plane in walls]
    return [(m, wall_band(points, p, m, cfg)) for p, m in zip(walls, models, strict=True)]


def main_floor(planes: tuple[Plane, ...]) -> Plane | None:
    """Return the floor plane with the most points of its own (None: no floor plane)."""
    return max(
        (p for p in planes if p.label == Label.FLOOR), key=lambda p: len(p.removed), default=None
    )


def floor_said_above(
    heights: npt.NDArray[np.float32] | None,
    planes: tuple[Plane, ...],
    labels: npt.NDArray[np.uint8] | None,
    structural: npt.NDArray[np.bool_],
    cfg: RefineConfig,
) -> npt.NDArray[np.bool_] | None:
    """Return the points labelled floor, off the planes, over `floor_label_max_m` above it."""
    floor = main_floor(planes)
    if heights is None or labels is None or floor is None or not len(floor.removed):
        return None
    if cfg.floor_label_max_m <= 0:
        return None
    above = heights > floor.height_m + cfg.floor_label_max_m
    said: npt.NDArray[np.bool_] = (labels == Label.FLOOR) & above & ~structural
    return said


def floor_said_low(
    points: npt.NDArray[np.float32],
    planes: tuple[Plane, ...],
    up: npt.NDArray[np.float64] | None,
    labels: npt.NDArray[np.uint8],
    cfg: RefineConfig,
) -> npt.NDArray[np.bool_]:
    """Return the points labelled floor, past RANSAC's band, up to `floor_label_max_m` above it.

    `points` are off every structural plane and `labels` their network labels; the band is
    `plane_distance_m` over the largest floor plane.
    """
    floor = main_floor(planes)
    if up is None or floor is None or not len(floor.removed) or cfg.floor_label_max_m <= 0:
        return np.zeros(len(points), bool)
    heights = points @ up.astype(np.float32) - np.float32(floor.height_m)
    low: npt.NDArray[np.bool_] = (labels == Label.FLOOR) & (heights > cfg.plane_distance_m)
    return low & (heights <= cfg.floor_label_max_m)


def behind_walls(
    points: npt.NDArray[np.float32], planes: tuple[Plane, ...], cfg: RefineConfig
) -> npt.NDArray[np.bool_]:
    """Return the points more than `wall_keep_out_m` behind a wall plane, within its extent.

    Behind: on the side away from the room's centre.
    """
    out = np.zeros(len(points), bool)
    walls = [p for p in planes if p.label == Label.WALL and len(p.removed)]
    if cfg.wall_keep_out_m <= 0 or not walls:
        return out
    centre = points.mean(axis=0, dtype=np.float64)
    for wall in walls:
        model = facing(wall.model, centre)
        offset = points @ model[:3].astype(np.float32) + np.float32(model[3])
        candidates = np.flatnonzero(offset < -cfg.wall_keep_out_m)
        if len(candidates):
            uv, own = plane_uv(points[candidates], model), plane_uv(points[wall.removed], model)
            out[candidates[_within_extent(uv, own)]] = True
    return out


# a wall's own surface behind what stands before it (walls_behind_objects)
FRONT_M = 0.15  # an object standing this close before a wall has the wall behind it
BEHIND_CELL_M = 0.05  # ... over this grid of the wall's plane (a cell and its side neighbours)
FRONT_NEIGHBOURS = 8  # a point is behind the layer of its nearest standing points before it
REFITS = 3  # the wall's plane refitted on its bare points this often, ...
REFIT_SIGMAS = 2.5  # ... each time dropping those this many robust sigmas off it
REFIT_TURN_DEG = 10.0  # a refit turned further from RANSAC's plane is not the wall's
NOISY_FRONT = (Label.PLANT,)  # the standing classes before a noisy wall


def walls_behind_objects(
    points: npt.NDArray[np.float32],
    planes: tuple[Plane, ...],
    labels: npt.NDArray[np.uint8] | None,
    cfg: RefineConfig,
) -> tuple[Plane, ...]:
    """Return the planes, each wall with its own surface behind standing objects taken in.

    Args:
        points: (N, 3) the cloud.
        planes: the planes so far; only walls whose band was tightened change.
        labels: (N,) the network's labels (phase I); None: the planes as they are.
        cfg: `walls_behind_objects` switches it; `structure_band_sigmas` gives the band.
    """
    if labels is None or not cfg.walls_behind_objects or cfg.structure_band_sigmas <= 0:
        return planes
    standing = np.flatnonzero(np.isin(labels, STANDING))
    if len(standing) == 0 or not any(p.label == Label.WALL for p in planes):
        return planes
    centre = points.mean(axis=0, dtype=np.float64)
    out = []
    for plane in planes:
        surface = _own_surface(points, plane, centre, cfg)
        if surface is None:
            out.append(plane)
            continue
        model, middle, band, noisy = surface
        rest = np.setdiff1d(plane.indices, plane.removed)
        depth = points[rest].astype(np.float64) @ model[:3] + model[3]
        rest, depth = rest[depth <= band], depth[depth <= band]
        offset = points[standing].astype(np.float64) @ model[:3] + model[3]
        ahead = (offset > band) & (offset <= FRONT_M)
        if noisy:
            ahead &= np.isin(labels[standing], NOISY_FRONT)
        front, front_depth = standing[ahead], offset[ahead]
        if len(rest) == 0 or len(front) == 0:
            out.append(plane)
            continue
        uv_front, uv_rest = plane_uv(points[front], model), plane_uv(points[rest], model)
        behind = over_footprint(uv_front, uv_rest, BEHIND_CELL_M)
        if not behind.any():
            out.append(plane)
            continue
        # nearer the wall than the layer before it: the sofa's back in a noisy band stays
        _, near = kd_tree(uv_front).query(uv_rest[behind], min(FRONT_NEIGHBOURS, len(front)))
        level = np.median(front_depth[near.reshape(int(behind.sum()), -1)], axis=1)
        behind[behind] = depth[behind] < (middle + level) / 2
        taken = rest[behind]
        if len(taken) == 0:
            out.append(plane)
            continue
        note = f"{len(taken)} points of its surface behind standing objects taken in"
        out.append(replace(_taken_in(plane, taken, note), behind_taken=len(taken)))
    return tuple(out)


def _own_surface(
    points: npt.NDArray[np.float32],
    plane: Plane,
    centre: npt.NDArray[np.float64],
    cfg: RefineConfig,
) -> tuple[npt.NDArray[np.float64], float, float, bool] | None:
    """Return a wall's plane fitted to its bare points, their median offset, band and noise.

    Noisy: its band is wider than RANSAC's (and then at most WIDE_CAP plane distances). The plane
    faces the room; the band's upper edge is the offset below which a point is on it.

    RANSAC's plane through a wall and a sofa's back 2 cm before it lies between the two and
    tilts (generator 4's living room: the wall's points spread over 3 cm of its offsets); the
    least-squares plane of the points it removed as wall, refitted without those off it, is the
    wall's own. None for a plane that is no wall or whose refit turns more than `REFIT_TURN_DEG`
    from RANSAC's plane (bare points along a strip).
    """
    if plane.label != Label.WALL or len(plane.removed) < 10:
        return None
    bare = points[plane.removed].astype(np.float64)
    model = facing(plane.model, centre)
    for _ in range(REFITS):
        mean = bare.mean(axis=0)
        normal = np.linalg.svd(bare - mean, full_matrices=False)[2][2]  # least spread
        model = facing(np.append(normal, -normal @ mean), centre)
        offset = bare @ model[:3] + model[3]
        sigma = float(median_abs_deviation(offset, scale="normal"))
        keep = np.abs(offset - np.median(offset)) <= REFIT_SIGMAS * sigma
        if keep.sum() < 10:
            break
        bare = bare[keep]
    if abs(float(model[:3] @ plane.model[:3])) < math.cos(math.radians(REFIT_TURN_DEG)):
        return None  # bare points on a line or a strip: no plane of their own to trust
    offset = bare @ model[:3] + model[3]
    band = max(_noise_band(offset, cfg.structure_band_sigmas), cfg.plane_distance_m / 4)
    noisy = band >= cfg.plane_distance_m
    band = min(band, WIDE_CAP * cfg.plane_distance_m)
    return model, float(np.median(offset)), band, noisy
