"""Gravity-up for the plane step: from the planes found, a hint and the network's own labels.

The hint the pipeline passes is the first camera's "up" (minus its optical y axis). A hand-held
camera is level only roughly: on TUM `fr1_rpy` the first frame looks down at a desk and its up
lies 48 degrees from gravity (the mocap frame's z, checked against groundtruth.txt), closer to
a wall's normal than to the floor's. Snapping the hint to the nearest large plane then takes a
wall for the floor, and the floor becomes "wall".

Where the network labels structure (real-image networks and the simulator checkpoint label
ceiling, floor and wall), those labels say which planes are level: the up chosen is the plane
normal, among those within `_MAX_HINT_DEG` of the hint, under which the most plane inliers carry
a structural label that fits their plane's orientation (floor and ceiling on level planes, wall
on upright ones), minus those that do not. Without such labels (clouds labelled with objects
only), the hint snaps to the largest plane within `_SNAP_UP_DEG`, as before.

Without a hint (`semreplay-process refine` on a map file) the same vote runs over all plane
normals, and the up faces from the floor-labelled points to the ceiling-labelled ones (or to
the rest of the room). Only clouds without structure labels fall back to the objects' position
and the largest plane.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from capture.recording import Label

_SNAP_UP_DEG = 40.0  # a given `up` is replaced by the normal of the largest plane this close to it
_MAX_HINT_DEG = 65.0  # with network evidence: up lies within this of the hint
_MIN_EVIDENCE = 0.05  # ... and at least this share of the planes' inliers carry structure labels
_MIN_OBJECT_POINTS = 100  # without a hint, this many object-labelled points orient a table top
_MIN_LEVEL_POINTS = 100  # ... and this many floor- or ceiling-labelled points a labelled vote
_BOUNDARY_SHARE = 0.05  # a plane with at most this share of the points on a side bounds the room
_AXIS_APART_DEG = 20.0  # plane normals this far apart are different axes of the room
_LOPSIDED_RATIO = 2.0  # another axis is up when the objects are this many times as lopsided
_LOPSIDED_MARGIN = 0.1  # ... and by this share of the room's extent more than on the largest's

Found = list[tuple[npt.NDArray[np.float64], npt.NDArray[np.intp]]]  # (plane model, inliers)


def gravity(
    points: npt.NDArray[np.float32],
    found: Found,
    up: npt.NDArray[np.float64] | None,
    *,
    labels: npt.NDArray[np.uint8] | None,
    level_tolerance_deg: float,
) -> tuple[npt.NDArray[np.float64] | None, str]:
    """Return (gravity-up, how it was found) from the hint `up`, the planes and the labels.

    Sources: "labelled planes" (the network's structure labels chose among plane normals, near
    the hint where there is one), "argument snapped to plane", "argument", "largest plane" (no
    hint), "largest plane, objects below" (no hint, the plane has points on both sides),
    "plane with the objects at one end" (no hint, the largest plane is a wall:
    `_lopsided_axis`) or "none".
    """
    if up is not None:
        up = np.asarray(up, np.float64) / np.linalg.norm(up)
        if labels is not None:
            voted = _labelled_up(found, up, labels, level_tolerance_deg)
            if voted is not None:
                return voted, "labelled planes"
        # a hand-held first pose is level only to 10-20 degrees; the floor is level exactly
        snap = math.cos(math.radians(_SNAP_UP_DEG))
        level = [(len(i), m) for m, i in found if abs(m[:3] @ up) >= snap]
        if not level:
            return up, "argument"
        normal = max(level, key=lambda t: t[0])[1][:3]
        return normal * np.sign(normal @ up), "argument snapped to plane"
    if not found:
        return None, "none"
    if labels is not None:
        # a map fused from a hand-held camera holds a floor the network labels floor: that
        # outvotes where the objects lie (generator recordings whose wall the objects line,
        # with the floor the largest plane, turned the room on its side)
        voted = _labelled_up(found, None, labels, level_tolerance_deg, points=points)
        if voted is not None:
            return voted, "labelled planes"
        lopsided = _lopsided_axis(points, found, labels)
        if lopsided is not None:
            return lopsided, "plane with the objects at one end"
    # no gravity given: the largest plane is taken as the floor, facing the bulk of the points
    model = max(found, key=lambda t: len(t[1]))[0]
    heights = points @ model[:3].astype(np.float32) + np.float32(model[3])
    objects = heights[labels >= Label.TABLE] if labels is not None else heights[:0]
    if _inside_the_room(heights) and len(objects) >= _MIN_OBJECT_POINTS:
        # not a floor but a large table top (generator 4's object-heavy kitchen, in a random
        # frame): furniture and people fill the lower part of the room, so up faces away from
        # the end nearer the objects' median
        side = _lopsidedness(heights, objects)
        return model[:3] * (1.0 if side >= 0 else -1.0), "largest plane, objects below"
    side = np.median(heights)
    return model[:3] * (1.0 if side >= 0 else -1.0), "largest plane"


def _lopsided_axis(
    points: npt.NDArray[np.float32], found: Found, labels: npt.NDArray[np.uint8]
) -> npt.NDArray[np.float64] | None:
    """Return up along another plane's normal when the largest plane is a wall, else None.

    Furniture and people stand on the floor: along gravity the labelled objects lie at one end
    of the room, along a wall's normal they line both walls (`_lopsidedness`). When another
    axis is `_LOPSIDED_RATIO` times as lopsided as the largest plane's, and by
    `_LOPSIDED_MARGIN` more, the largest plane is a wall (generator 4's living rooms in a
    random frame: sofas and shelves against a long wall), and up leaves the objects.
    """
    objects = labels >= Label.TABLE
    if int(objects.sum()) < _MIN_OBJECT_POINTS:
        return None
    apart = math.cos(math.radians(_AXIS_APART_DEG))
    axes: list[npt.NDArray[np.float64]] = []
    for model, _ in sorted(found, key=lambda t: -len(t[1])):
        normal = np.asarray(model[:3], np.float64) / np.linalg.norm(model[:3])
        if all(abs(float(normal @ axis)) < apart for axis in axes):
            axes.append(normal)
    if len(axes) < 2:
        return None
    sides = []
    for axis in axes:
        heights = points @ axis.astype(np.float32)
        sides.append(_lopsidedness(heights, heights[objects]))
    size = np.abs(sides)
    best = int(np.argmax(size))
    if best == 0 or size[best] < max(_LOPSIDED_RATIO * size[0], size[0] + _LOPSIDED_MARGIN):
        return None
    up: npt.NDArray[np.float64] = axes[best] * (1.0 if sides[best] > 0 else -1.0)
    return up


def _lopsidedness(heights: npt.NDArray[np.float32], objects: npt.NDArray[np.float32]) -> float:
    """Return how far the objects' median lies below the middle of the heights' extent.

    The extent: 1st-99th percentile of all heights; the result a share of it (< 0: above).
    """
    low, high = (float(v) for v in np.percentile(heights, [1.0, 99.0]))
    return ((low + high) / 2 - float(np.median(objects))) / max(high - low, 1e-9)


def _inside_the_room(heights: npt.NDArray[np.float32]) -> bool:
    """Return whether a plane has more than `_BOUNDARY_SHARE` of the points on either side."""
    above, below = float(np.mean(heights > 0.05)), float(np.mean(heights < -0.05))
    return min(above, below) > _BOUNDARY_SHARE


def _labelled_up(
    found: Found,
    hint: npt.NDArray[np.float64] | None,
    labels: npt.NDArray[np.uint8],
    tolerance_deg: float,
    *,
    points: npt.NDArray[np.float32] | None = None,
) -> npt.NDArray[np.float64] | None:
    """Return the plane normal near `hint` that the network's structure labels agree with most.

    Without a hint every normal competes and `points` orient the winner (`_facing`). None when
    the planes carry too few structure labels to say, no normal is near the hint, or (without
    one) no floor or ceiling label says which way is up.
    """
    if not found:
        return None
    normals = np.array([m[:3] for m, _ in found])
    # per plane: inliers the network calls level structure (floor, ceiling) and upright (wall)
    level_votes = np.array(
        [np.isin(labels[i], (Label.FLOOR, Label.CEILING)).sum() for _, i in found]
    )
    wall_votes = np.array([(labels[i] == Label.WALL).sum() for _, i in found])
    total = sum(len(i) for _, i in found)
    if level_votes.sum() + wall_votes.sum() < _MIN_EVIDENCE * total:
        return None
    cos_near = math.cos(math.radians(_MAX_HINT_DEG))
    level_cos = math.cos(math.radians(tolerance_deg))
    upright_cos = math.sin(math.radians(tolerance_deg))
    best: tuple[float, npt.NDArray[np.float64]] | None = None
    for normal in normals:
        if hint is not None and abs(normal @ hint) < cos_near:
            continue
        cosine = np.abs(normals @ normal)
        level, upright = cosine >= level_cos, cosine <= upright_cos
        score = float(
            (level_votes * level).sum()
            + (wall_votes * upright).sum()
            - (wall_votes * level).sum()
            - (level_votes * upright).sum()
        )
        if score > 0 and (best is None or score > best[0]):
            best = (score, normal if hint is None else normal * np.sign(normal @ hint))
    if best is None:
        return None
    if hint is not None:
        return best[1]
    assert points is not None, "without a hint the points say which way is up"
    return _facing(points, best[1], labels)


def _facing(
    points: npt.NDArray[np.float32], normal: npt.NDArray[np.float64], labels: npt.NDArray[np.uint8]
) -> npt.NDArray[np.float64] | None:
    """Return `normal` turned from the floor-labelled points to the ceiling-labelled ones.

    Median heights; with one of the two labels only, to or from the whole cloud's median. None
    when fewer than `_MIN_LEVEL_POINTS` carry either label.
    """
    heights = points @ normal.astype(np.float32)
    floor, ceiling = labels == Label.FLOOR, labels == Label.CEILING
    enough = [int(m.sum()) >= _MIN_LEVEL_POINTS for m in (floor, ceiling)]
    if not any(enough):
        return None
    low = float(np.median(heights[floor] if enough[0] else heights))
    high = float(np.median(heights[ceiling] if enough[1] else heights))
    if high == low:
        return None
    return normal * (1.0 if high > low else -1.0)
