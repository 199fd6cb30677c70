"""Step 1: iterative RANSAC planes, classified as ceiling, floor or wall against gravity."""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from capture.recording import OBJECT_LABELS, Label
from process.refine.config import RefineConfig
from process.refine.graph import kd_tree
from process.refine.gravity import gravity
from process.refine.plane_grid import (
    DENSITY_RADIUS_M,
    PIECE_CELL_M,
    connected_pieces,
    plane_uv,
    wide_object_regions,
)
from process.refine.ransac import best_plane
from process.refine.surfaces import table_surfaces
from process.refine.walls import (
    floor_said_above,
    furniture_fronts,
    objects_on_walls,
    tighten_bands,
    walls_behind_objects,
    widen_bands,
)

logger = logging.getLogger(__name__)

_STRUCTURE_SHARE = 0.5  # a plane the network labels this much floor (ceiling, wall) is one
_WALL_OBJECT_MAX = 0.5  # an upright plane whose wall points the network labels more objects is
# no wall: a standing person's front and a chair's back in line (fresh recordings 68 and 74:
# 98 and 100 % object labels, 98 and 99 % object points). Of 881 wall planes on the suite's,
# the held-out and 20 fresh recordings' clouds, every other one is at most 15 % object labels


@dataclass(frozen=True)
class Plane:
    """One RANSAC plane: model, inliers and what it was classified as."""

    model: npt.NDArray[np.float64]  # (4,) a b c d, unit normal: a x + b y + c z + d = 0
    indices: npt.NDArray[np.intp]  # RANSAC inliers, indices into the input cloud
    label: int  # 1 ceiling, 2 floor, 3 wall; 0 = not structural, stays in the object cloud
    removed: npt.NDArray[np.intp]  # the inliers taken out as structure (connected pieces)
    height_m: float  # mean height of the removed (else all) inliers along `up`; nan if unknown
    network_label: int = 0  # the structure label the network gives most of it (0: none)
    kept_as_objects: int = 0  # inliers of a wide object-labelled region, left to the objects
    table_points: int = 0  # inliers of a table surface (surfaces.py) that become table
    on_wall: int = 0  # inliers in front of a parallel wall behind, given back (walls.py)
    off_band: int = 0  # inliers beyond the plane's own noise band, given back (walls.py)
    noise_taken: int = 0  # points of a noisy wall beyond RANSAC's band, taken in (walls.py)
    behind_taken: int = 0  # points of a wall's surface behind standing objects, taken in
    note: str = ""  # why a level plane that is not structural is (not) a table surface
    top: npt.NDArray[np.intp] | None = None  # a table surface's points, whatever their labels


@dataclass(frozen=True)
class PlaneSegmentation:
    """All planes found, the structural label of every input point, and the gravity used."""

    planes: tuple[Plane, ...]
    labels: npt.NDArray[np.uint8]  # (N,) 1/2/3 on structural planes, 0 elsewhere
    up: npt.NDArray[np.float64] | None  # (3,) unit gravity-up; None when it could not be found
    up_source: str  # how `up` was found: one of gravity.gravity's sources
    min_points: int = 0  # the Min used: a plane needs this many inliers
    density_per_m2: float = math.nan  # the cloud's surface density it was derived from
    table: npt.NDArray[np.bool_] | None = None  # (N,) points of table surfaces, made table
    not_floor: npt.NDArray[np.bool_] | None = None  # (N,) "floor" well above it (walls.py)
    faces_only: tuple[Plane, ...] = ()  # planes past max_planes that are no structure: only
    # bare faces are looked for on them (faces.py)

    def object_labels(self, labels: npt.NDArray[np.uint8]) -> npt.NDArray[np.uint8]:
        """Return the network's labels, table surfaces table, "floor" above the floor 0."""
        if self.not_floor is not None and self.not_floor.any():
            labels = np.where(self.not_floor, np.uint8(0), labels).astype(np.uint8)
        if self.table is None or not self.table.any():
            return labels
        return np.where(self.table, np.uint8(Label.TABLE), labels).astype(np.uint8)

    @property
    def structural(self) -> npt.NDArray[np.bool_]:
        """Return the mask of points removed from the object cloud (on a structural plane)."""
        return self.labels > 0


