"""A plane's points on a 2-D grid: its connected pieces, and the objects the network sees on it."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy import ndimage

from capture.recording import Label

PIECE_CELL_M = 0.1  # grid of the connected pieces of a plane: gaps over ~10 cm separate
DENSITY_RADIUS_M = 0.05  # disc over which a surface density is counted (planes, surfaces)


def plane_uv(
    points: npt.NDArray[np.float32], model: npt.NDArray[np.float64]
) -> npt.NDArray[np.float32]:
    """Return (N, 2) coordinates of the points in two unit axes of the plane."""
    normal = model[:3]
    u = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    uv: npt.NDArray[np.float32] = points @ np.stack([u, np.cross(normal, u)], axis=1).astype(
        np.float32
    )
    return uv


def heights_over(
    points: npt.NDArray[np.floating], floor: npt.NDArray[np.float64], up: npt.NDArray[np.float64]
) -> npt.NDArray[np.float32]:
    """Return each point's height over a plane (a, b, c, d), its normal turned to face `up`."""
    normal = floor if float(floor[:3] @ up) >= 0 else -floor
    heights: npt.NDArray[np.float32] = np.asarray(points, np.float32) @ normal[:3].astype(
        np.float32
    ) + np.float32(normal[3])
    return heights


@dataclass(frozen=True)
class OverFloor:
    """One class's clustered points, measured over the floor plane (`over_floor`)."""

    rows: npt.NDArray[np.intp]  # their indices in the cloud
    points: npt.NDArray[np.float32]  # (n, 3) their positions
    height: npt.NDArray[np.float32]  # (n,) over the floor plane
    uv: npt.NDArray[np.float32]  # (n, 2) in plan: along the floor plane's axes


def over_floor(
    points: npt.NDArray[np.floating],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    label: int,
    floor: npt.NDArray[np.float64] | None,
    up: npt.NDArray[np.float64],
) -> OverFloor:
    """Return the clustered points of `label` with their heights and plan coordinates.

    Heights are over the floor plane (a, b, c, d); none are returned without one (`floor` None).
    """
    rows = np.flatnonzero((labels == label) & (clusters > 0))
    if floor is None:
        rows = rows[:0]
    pts = np.asarray(points[rows], np.float32)
    if floor is None:
        return OverFloor(rows, pts, np.zeros(0, np.float32), np.zeros((0, 2), np.float32))
    return OverFloor(rows, pts, heights_over(pts, floor, up), plane_uv(pts, floor))


def grid_of(uv: npt.NDArray[np.float32], cell_m: float) -> npt.NDArray[np.int64]:
    """Return each point's (i, j) cell of side `cell_m`, counted from the lowest corner."""
    if len(uv) == 0:
        return np.zeros((0, 2), np.int64)
    ij: npt.NDArray[np.int64] = ((uv - uv.min(axis=0)) / cell_m).astype(np.int64)
    return ij


def over_footprint(
    uv_own: npt.NDArray[np.float32],
    uv: npt.NDArray[np.float32],
    cell_m: float,
    *,
    diagonal: bool = False,
    grow: int = 1,
) -> npt.NDArray[np.bool_]:
    """Return which points (u, v) lie in a cell of `uv_own`'s points or near one.

    Near: within `grow` steps of cells sharing a side, or with `diagonal` a corner too.
    """
    if len(uv) == 0 or len(uv_own) == 0:
        return np.zeros(len(uv), bool)
    origin = uv_own.min(axis=0) - grow * cell_m  # a margin of `grow` cells for the neighbours
    own = ((uv_own - origin) / cell_m).astype(np.int64)
    shape = tuple(int(v) + 1 + grow for v in own.max(axis=0))
    grid = np.zeros(shape, bool)
    grid[own[:, 0], own[:, 1]] = True
    if grow > 0:  # SciPy reads 0 iterations as "until nothing changes"
        structure = np.ones((3, 3), bool) if diagonal else None
        grid = ndimage.binary_dilation(grid, structure, iterations=grow)
    ij = np.floor((uv - origin) / cell_m).astype(np.int64)
    inside: npt.NDArray[np.bool_] = np.all((ij >= 0) & (ij < np.array(shape)), axis=1)
    inside[inside] = grid[ij[inside, 0], ij[inside, 1]]
    return inside


def connected_pieces(uv: npt.NDArray[np.float32], cell_m: float) -> npt.NDArray[np.int64]:
    """Return each point's connected piece (0..) on a grid of `cell_m` cells (8-connected).

    The grid grows past `cell_m` where the points span over 2,000 cells: RANSAC's infinite
    plane takes stray inliers metres away.
    """
    if len(uv) == 0:
        return np.zeros(0, np.int64)
    extent = float((uv.max(axis=0) - uv.min(axis=0)).max())
    ij = grid_of(uv, max(cell_m, extent / 2000))
    grid = np.zeros(tuple(ij.max(axis=0) + 1), bool)
    grid[ij[:, 0], ij[:, 1]] = True
    labelled, _ = ndimage.label(grid, structure=np.ones((3, 3), bool))
    piece: npt.NDArray[np.int64] = labelled[ij[:, 0], ij[:, 1]].astype(np.int64) - 1
    return piece


def wide_object_regions(
    uv: npt.NDArray[np.float32],
    labels: npt.NDArray[np.uint8],
    *,
    width_m: float,
    min_share: float = 0.0,
) -> npt.NDArray[np.bool_]:
    """Return the points in object-labelled regions of the plane at least `width_m` wide.

    A cell is object-labelled where most of its labelled points carry an object label and
    they are over `min_share` of all its points, and the region's unlabelled points go with it:
    regrowth may fill them.

    A plane's points that the network calls an object (4-10) are either label bleed, a band a
    few centimetres wide along the object's edge where it meets the floor or wall, or an
    object lying flat on it (a television on a wall, a rug, a whiteboard). A morphological
    opening of the cells where object labels are the majority, by a square of `width_m`,
    removes the bands and keeps the wide regions: those stay objects.
    """
    out = np.zeros(len(uv), bool)
    is_object = labels >= Label.TABLE
    if not is_object.any() or width_m <= 0:
        return out
    cell = width_m / 3
    ij = grid_of(uv, cell)
    shape = tuple(ij.max(axis=0) + 1)
    flat = np.ravel_multi_index((ij[:, 0], ij[:, 1]), shape)
    votes = np.bincount(flat, is_object, minlength=int(np.prod(shape)))
    size = int(np.prod(shape))
    labelled = np.bincount(flat, labels > 0, minlength=size)
    total = np.bincount(flat, minlength=size)
    # the share of all points is taken over the opening's square: a sofa back seen with holes
    # has cells of few labels among well-labelled ones, bleed on a bare wall has none
    near_votes = ndimage.uniform_filter(votes.reshape(shape), 3, mode="constant")
    near_total = ndimage.uniform_filter(total.reshape(shape).astype(float), 3, mode="constant")
    mask = (2 * votes > labelled).reshape(shape) & (near_votes > min_share * near_total)
    square = np.ones((3, 3), bool)
    mask = ndimage.binary_opening(mask, square)
    out[:] = mask.ravel()[flat] & ((labels == 0) | is_object)
    return out
