"""ORB features with depth, and what the odometry keeps of a keyframe."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from capture.recording import Intrinsics
from process.geometry import normalise, project, transform_points

THUMB_SIZE = (32, 24)  # (w, h) of the keyframe thumbnails used for place recognition
_LIFT_RADIUS = 2  # keypoint depth from the 5x5 neighbourhood
_DY, _DX = (
    g.ravel() for g in np.mgrid[-_LIFT_RADIUS : _LIFT_RADIUS + 1, -_LIFT_RADIUS : _LIFT_RADIUS + 1]
)


@dataclass(slots=True)
class Keyframe:
    """What the odometry keeps of a keyframe: features with depth, a thumbnail, its links."""

    id: int
    frame_index: int
    stamp_ns: int
    segment: int
    xy: npt.NDArray[np.float32]  # (M, 2) features that have depth
    descriptors: npt.NDArray[np.uint8]  # (M, 32)
    points: npt.NDArray[np.float32]  # (M, 3) keyframe camera frame
    thumbnail: npt.NDArray[np.float32]  # (24 * 32,) zero mean, unit norm
    first_inliers: int = 0  # PnP inliers of the first frame tracked against it
    dense: Any = field(default=None)  # downsampled RGB-D for dense alignment, reference only


class FeatureExtractor:
    """Detect ORB features and lift them to 3-D with the registered depth."""

    def __init__(
        self,
        intrinsics: Intrinsics,
        *,
        n_features: int,
        scale_factor: float,
        levels: int,
        fast_threshold: int,
        min_depth_m: float,
        max_depth_m: float,
    ) -> None:
        self.intrinsics = intrinsics
        self.orb = cv2.ORB.create(
            nfeatures=n_features,
            scaleFactor=scale_factor,
            nlevels=levels,
            fastThreshold=fast_threshold,
        )
        self.min_depth_m = min_depth_m
        self.max_depth_m = max_depth_m
        self.camera_matrix = intrinsics.matrix
        self.dist = np.asarray(intrinsics.coeffs, np.float64) if intrinsics.is_distorted else None

    def detect(
        self, gray: npt.NDArray[np.uint8]
    ) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.uint8]]:
        """Return keypoint positions (N, 2) and ORB descriptors (N, 32)."""
        keypoints, descriptors = self.orb.detectAndCompute(gray, None)
        if descriptors is None or not keypoints:
            return np.zeros((0, 2), np.float32), np.zeros((0, 32), np.uint8)
        xy = np.asarray(cv2.KeyPoint.convert(keypoints), np.float32).reshape(-1, 2)
        return xy, np.asarray(descriptors, np.uint8)

    def lift(
        self,
        xy: npt.NDArray[np.float32],
        depth_m: npt.NDArray[np.float32],
    ) -> npt.NDArray[np.float32]:
        """Return the 3-D point (camera frame) of each pixel, NaN where the depth is unusable.

        A plane is fitted to the 5x5 depths around the keypoint that agree with their median (the
        majority surface), and evaluated at the sub-pixel keypoint: this averages the sensor's
        noise down and is exact on planes. A keypoint whose neighbourhood has no clear majority
        surface (a depth edge, a hole) gets no depth.
        """
        out = np.full((len(xy), 3), np.nan, np.float32)
        if len(xy) == 0:
            return out
        h, w = depth_m.shape
        r = _LIFT_RADIUS
        cx = np.clip(np.rint(xy[:, 0]).astype(np.int64), r, w - 1 - r)
        cy = np.clip(np.rint(xy[:, 1]).astype(np.int64), r, h - 1 - r)
        patch = depth_m[cy[:, None] + _DY[None, :], cx[:, None] + _DX[None, :]]  # (N, 25)
        valid = patch > 0
        median = np.median(np.where(valid, patch, np.nan), axis=1)
        with np.errstate(invalid="ignore"):
            inlier = valid & (np.abs(patch - median[:, None]) <= 0.03 * median[:, None] + 0.01)
        weight = inlier.astype(np.float32)
        count = weight.sum(axis=1)
        ok = (count >= 0.5 * len(_DX)) & (median >= self.min_depth_m) & (median <= self.max_depth_m)
        z = _plane_at(patch[ok], weight[ok], xy[ok, 0] - cx[ok], xy[ok, 1] - cy[ok])
        rays = self.normalised(xy[ok])
        out[ok, :2] = rays * z[:, None]
        out[ok, 2] = z
        return out

    def normalised(self, xy: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
        """Return normalised image coordinates (x/z, y/z) of pixels, undistorted if needed."""
        if self.dist is None:
            return normalise(xy.astype(np.float32, copy=False), self.intrinsics)
        und = cv2.undistortPoints(
            xy.reshape(-1, 1, 2).astype(np.float64), self.camera_matrix, self.dist
        )
        return und.reshape(-1, 2).astype(np.float32)


def _plane_at(
    patch: npt.NDArray[np.float32],
    weight: npt.NDArray[np.float32],
    off_x: npt.NDArray[np.float32],
    off_y: npt.NDArray[np.float32],
) -> npt.NDArray[np.float32]:
    """Return the weighted least-squares plane z = a + b x + c y of each patch at (off_x, off_y)."""
    count = weight.sum(axis=1)
    mx = (weight * _DX).sum(axis=1) / count
    my = (weight * _DY).sum(axis=1) / count
    mz = (weight * patch).sum(axis=1) / count
    dx, dy, dz = _DX - mx[:, None], _DY - my[:, None], patch - mz[:, None]
    # Normal equations of the two slopes (2x2 per patch), solved in closed form.
    sxx, syy, sxy = (weight * dx * dx).sum(1), (weight * dy * dy).sum(1), (weight * dx * dy).sum(1)
    sxz, syz = (weight * dx * dz).sum(1), (weight * dy * dz).sum(1)
    det = sxx * syy - sxy * sxy
    safe = np.where(np.abs(det) > 1e-9, det, 1.0)
    b = np.where(np.abs(det) > 1e-9, (sxz * syy - syz * sxy) / safe, 0.0)
    c = np.where(np.abs(det) > 1e-9, (syz * sxx - sxz * sxy) / safe, 0.0)
    return np.asarray(mz + b * (off_x - mx) + c * (off_y - my), np.float32)


def thumbnail(gray: npt.NDArray[np.uint8]) -> npt.NDArray[np.float32]:
    """Return a small blurred, zero-mean, unit-norm image for appearance-based place recognition."""
    resized = cv2.resize(gray, THUMB_SIZE, interpolation=cv2.INTER_AREA).astype(np.float32)
    small = np.asarray(cv2.GaussianBlur(resized, (3, 3), 0), np.float32).ravel()
    small -= small.mean()
    norm = float(np.linalg.norm(small))
    return small / norm if norm > 1e-6 else small


def visible_share(
    points: npt.NDArray[np.float32], camera_from_points: npt.NDArray[np.float64], intr: Intrinsics
) -> float:
    """Return the share of points (their own frame) that a camera sees inside its image."""
    if len(points) == 0:
        return 0.0
    p = transform_points(camera_from_points, points)
    front = p[:, 2] > 0
    p[:, 2] = np.maximum(p[:, 2], 1e-6)
    u, v = project(p, intr).T
    inside = front & (u >= 0) & (u < intr.width) & (v >= 0) & (v < intr.height)
    return float(inside.mean())
