"""Clusters grouped into objects, for regrowth's boxes and r2 (regrowth.py).

DBSCAN splits an object where the network missed or mislabelled a band across it: a table with
a missed patch across its top, a sofa whose seat the network called chair or floor, leaving its
back and its front 0.27 m apart (a fused map of a simulated recording). Two rules join the
pieces:
- same-class clusters whose boxes come within `gap_m` of each other are one object;
- same-class clusters up to `bridge_m` apart are one object when a patch of another class (a
  cluster no table, whose box has at most `patch_max_m` diagonal) touches both: the patch lies
  across the object, and regrowth then finds it nested in it (nested objects yield, adoption).
  A larger object between two, such as a table between two chairs, joins nothing, and
  clutter, which is many small things, is not bridged.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from capture.recording import Label
from process.refine.graph import components

Boxes = npt.NDArray[np.float64]  # (C, 3) per cluster, lower or upper corner


def group_objects(
    label: npt.NDArray[np.uint8],
    low: Boxes,
    high: Boxes,
    *,
    gap_m: float,
    r1: npt.NDArray[np.float64] | None = None,
    bridge_m: float = 0.0,
    patch_max_m: float = 0.0,
) -> npt.NDArray[np.int64]:
    """Return an object id (0..) per cluster.

    Args:
        label: (C,) class of each cluster.
        low: (C, 3) each cluster's own box, its lower corner ...
        high: (C, 3) ... and its upper corner.
        gap_m: same-class clusters whose boxes come this close are one object (chained).
        r1: (C,) each cluster's r1; a patch touches a cluster inside its box grown by r1.
        bridge_m: same-class clusters this close are one object when a patch of another
            class touches both; 0 or no r1: off.
        patch_max_m: the largest box diagonal of a bridging patch.
    """
    pairs = _near(label, low, high, gap_m)
    if bridge_m > gap_m and r1 is not None:
        pairs = np.concatenate([pairs, _bridged(label, low, high, r1, bridge_m, patch_max_m)])
    return components(len(label), pairs[:, 0], pairs[:, 1])[1].astype(np.int64)


def _near(
    label: npt.NDArray[np.uint8], low: Boxes, high: Boxes, gap_m: float
) -> npt.NDArray[np.intp]:
    """Return (P, 2) pairs of same-class clusters whose boxes come within `gap_m`."""
    lo, hi = low - gap_m / 2, high + gap_m / 2
    touch = np.all((lo[:, None] <= hi[None]) & (lo[None] <= hi[:, None]), axis=2)
    touch &= label[:, None] == label[None]
    return np.argwhere(touch)


def _bridged(
    label: npt.NDArray[np.uint8],
    low: Boxes,
    high: Boxes,
    r1: npt.NDArray[np.float64],
    bridge_m: float,
    patch_max_m: float,
) -> npt.NDArray[np.intp]:
    """Return (P, 2) pairs of same-class clusters within `bridge_m` that one patch touches."""
    near = _near(label, low, high, bridge_m)
    # clutter is many small things: two clutter clusters with a patch between are not one object
    # (TUM fr1_rpy: a monitor between two clutter clusters on a desk became clutter)
    near = near[(near[:, 0] < near[:, 1]) & (label[near[:, 0]] != Label.CLUTTER)]
    grown_low, grown_high = low - r1[:, None], high + r1[:, None]
    # touches[a, c]: cluster c's own box meets cluster a's box grown by r1
    touches = np.all(
        (grown_low[:, None] <= high[None]) & (low[None] <= grown_high[:, None]), axis=2
    )
    patch = label != Label.TABLE  # a table carries and shelters objects; it is no patch
    if patch_max_m > 0:
        patch &= np.linalg.norm(high - low, axis=1) <= patch_max_m
    a, b = near[:, 0], near[:, 1]
    bridge = touches[a] & touches[b] & patch[None] & (label[None] != label[a][:, None])
    pairs: npt.NDArray[np.intp] = near[bridge.any(axis=1)]
    return pairs
