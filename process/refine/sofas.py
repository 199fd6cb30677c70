"""A sofa seats two: what the network calls sofa and has a chair's size and shape is a chair.

Generator 5's network names a chair sofa whole in most views (its seed 5 at 200k: 20,500 chair
points sofa, chairs 0.5-0.65 m across), and no step of the paper's undoes a whole object. But the
two classes differ in size: a sofa seats two or more, 1.5-2.3 m long and 0.8-0.95 m deep in the
simulator and generators 1-4, while a chair fits in a 0.8 m square, armchairs too (generator 4's:
0.75 m), and an armchair is a chair in both networks' classes (`segmentation.ade20k`: armchair,
swivel chair, seat, stool; PASCAL VOC's chair takes armchairs too). A sofa object is a chair when
- its plan fits a rectangle of sides under `CHAIR_MAX_M` (OpenCV's smallest rectangle around
  it, turned as the object stands),
- it rises from a seat to a back (its 1st height percentile over the floor plane at most
  `SEAT_M`, its 99th at least `BACK_M`): a fused map holds a sofa in pieces where the camera saw
  it in part (the suite's recording 9: 0.85 m of a 1.3 m sofa's seat, no back; generator 2's
  room 12: a sofa regrown as two pieces, the network having left most of it unlabelled), and
- no sofa at least `SOFA_MIN_M` long lies within `NEAR_M` of it (a sofa's section the gaps of a
  fused map cut off).
The object: the sofa-labelled points linked within `LINK_M`, so that a seat and its back count
together; linked through the centroids of `CELL_M` voxels, for the pairs of a dense sofa's
points within `LINK_M` are many (generator 4's living room at 500k: 264,000 sofa points, 5.3 s
point to point, 0.27 s by voxels). What else of the sofa label lies within `NEAR_M` of such a
chair, shorter than a sofa and near none, goes with it (a swivel chair's base, 15 cm under its
seat). It runs after the votes: given to the piece vote, the chairs it makes moved a seated
person's label over 9,600 points of another chair (generator 5's office at 500k, -0.019).
Without the seat-and-back test it cost the suite's recording 9 0.18, generator 2's room 12 0.12
and a TSDF room 0.10. Written here because no library labels by such a size; the plan is the
floor plane's.
"""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from capture.recording import Label
from process.refine.cells import voxel_cells
from process.refine.graph import kd_tree, members, radius_components, relabelled
from process.refine.plane_grid import over_floor

CHAIR_MAX_M = 0.8  # a chair fits in a square of this side in plan
SOFA_MIN_M = 1.0  # a sofa is at least this long
BACK_M = 0.75  # a chair rises this high over the floor (its 99th percentile): its back ...
SEAT_M = 0.5  # ... from this high or lower (its 1st percentile): its seat
LINK_M = 0.05  # sofa points this close are one object (their voxels' centroids)
CELL_M = 0.02  # ... in voxels of this side
NEAR_M = 0.3  # a narrow piece this close to a sofa as long as one is its piece


def narrow_sofas(
    points: npt.NDArray[np.floating],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    floor: npt.NDArray[np.float64] | None,
    up: npt.NDArray[np.float64],
) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.int32], npt.NDArray[np.intp]]:
    """Return (labels, clusters, relabelled indices) with sofas narrower than a sofa made chair.

    `floor`: the floor plane (None: no rule); `up`: gravity-up. Clusters keep their ids.
    """
    sofa = over_floor(points, labels, clusters, Label.SOFA, floor, up)
    pts, uv, height = sofa.points, sofa.uv, sofa.height
    if len(pts) == 0:
        return relabelled(labels, clusters, sofa.rows, [], Label.CHAIR)
    cells, cell_of = voxel_cells(pts, CELL_M)  # a dense sofa's pairs within LINK_M are many
    groups = members(radius_components(cells, LINK_M)[cell_of])
    lengths = [_length(uv[g]) for g in groups]
    narrow = [
        g
        for g, long in zip(groups, lengths, strict=True)
        if long < CHAIR_MAX_M and _seat_and_back(height[g])
    ]
    if not narrow:
        return relabelled(labels, clusters, sofa.rows, [], Label.CHAIR)
    long_sofas = [g for g, long in zip(groups, lengths, strict=True) if long >= SOFA_MIN_M]
    tree = kd_tree(pts[np.concatenate(long_sofas)]) if long_sofas else None

    def near(g: npt.NDArray[np.intp], to: cKDTree | None) -> bool:
        return to is not None and bool(
            np.isfinite(to.query(pts[g], distance_upper_bound=NEAR_M)[0]).any()
        )

    chairs = [g for g in narrow if not near(g, tree)]  # not a piece of a sofa
    if not chairs:
        return relabelled(labels, clusters, sofa.rows, [], Label.CHAIR)
    # the rest of each chair: its base or legs, short, by it and by no sofa
    made = kd_tree(pts[np.concatenate(chairs)])
    taken = {id(g) for g in chairs}
    chairs += [
        g
        for g, long in zip(groups, lengths, strict=True)
        if id(g) not in taken and long < SOFA_MIN_M and near(g, made) and not near(g, tree)
    ]
    return relabelled(labels, clusters, sofa.rows, chairs, Label.CHAIR)


def _length(uv: npt.NDArray[np.float32]) -> float:
    """Return the long side of OpenCV's smallest rectangle around plan points."""
    if len(uv) < 3:
        return 0.0
    (_, _), (w, h), _ = cv2.minAreaRect(np.ascontiguousarray(uv, np.float32))
    return float(max(w, h))


def _seat_and_back(height: npt.NDArray[np.float32]) -> bool:
    """Return whether heights over the floor rise from a seat to a back.

    Their 1st percentile at most `SEAT_M`, their 99th at least `BACK_M`.
    """
    low, high = np.percentile(height, [1.0, 99.0])
    return bool(low <= SEAT_M and high >= BACK_M)
