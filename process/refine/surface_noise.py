"""The network's floor, wall and ceiling just off a structural plane: its label stands.

A map fused from a moving depth camera has thick surfaces: the floor of a simulated recording
spreads 2-4 cm about its plane (voxel layers, pose drift), past RANSAC's band
(`plane_distance_m`), and statistical outlier removal takes much of that tail for noise. The
network named those points right, but phase III left them unlabelled: no object took them,
and no plane held them. On 12 simulated recordings, 10,992 points ended unlabelled that
the network called floor, wall or ceiling; of those within 3 cm of a plane of that class 91 %
are that class (floor within 4 cm 94 %), of those 5-10 cm off 9 %: there the truth has no
surface at all (a wall's fused artefacts more than 5 cm off the real wall).

So a point that ends unlabelled, which the network calls floor, wall or ceiling, within
`structure_noise_m` of a structural plane of that class and over its extent, takes that
label. Nothing else changes: an object's point is never made structure, and what the network
calls floor well above the floor (`floor_label_max_m`, walls.py) is not near the floor plane.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from process.refine.planes import Plane
from process.refine.walls import near_plane


def network_surfaces(
    points: npt.NDArray[np.float32],
    labels: npt.NDArray[np.uint8],
    network: npt.NDArray[np.uint8],
    planes: tuple[Plane, ...],
    band_m: float,
) -> npt.NDArray[np.intp]:
    """Return the points left unlabelled (`labels` 0) that the network's structure label fits.

    Each lies within `band_m` of a structural plane whose class the network (`network`) gives
    it, and over that plane's extent (`walls.near_plane`, as a noisy wall takes in its noise).
    """
    if band_m <= 0:
        return np.zeros(0, np.intp)
    found = []
    free = labels == 0
    for plane in planes:
        if plane.label == 0 or not len(plane.removed):
            continue
        candidates = np.flatnonzero(free & (network == plane.label))
        if not len(candidates):
            continue
        taken = near_plane(points, plane, candidates, band_m)
        free[taken] = False
        found.append(taken)
    return np.sort(np.concatenate(found)) if found else np.zeros(0, np.intp)
