"""Structure labels off the structural planes that lie inside objects: the objects' to regrow.

The network labels a whole segment wrong now and then, and on a fused map of a recording such
a segment can be structure: a chair's back called wall, a table's leg called floor. DBSCAN
keeps it as a wall or floor cluster when it is large enough, and regrowth keeps out of every
point the network calls structure, so it stays wall, off every wall plane, in the middle of the
room (eight fresh simulated recordings: 1,535 object points, 1.2 % of them, kept as structure
this way). A real wall's or floor's piece that RANSAC's planes left out lies beside more
structure, or alone; one whose neighbourhood is mostly object points (at least
`inside_objects_share` of the labelled points within `inside_objects_link` point spacings
around it, on the same eight recordings: 0.88-1.00 for the object segments, at most 0.42 for
the 35 structure pieces) is taken for part of them: its points become unlabelled and open to
regrowth, which gives them to the object they lie in or leaves them unlabelled.

Smaller segments DBSCAN drops as noise are unlabelled after phase II, yet regrowth still keeps
out of them, as the network called them structure: a chair back's edge called wall, a few
centimetres of a table's edge. They are grouped into segments the same way (pairs within
`inside_objects_link` spacings) and opened by the same test (eight fresh recordings: 423
points changed, 354 to their true class, 11 of them right before; +0.0001 to +0.0033 F1 on
each, and on each of the suite's five recordings +0 to +0.0021).

Ceiling clusters stay: the ceiling lies above every object, and a piece of it beside object
points is the ceiling over a tall one (a suite recording: a 0.7 x 0.4 m patch of ceiling with
no ceiling plane found, 163 points whose few labelled neighbours were a television's, became
television). No recording here has an object the network calls ceiling.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from capture.recording import OBJECT_LABELS, STRUCTURAL_LABELS, Label
from process.refine.graph import kd_tree, point_spacing, radius_components

_PROBE = 300  # points of a cluster whose neighbourhoods are looked at (an even sample)
_OPENED = (Label.FLOOR, Label.WALL)  # structure labels a segment inside objects may carry


def structure_inside_objects(
    points: npt.NDArray[np.float32],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    *,
    share: float,
    link: float,
    network: npt.NDArray[np.uint8] | None = None,
) -> npt.NDArray[np.intp]:
    """Return the points of floor and wall segments (off the planes) amid object points.

    `labels` and `clusters` cover the whole cloud after DBSCAN: plane points carry their
    structure label and cluster 0, the off-plane structure clusters their label and an id.
    `network`, if given, is the network's label per point: the points it calls floor or wall
    that are unlabelled after DBSCAN (dropped as noise, or by SOR) form segments too, the
    components of the pairs within the radius below. A segment's neighbourhood: labelled
    points of other segments or planes within `link` times the object points' spacing of an
    even sample of its points.
    """
    structure = np.flatnonzero(np.isin(labels, _OPENED) & (clusters > 0))
    objects = np.isin(labels, OBJECT_LABELS)
    dropped = np.zeros(0, np.intp)
    if network is not None:
        dropped = np.flatnonzero(np.isin(network, _OPENED) & (labels == 0))
    if len(structure) + len(dropped) == 0 or not objects.any():
        return np.zeros(0, np.intp)
    radius = link * point_spacing(points[objects])
    tree = kd_tree(points)
    ids = clusters.copy()
    if len(dropped):
        ids[dropped] = int(clusters.max()) + 1 + radius_components(points[dropped], radius)
        structure = np.concatenate([structure, dropped])
    structure = structure[np.argsort(ids[structure], kind="stable")]  # grouped by segment
    starts = np.flatnonzero(np.r_[True, np.diff(ids[structure]) != 0])
    opened: list[npt.NDArray[np.intp]] = []
    for members in np.split(structure, starts[1:]):
        probe = points[members[:: max(1, len(members) // _PROBE)]]
        near = np.unique(np.concatenate(tree.query_ball_point(probe, radius)).astype(np.intp))
        near = near[ids[near] != ids[members[0]]]  # ids unique over classes; planes 0
        n_objects = int(objects[near].sum())
        n_structure = int(np.isin(labels[near], STRUCTURAL_LABELS).sum())
        if n_objects and n_objects >= share * (n_objects + n_structure):
            opened.append(members)
    return np.sort(np.concatenate(opened)) if opened else np.zeros(0, np.intp)
