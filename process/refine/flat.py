"""An object lying flat in the floor's band is floor.

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
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from capture.recording import OBJECT_LABELS, Label

FLAT_M = 0.03  # the floor's band: height over the floor plane
FLAT_SHARE = 0.9  # of a cluster's points within it


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
