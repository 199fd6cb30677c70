"""Feature matching: all against all (ratio test), or by projection around a predicted pose."""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from capture.recording import Intrinsics
from process.geometry import project, transform_points

_GUIDED_NEIGHBOURS = 16  # nearest current keypoints compared with each projected reference
_MAX_HAMMING = 64  # of 256 bits: ORB descriptors further apart are not the same point


def guided_match(
    points: npt.NDArray[np.float32],
    descriptors: npt.NDArray[np.uint8],
    xy: npt.NDArray[np.float32],
    query: npt.NDArray[np.uint8],
    *,
    camera_from_points: npt.NDArray[np.float64],
    intrinsics: Intrinsics,
    radius_px: float,
    ratio: float,
    offset_px: npt.NDArray[np.float64] | None = None,
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Match reference features to the current ones found near where a predicted pose puts them.

    Like ORB-SLAM's search by projection: each reference point is projected with the prediction
    and compared only with the current keypoints within radius_px, so a repeated pattern
    elsewhere in the image cannot claim it. offset_px (M, 2), if given, is added to the
    projections (a rolling shutter's displacement). Returns (current index, reference index).
    """
    empty = np.zeros(0, np.int64), np.zeros(0, np.int64)
    if len(points) == 0 or len(xy) < 2:
        return empty
    p = transform_points(camera_from_points, points.astype(np.float32, copy=False))
    front = np.flatnonzero(p[:, 2] > 0.05)
    uv = project(p[front], intrinsics)
    if offset_px is not None:
        uv = (uv + offset_px[front]).astype(np.float32)
    k = min(_GUIDED_NEIGHBOURS, len(xy))
    dist_px, near = cKDTree(xy).query(uv, k=k, distance_upper_bound=radius_px)
    valid = np.isfinite(dist_px)
    near = np.where(valid, near, 0)
    # Hamming distances of each reference descriptor to its candidates: popcount of the XOR.
    ref = descriptors[front].view(np.uint64)  # (M, 4)
    cur = query.view(np.uint64)  # (N, 4)
    hamming = np.bitwise_count(ref[:, None, :] ^ cur[near]).sum(axis=2).astype(np.float32)
    hamming[~valid] = np.inf
    order = np.argsort(hamming, axis=1)
    rows = np.arange(len(front))
    best = hamming[rows, order[:, 0]]
    second = hamming[rows, order[:, 1]] if k > 1 else np.full(len(front), np.inf, np.float32)
    ok = (best <= _MAX_HAMMING) & (best < ratio * second)
    cur_idx = near[rows, order[:, 0]][ok]
    ref_idx = front[ok]
    # One reference feature per current keypoint: the closest descriptor wins.
    by_distance = np.argsort(best[ok], kind="stable")
    _, first = np.unique(cur_idx[by_distance], return_index=True)
    keep = by_distance[first]
    return cur_idx[keep].astype(np.int64), ref_idx[keep].astype(np.int64)


def match(
    query: npt.NDArray[np.uint8], train: npt.NDArray[np.uint8], *, ratio: float
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Return (query index, train index) of matches that pass Lowe's ratio test."""
    if len(query) < 2 or len(train) < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    pairs = cv2.BFMatcher(cv2.NORM_HAMMING).knnMatch(query, train, k=2)
    q, t = [], []
    for pair in pairs:
        if len(pair) == 2 and pair[0].distance < ratio * pair[1].distance:
            q.append(pair[0].queryIdx)
            t.append(pair[0].trainIdx)
    return np.array(q, np.int64), np.array(t, np.int64)