def segment_planes(
    points: npt.NDArray[np.float32],
    cfg: RefineConfig,
    *,
    up: npt.NDArray[np.float64] | None,
    labels: npt.NDArray[np.uint8] | None = None,
) -> PlaneSegmentation:
    """Find planes until one has fewer than Min inliers or fewer than Max points remain.

    Min is `cfg.plane_min_points` when set, else relative to the cloud (`min_plane_points`).
    `labels` are the network's labels of the points (phase I), if any: where they call the
    planes floor, ceiling or wall, they help find gravity (gravity.py) and classify the planes.
    """
    rng = np.random.default_rng(cfg.seed)
    min_points, density = min_plane_points(points, cfg, rng)
    remaining = np.arange(len(points))
    found: list[tuple[npt.NDArray[np.float64], npt.NDArray[np.intp]]] = []
    while (
        len(found) < cfg.max_planes + cfg.structure_planes
        and len(remaining) > cfg.plane_max_remaining
        and len(remaining) >= min_points
    ):
        model, inliers = _ransac_plane(points[remaining], cfg, rng)
        if len(inliers) < min_points:
            break
        found.append((model, remaining[inliers]))
        remaining = np.delete(remaining, inliers)
    if up is None and cfg.up is not None:
        up = np.asarray(cfg.up, np.float64)
    tolerance = cfg.horizontal_tolerance_deg
    up_used, source = gravity(points, found, up, labels=labels, level_tolerance_deg=tolerance)
    heights = None if up_used is None else points @ up_used.astype(np.float32)
    planes = tuple(
        _classify(points, m, idx, heights, up_used, cfg, min_points, labels) for m, idx in found
    )
    # past max_planes only structure counts: in a furnished room desk, seat and sofa tops use up
    # the first planes, and a wall found later would otherwise be left to regrowth
    extra = tuple(p for p in planes[cfg.max_planes :] if not p.label)
    planes = planes[: cfg.max_planes] + tuple(p for p in planes[cfg.max_planes :] if p.label)
    planes = furniture_fronts(points, heights, planes, cfg)
    planes = tighten_bands(points, objects_on_walls(points, planes, cfg, heights), cfg)
    planes = walls_behind_objects(points, planes, labels, cfg)
    planes = widen_bands(points, planes, labels, cfg)
    planes, table = table_surfaces(points, planes, up_used, labels, cfg, density)
    structure = np.zeros(len(points), np.uint8)
    for plane in planes:
        structure[plane.removed] = plane.label
    logger.debug("planes (Min %d): %s", min_points, [(p.label, len(p.indices)) for p in planes])
    not_floor = floor_said_above(heights, planes, labels, structure > 0, cfg)
    return PlaneSegmentation(
        planes, structure, up_used, source, min_points, density, table, not_floor, extra
    )


def min_plane_points(
    points: npt.NDArray[np.float32], cfg: RefineConfig, rng: np.random.Generator
) -> tuple[int, float]:
    """Return (Min, surface density per m^2): the configured Min, else one relative to the cloud.

    The relative Min is the smaller of `plane_min_area_m2` at the cloud's density and
    `plane_min_share` of its points, at least 3. The density is the mean count of points
    within 5 cm of 2,000 random points over the disc of 5 cm: a voxel map at 2 cm gives
    ~2,500 per m^2, so a floor needs 1 m^2 of it seen.
    """
    if len(points) < 3:
        return max(cfg.plane_min_points, 3), math.nan

    probe = points[rng.choice(len(points), min(2000, len(points)), replace=False)]
    counts = kd_tree(points).query_ball_point(probe, DENSITY_RADIUS_M, return_length=True)
    density = float(np.mean(counts) / (math.pi * DENSITY_RADIUS_M**2))
    if cfg.plane_min_points:
        return cfg.plane_min_points, density
    by_area, by_share = cfg.plane_min_area_m2 * density, cfg.plane_min_share * len(points)
    return max(3, round(min(by_area, by_share))), density


def _ransac_plane(
    points: npt.NDArray[np.float32], cfg: RefineConfig, rng: np.random.Generator
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.intp]]:
    """Return the best plane (RANSAC on a sample, refit on all inliers) and its inliers."""
    sample = points
    if 0 < cfg.plane_sample_points < len(points):
        # hypotheses scored on a random subset find the same dominant plane; all points are
        # then tested against it, so inlier counts are exact
        sample = points[rng.choice(len(points), cfg.plane_sample_points, replace=False)]
    model, _ = best_plane(
        sample,
        uniform=cfg.plane_iterations,
        local=cfg.plane_local_hypotheses,
        distance_m=cfg.plane_distance_m,
        rng=rng,
    )
    inliers = _inliers(points, model, cfg.plane_distance_m)
    if len(inliers) >= 3:
        model = _fit_plane(points[inliers])
        inliers = _inliers(points, model, cfg.plane_distance_m)
    return model, inliers


def _inliers(
    points: npt.NDArray[np.float32], model: npt.NDArray[np.float64], distance_m: float
) -> npt.NDArray[np.intp]:
    distance = np.abs(points @ model[:3].astype(np.float32) + np.float32(model[3]))
    return np.flatnonzero(distance <= distance_m)


def _fit_plane(points: npt.NDArray[np.float32]) -> npt.NDArray[np.float64]:
    """Return the least-squares plane (smallest principal axis through the centroid)."""
    centroid = points.mean(axis=0, dtype=np.float64)
    centred = points - centroid.astype(np.float32)
    covariance = (centred.T @ centred).astype(np.float64)
    normal = np.linalg.eigh(covariance)[1][:, 0]
    return np.append(normal, -normal @ centroid)


