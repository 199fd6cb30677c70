"""The sparse half of the visual odometry: ORB features with depth, matching, PnP RANSAC."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from capture.recording import Intrinsics

THUMB_SIZE = (32, 24)  # (w, h) of the keyframe thumbnails used for place recognition
_LIFT_RADIUS = 2  # keypoint depth from the 5x5 neighbourhood
_PRIOR_GATE = 4.0  # matches within this many RANSAC thresholds of the prior seed its hypothesis
_PRIOR_SHARE = 0.8  # the prior's hypothesis wins with at least this share of RANSAC's inliers
_GUIDED_NEIGHBOURS = 32  # nearest current keypoints compared with each projected reference
_MAX_HAMMING = 64  # of 256 bits: ORB descriptors further apart are not the same point
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


@dataclass(frozen=True, slots=True)
class PnpResult:
    """A pose from 3-D/2-D matches: the reference's points seen by the current camera."""

    camera_from_reference: npt.NDArray[np.float64]  # (4, 4)
    inliers: npt.NDArray[np.int64]  # indices into the matches given
    rms_px: float

    @property
    def reference_from_camera(self) -> npt.NDArray[np.float64]:
        """Return the inverse pose: the current camera in the reference frame."""
        return rigid_inverse(self.camera_from_reference)


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
        xy = np.array([k.pt for k in keypoints], np.float32).reshape(-1, 2)
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
            k = self.intrinsics
            return np.stack([(xy[:, 0] - k.cx) / k.fx, (xy[:, 1] - k.cy) / k.fy], axis=1).astype(
                np.float32
            )
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
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Match reference features to the current ones found near where a predicted pose puts them.

    Like ORB-SLAM's search by projection: each reference point is projected with the prediction
    and compared only with the current keypoints within radius_px, so a repeated pattern
    elsewhere in the image cannot claim it. Returns (current index, reference index).
    """
    empty = np.zeros(0, np.int64), np.zeros(0, np.int64)
    if len(points) == 0 or len(xy) < 2:
        return empty
    p = points @ camera_from_points[:3, :3].T.astype(np.float32) + camera_from_points[:3, 3].astype(
        np.float32
    )
    front = np.flatnonzero(p[:, 2] > 0.05)
    uv = np.stack(
        [
            p[front, 0] / p[front, 2] * intrinsics.fx + intrinsics.cx,
            p[front, 1] / p[front, 2] * intrinsics.fy + intrinsics.cy,
        ],
        axis=1,
    )
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


@dataclass(frozen=True, slots=True)
class PnpSolver:
    """PnP RANSAC on 3-D/2-D matches, then Levenberg-Marquardt on the inliers."""

    camera_matrix: npt.NDArray[np.float64]
    dist: npt.NDArray[np.float64] | None
    reprojection_px: float
    iterations: int
    confidence: float

    def solve(
        self,
        points: npt.NDArray[np.float32],
        xy: npt.NDArray[np.float32],
        *,
        min_inliers: int,
        prior: npt.NDArray[np.float64] | None = None,
    ) -> PnpResult | None:
        """Return the pose mapping reference points onto pixels, or None with < min_inliers.

        With a prior (the pose predicted by the camera's last motion) a second hypothesis is
        grown from the matches that the prior already explains. On repetitive texture (floor
        planks, book spines) RANSAC can find a consensus of matches shifted by one period, as
        large as the true one; the prior's hypothesis wins unless it has clearly fewer inliers.
        """
        if len(points) < max(min_inliers, 6):
            return None
        obj = np.ascontiguousarray(points, np.float64)
        img = np.ascontiguousarray(xy, np.float64)
        seed = self._ransac(obj, img, min_inliers)
        found = self._refine(obj, img, seed, min_inliers) if seed is not None else None
        if prior is None:
            return found
        rvec = np.asarray(cv2.Rodrigues(prior[:3, :3])[0], np.float64)
        tvec = prior[:3, 3].reshape(3, 1).copy()
        err = _reprojection_errors(obj, img, rvec, tvec, self.camera_matrix, self.dist)
        gated = np.flatnonzero(err < _PRIOR_GATE * self.reprojection_px).astype(np.int64)
        if len(gated) < min_inliers:
            return found
        predicted = self._refine(obj, img, (rvec, tvec, gated), min_inliers)
        if predicted is None:
            return found
        if found is None or len(predicted.inliers) >= _PRIOR_SHARE * len(found.inliers):
            return predicted
        return found

    def _ransac(
        self, obj: npt.NDArray[np.float64], img: npt.NDArray[np.float64], min_inliers: int
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.int64]] | None:
        ok, rvec, tvec, inliers = cv2.solvePnPRansac(
            obj,
            img,
            self.camera_matrix,
            self.dist,
            iterationsCount=self.iterations,
            reprojectionError=self.reprojection_px,
            confidence=self.confidence,
            flags=cv2.SOLVEPNP_EPNP,
        )
        if not ok or inliers is None or len(inliers) < min_inliers:
            return None
        idx = np.asarray(inliers).ravel().astype(np.int64)
        return np.asarray(rvec, np.float64), np.asarray(tvec, np.float64), idx

    def _refine(
        self,
        obj: npt.NDArray[np.float64],
        img: npt.NDArray[np.float64],
        hypothesis: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.int64]],
        min_inliers: int,
    ) -> PnpResult | None:
        """Run LM on the inliers twice, re-selecting them with the refined pose in between."""
        rvec, tvec, idx = hypothesis
        for _ in range(2):
            refined = cv2.solvePnPRefineLM(
                obj[idx], img[idx], self.camera_matrix, self.dist, rvec, tvec
            )
            rvec, tvec = np.asarray(refined[0], np.float64), np.asarray(refined[1], np.float64)
            err = _reprojection_errors(obj, img, rvec, tvec, self.camera_matrix, self.dist)
            idx = np.flatnonzero(err < self.reprojection_px).astype(np.int64)
            if len(idx) < min_inliers:
                return None
        rms = float(np.sqrt(np.mean(err[idx] ** 2)))
        return PnpResult(to_matrix(rvec, tvec), idx, rms)


def _reprojection_errors(
    obj: npt.NDArray[np.float64],
    img: npt.NDArray[np.float64],
    rvec: npt.NDArray[np.float64],
    tvec: npt.NDArray[np.float64],
    camera_matrix: npt.NDArray[np.float64],
    dist: npt.NDArray[np.float64] | None,
) -> npt.NDArray[np.float64]:
    proj, _ = cv2.projectPoints(obj, rvec, tvec, camera_matrix, dist)
    err = np.asarray(np.linalg.norm(np.asarray(proj).reshape(-1, 2) - img, axis=1), np.float64)
    rot = np.asarray(cv2.Rodrigues(rvec)[0], np.float64)
    behind = (obj @ rot.T + tvec.reshape(1, 3))[:, 2] <= 0
    err[behind] = np.inf
    return err


def rigid_inverse(transform: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Return the inverse of a 4x4 rigid transform."""
    out = np.eye(4)
    rot = transform[:3, :3]
    out[:3, :3] = rot.T
    out[:3, 3] = -rot.T @ transform[:3, 3]
    return out


def to_matrix(
    rvec: npt.NDArray[np.float64], tvec: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]:
    """Return the 4x4 transform of an OpenCV (rvec, tvec) pair."""
    out = np.eye(4)
    out[:3, :3] = np.asarray(cv2.Rodrigues(np.asarray(rvec, np.float64))[0], np.float64)
    out[:3, 3] = np.asarray(tvec, np.float64).ravel()
    return out


def visible_share(
    points: npt.NDArray[np.float32], camera_from_points: npt.NDArray[np.float64], intr: Intrinsics
) -> float:
    """Return the share of points (their own frame) that a camera sees inside its image."""
    if len(points) == 0:
        return 0.0
    rot = camera_from_points[:3, :3].astype(np.float32)
    p = points @ rot.T + camera_from_points[:3, 3].astype(np.float32)
    z = np.maximum(p[:, 2], 1e-6)
    u = p[:, 0] / z * intr.fx + intr.cx
    v = p[:, 1] / z * intr.fy + intr.cy
    inside = (p[:, 2] > 0) & (u >= 0) & (u < intr.width) & (v >= 0) & (v < intr.height)
    return float(inside.mean())


def information_from_points(points: npt.NDArray[np.float32]) -> npt.NDArray[np.float64]:
    """Return the 6x6 information of a rigid alignment supported by these points (target frame).

    The same sum of G^T G over correspondences as Open3D's
    get_information_matrix_from_point_clouds, computed here from matched points instead of clouds.
    """
    p = np.asarray(points, np.float64)
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    zero, one = np.zeros_like(x), np.ones_like(x)
    g = np.stack(
        [
            np.stack([zero, z, -y, one, zero, zero], axis=1),
            np.stack([-z, zero, x, zero, one, zero], axis=1),
            np.stack([y, -x, zero, zero, zero, one], axis=1),
        ],
        axis=1,
    )  # (N, 3, 6)
    return np.asarray(np.einsum("nri,nrj->ij", g, g), np.float64)
