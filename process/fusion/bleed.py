"""Object labels that bled off their object: pixels whose depth is an outlier of their blob's.

A segmentation network's labels are coarse (DeepLab's come from a 1/4-resolution grid and are
blobby at object borders), so an object's label spills onto the background around its
silhouette. In a rotating camera the same strip of wall stays next to the same object and the
spill is fused into a ghost of the object on the wall (on TUM fr1_rpy a 0.7 x 0.8 m "person"
1.3 m behind the seated person). An object is compact in depth: within each connected blob of an
object label, a pixel whose depth is further from the blob's median depth than `mad_factor`
robust standard deviations (1.4826 x the median absolute deviation), and at least `min_margin_m`,
is taken for spill (robust while spill is under half the blob); fusion lets it add geometry but
no label vote. A receding table top has a wide spread and keeps its far end.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy import ndimage

from capture.recording import OBJECT_LABELS


def spilled_labels(
    labels: npt.NDArray[np.uint8],
    depth_m: npt.NDArray[np.float32],
    *,
    mad_factor: float,
    min_margin_m: float,
) -> npt.NDArray[np.bool_]:
    """Return where an object label's depth is an outlier of its connected blob's (H, W).

    Pixels without depth (0) are never outliers and do not count.
    """
    out = np.zeros(labels.shape, bool)
    has_depth = depth_m > 0
    for label in np.intersect1d(np.unique(labels), np.asarray(OBJECT_LABELS)):
        blobs, n = ndimage.label(labels == label)
        sel = (blobs > 0) & has_depth
        if n == 0 or not sel.any():
            continue
        ids, depth = blobs[sel], depth_m[sel].astype(np.float64)
        median = _group_median(ids, depth, n)
        deviation = np.abs(depth - median[ids])
        spread = 1.4826 * _group_median(ids, deviation, n)  # the MAD as a standard deviation
        out[sel] = deviation > np.maximum(mad_factor * spread, min_margin_m)[ids]
    return out


def _group_median(
    ids: npt.NDArray[np.int32], values: npt.NDArray[np.float64], n: int
) -> npt.NDArray[np.float64]:
    """Return the (lower) median of the values of each group 1..n, indexed by group (0 unused)."""
    order = np.lexsort((values, ids))
    counts = np.bincount(ids, minlength=n + 1)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    median = np.zeros(n + 1)
    has = counts > 0
    median[has] = values[order][starts[has] + (counts[has] - 1) // 2]
    return median