def _classify(
    points: npt.NDArray[np.float32],
    model: npt.NDArray[np.float64],
    indices: npt.NDArray[np.intp],
    heights: npt.NDArray[np.float32] | None,  # (N,) every point's height along up
    up: npt.NDArray[np.float64] | None,
    cfg: RefineConfig,
    min_points: int,
    labels: npt.NDArray[np.uint8] | None = None,
) -> Plane:
    """Classify a plane by its orientation and position along `up`, not by its size.

    Floor: level, at the bottom of the cloud, with the room rising `wall_min_height_m` above
    it. Ceiling: level, at the top, that far above the bottom. Wall: upright, rising that high
    above the bottom and spanning half of it itself. A table top seen from above is level and
    at the bottom of a table scene, but nothing rises a room's height above it: it stays an
    object. Where the network labels most of the plane floor (ceiling, wall), that stands in
    for the room's height: a map of furniture seen from above holds the floor but little wall;
    and where it labels most of an upright plane's points objects, the plane is theirs, no
    wall (`_WALL_OBJECT_MAX`). Only the plane's large connected pieces count: RANSAC's
    infinite plane also takes the coplanar faces of furniture far from the wall or floor,
    which must stay objects.
    """
    none = np.zeros(0, np.intp)
    if up is None or heights is None:
        return Plane(model, indices, 0, none, math.nan)
    cosine = abs(float(model[:3] @ up))
    tolerance = math.radians(cfg.horizontal_tolerance_deg)
    level, upright = cosine >= math.cos(tolerance), cosine <= math.sin(tolerance)
    pieces = _large_pieces(points[indices], model, min_points) if level or upright else None
    if pieces is None or int(pieces.sum()) < min_points:
        return Plane(model, indices, 0, none, float(heights[indices].mean()))
    kept = indices[pieces]
    height = float(heights[kept].mean())
    low, high = (float(v) for v in np.percentile(heights, [1.0, 99.0]))
    label = 0
    room, tol = cfg.wall_min_height_m, cfg.structure_height_tol_m
    said = _network_says(labels, kept)
    if level and height - low <= tol and (high - height >= room or said == Label.FLOOR):
        label = Label.FLOOR
    elif level and high - height <= tol and (height - low >= room or said == Label.CEILING):
        label = Label.CEILING
    elif upright and (_is_wall(heights[kept], low, room) or said == Label.WALL):
        label = Label.WALL
    flat = np.zeros(len(kept), bool)
    if label and labels is not None and cfg.plane_object_width_m > 0:
        # objects lying flat on the structure stay objects; label bleed onto it does not. On a
        # floor or ceiling a region is the objects' only where they are most of all its points:
        # a network that labels no floor (VOC) leaves the bleed around feet and legs the only
        # labels there (generator 3: 2,200 floor points regrown as person). On a wall a quarter
        # will do, as a sofa back against it is seen with holes; but not less: a network that
        # labels no wall makes every cell with a few bleeding labels an object's (generator 5:
        # the wall behind a desk, 4 % object labels, regrown as desk and monitor).
        flat = wide_object_regions(
            plane_uv(points[kept], model),
            labels[kept],
            width_m=cfg.plane_object_width_m,
            min_share=cfg.wall_object_share if label == Label.WALL else 0.5,
        )
    removed = kept[~flat] if label else none
    if (
        label == Label.WALL
        and labels is not None
        and _object_share(labels, removed) > _WALL_OBJECT_MAX
    ):
        label, removed, flat = 0, none, np.zeros(0, bool)
    return Plane(model, indices, label, removed, height, said, int(flat.sum()))


def _object_share(labels: npt.NDArray[np.uint8], rows: npt.NDArray[np.intp]) -> float:
    """Return the share of these points the network labels an object class (0 if none)."""
    return float(np.isin(labels[rows], OBJECT_LABELS).mean()) if len(rows) else 0.0


def _network_says(labels: npt.NDArray[np.uint8] | None, kept: npt.NDArray[np.intp]) -> int:
    """Return the structure label the network gives most of the plane's points, else 0."""
    if labels is None or len(kept) == 0:
        return 0
    counts = np.bincount(labels[kept], minlength=int(Label.WALL) + 1)
    label = int(np.argmax(counts[1 : int(Label.WALL) + 1])) + 1
    return label if counts[label] >= _STRUCTURE_SHARE * len(kept) else 0


def _is_wall(heights: npt.NDArray[np.float32], low: float, room_m: float) -> bool:
    """Return whether an upright plane rises `room_m` above the floor and spans half of it.

    Chair backs and desk sides do not rise so high; a television or a whiteboard on a wall
    rises high but spans well under a metre, and stays an object.
    """
    bottom, top = (float(v) for v in np.percentile(heights, [1.0, 99.0]))
    return top - low >= room_m and top - bottom >= room_m / 2


def _large_pieces(
    points: npt.NDArray[np.float32], model: npt.NDArray[np.float64], min_points: int
) -> npt.NDArray[np.bool_]:
    """Return the inliers in the largest connected piece, or in any piece of >= Min points."""
    piece = connected_pieces(plane_uv(points, model), PIECE_CELL_M)
    sizes = np.bincount(piece)
    big = (sizes >= min_points) | (np.arange(len(sizes)) == sizes.argmax())
    kept: npt.NDArray[np.bool_] = big[piece]
    return kept
