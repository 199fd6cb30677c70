"""An object lying flat in the floor's band is floor; one lying flat on a wall, apart, is wall.

The plane step leaves a wide region of the floor plane the network labels an object to the
objects (`plane_grid.wide_object_regions`): the feet and lower edges of a sofa, a chair or a
plant stand in the floor's band, and regrowth joins them to the body above. A network also calls
a stretch of bare floor an object whole: on fused maps of simulated recordings a 0.45 x 0.5 m
patch table, a 0.6 m one sofa, two clutter (fresh recordings 61, 74, 81, 82: 100-630 points a
cluster). DBSCAN keeps each as an object of its own, and nothing rises from it. No object of the
target classes is that flat: an object cluster with at least `FLAT_SHARE` of its points within
`FLAT_M` over the floor plane is floor; its few points higher are left unlabelled. Of the suite's
58 clouds and 32 fresh recordings, every cluster so flat was floor in the ground truth (and one
floor-and-wall strip of generator 2's room 10, 152 points); the flattest real object, a table of
generator 3 seen tilted, had 66 % of its points in the band. Written here because no library
labels by height over a plane; the floor plane is the plane step's.

A wall the network calls an object: the chair label bleeds onto the wall behind a chair (fresh
recording 88: 221 wall points called chair, 0.24-0.44 m up, 5 cm and more from the chair), and
DBSCAN keeps the patch as a chair of its own lying in the wall's face: 2.3 cm behind RANSAC's
plane on the median, for a wall fused from depth is a few centimetres thick. A thing flat on a
wall hangs there (a television, a picture: their class is no standing class), stands proud of it
(a screen's edge 2-5 cm before TUM fr1_rpy's wall, called chair) or is the face of what stands
against it (a sofa's front, the low frame of a chair pushed to a wall: generator 1's office,
generator 2's rooms 38 and 39, 164-604 points, truth sofa and chair), standing on the floor or
touching the rest of its object. So a cluster of a standing class (table, chair, person, plant,
sofa) with `FLAT_SHARE` of its points in a wall's band (`walls.wall_band` in front, `BEHIND_M`
behind), its median at most `PROUD_M` in front, its lowest point `FLOAT_M` or more over the
floor and no point of another object within `APART_M`, is wall (its points out of the band:
unlabelled).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from capture.recording import OBJECT_LABELS, Label
from process.refine.graph import kd_tree
from process.refine.regrowth import STANDING

FLAT_M = 0.03  # the floor's band: height over the floor plane
FLAT_SHARE = 0.9  # of a cluster's points within it
BEHIND_M = 0.05  # a wall's band behind its plane (a door's recess lies 5-15 cm behind)
FLOAT_M = 0.1  # a patch on a wall whose lowest point is this far over the floor stands on nothing
APART_M = 0.05  # ... and touches no other object within this
PROUD_M = 0.01  # ... and lies in the wall's face: its median at most this far in front


def flat_on_floor(
    points: npt.NDArray[np.floating],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    floor: npt.NDArray[np.float64] | None,
    up: npt.NDArray[np.float64],
) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.int32], npt.NDArray[np.intp]]:
    """Return (labels, clusters, relabelled indices) with objects flat on the floor made floor.

    `floor`: the floor plane (a, b, c, d; None: no rule); `up`: gravity-up.
    """
    out_labels, out_clusters = labels.copy(), clusters.copy()
    none = np.zeros(0, np.intp)
    objects = np.flatnonzero(np.isin(labels, OBJECT_LABELS) & (clusters > 0))
    if floor is None or len(objects) == 0:
        return out_labels, out_clusters, none
    floor = floor if float(floor[:3] @ up) >= 0 else -floor
    pts = np.asarray(points[objects], np.float64)
    low = pts @ floor[:3] + floor[3] <= FLAT_M
    size = np.bincount(clusters[objects])
    flat = np.bincount(clusters[objects[low]], minlength=len(size)) >= FLAT_SHARE * size
    rows = objects[flat[clusters[objects]]]
    if len(rows) == 0:
        return out_labels, out_clusters, none
    in_band = np.zeros(len(labels), bool)
    in_band[objects[low]] = True
    out_labels[rows] = np.where(in_band[rows], Label.FLOOR, Label.UNLABELLED)
    out_clusters[rows] = 0
    return out_labels, out_clusters, rows


def flat_on_walls(
    points: npt.NDArray[np.floating],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    walls: list[tuple[npt.NDArray[np.float64], float]],
    floor: npt.NDArray[np.float64] | None,
    up: npt.NDArray[np.float64],
) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.int32], npt.NDArray[np.intp]]:
    """Return (labels, clusters, relabelled indices) with standing objects flat on a wall made wall.

    `walls`: each wall's plane (a, b, c, d; positive towards the room) and its band in front of
    it (`walls.wall_band`); `floor`: the floor plane (None: no rule); `up`: gravity-up.
    """
    out_labels, out_clusters = labels.copy(), clusters.copy()
    none = np.zeros(0, np.intp)
    objects = np.flatnonzero(np.isin(labels, OBJECT_LABELS) & (clusters > 0))
    standing = objects[np.isin(labels[objects], STANDING)]
    if floor is None or not walls or len(standing) == 0:
        return out_labels, out_clusters, none
    floor = floor if float(floor[:3] @ up) >= 0 else -floor
    pts = np.asarray(points[standing], np.float64)
    ids = clusters[standing]
    size = np.bincount(ids)
    low = np.full(len(size), np.inf)
    np.minimum.at(low, ids, pts @ floor[:3] + floor[3])
    in_band = np.zeros(len(standing), bool)
    flat = np.zeros(len(size), bool)
    for model, band in walls:
        offset = pts @ model[:3] + model[3]
        inside = (offset >= -BEHIND_M) & (offset <= band)
        on = np.bincount(ids[inside], minlength=len(size)) >= FLAT_SHARE * size
        on &= (size > 0) & (low >= FLOAT_M)
        for c in np.flatnonzero(on):  # ... in the wall's face, not standing proud of it
            on[c] = float(np.median(offset[ids == c])) <= PROUD_M
        flat |= on
        in_band |= inside & on[ids]
    if not flat.any():
        return out_labels, out_clusters, none
    xyz = np.asarray(points[objects], np.float64)
    for c in np.flatnonzero(flat):  # a patch touching another object is that object's face
        own = pts[ids == c]
        near = np.all((xyz >= own.min(0) - APART_M) & (xyz <= own.max(0) + APART_M), axis=1)
        hits = kd_tree(xyz[near]).query_ball_point(own, APART_M, return_sorted=False)
        touched = clusters[objects[near][np.unique(np.concatenate(hits).astype(np.intp))]]
        flat[c] = bool((touched == c).all())
    chosen = flat[ids]
    rows = standing[chosen]
    if len(rows) == 0:
        return out_labels, out_clusters, none
    out_labels[rows] = np.where(in_band[chosen], Label.WALL, Label.UNLABELLED)
    out_clusters[rows] = 0
    return out_labels, out_clusters, rows
