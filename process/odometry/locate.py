"""Locate an image against one keyframe: matching, PnP, then refinement with the current depth."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from process.geometry import project
from process.odometry.features import FeatureExtractor, Keyframe
from process.odometry.matching import guided_match, match
from process.odometry.pnp import PnpResult, PnpSolver
from process.odometry.pose_refine import refine_with_depth
from process.odometry.rolling_shutter import RollingShutter

if TYPE_CHECKING:
    from process.odometry.config import OdometryConfig

_REFINE_ITERATIONS = 8


@dataclass(frozen=True, slots=True)
class Located:
    """The pose of an image against a keyframe and the matches behind it."""

    keyframe: Keyframe
    pnp: PnpResult
    query: npt.NDArray[np.int64]  # matched current features
    train: npt.NDArray[np.int64]  # their keyframe features
    # (K, 2) the matched keypoints where a global shutter at the middle row's time would see them
    observed: npt.NDArray[np.float32]


class Locator:
    """Find the pose of an image (keypoints, descriptors, depth) relative to a keyframe."""

    def __init__(
        self,
        cfg: OdometryConfig,
        *,
        extractor: FeatureExtractor,
        shutter: RollingShutter | None = None,
    ) -> None:
        self.cfg = cfg
        self.extractor = extractor
        self.shutter = shutter  # None: a global shutter
        self.pnp = PnpSolver(
            extractor.camera_matrix,
            extractor.dist,
            cfg.ransac_reprojection_px,
            cfg.ransac_iterations,
            cfg.ransac_confidence,
        )

    def locate(
        self,
        kf: Keyframe,
        xy: npt.NDArray[np.float32],
        descriptors: npt.NDArray[np.uint8],
        depth: npt.NDArray[np.float32],
        *,
        prior: npt.NDArray[np.float64] | None,
        twist: npt.NDArray[np.float64] | None = None,
    ) -> Located | str:
        """Return the located pose, or why it failed (a phrase for the timeline).

        With a rolling shutter, a prior and the camera's twist (process.odometry.rolling_shutter),
        each keyframe point is searched where the moving shutter sees it, and the matched
        keypoints are moved to where the middle row's camera would see them.
        """
        shift = self._shutter_shift(kf, prior, twist)
        q, t = self._match(kf, xy, descriptors, prior, shift)
        observed = xy[q] if shift is None else (xy[q] - shift[t, :2]).astype(np.float32)
        pnp = self.pnp.solve(kf.points[t], observed, min_inliers=self.cfg.min_inliers, prior=prior)
        if pnp is None:
            return f"{len(xy)} features, {len(q)} matches, < {self.cfg.min_inliers} PnP inliers"
        inl = pnp.inliers
        z = self.extractor.lift(xy[q[inl]], depth)[:, 2]  # the depth image is read where seen
        if shift is not None:
            z = z - shift[t[inl], 2].astype(np.float32)
        pnp = self._with_depth(pnp, kf.points[t[inl]], observed[inl], z)
        return Located(kf, pnp, q, t, observed)

    def _shutter_shift(
        self,
        kf: Keyframe,
        prior: npt.NDArray[np.float64] | None,
        twist: npt.NDArray[np.float64] | None,
    ) -> npt.NDArray[np.float64] | None:
        """Return (M, 3) rolling-shutter displacements (px, px, m) of kf's points, or None."""
        if self.shutter is None or prior is None or twist is None or not np.any(twist):
            return None
        p = kf.points.astype(np.float64) @ prior[:3, :3].T + prior[:3, 3]
        front = p[:, 2] > 0.05
        shift = np.zeros((len(p), 3))
        if front.any():
            seen, depth = self.shutter.observe(p[front], twist)
            shift[front, :2] = seen - project(p[front], self.extractor.intrinsics)
            shift[front, 2] = depth - p[front, 2]
        return shift

    def _with_depth(
        self,
        pnp: PnpResult,
        points: npt.NDArray[np.float32],
        xy: npt.NDArray[np.float32],
        z: npt.NDArray[np.float32],
    ) -> PnpResult:
        """Refine a PnP pose with the current depth z at its inlier keypoints, if configured.

        The pose gets its information as a pose-graph edge either way.
        """
        refine = self.cfg.depth_refine and int(np.isfinite(z).sum()) >= self.cfg.min_inliers
        refined = refine_with_depth(
            points,
            self.extractor.normalised(xy),
            z,
            camera_from_reference=pnp.camera_from_reference,
            focal_px=self.extractor.intrinsics.fx,
            iterations=_REFINE_ITERATIONS if refine else 0,  # else keep the PnP pose
        )
        return PnpResult(
            refined.camera_from_reference, pnp.inliers, pnp.rms_px, refined.information
        )

    def _match(
        self,
        kf: Keyframe,
        xy: npt.NDArray[np.float32],
        descriptors: npt.NDArray[np.uint8],
        prior: npt.NDArray[np.float64] | None,
        shift: npt.NDArray[np.float64] | None,
    ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
        """Match by projection around the predicted pose, else (or if too few) all against all."""
        cfg = self.cfg
        if prior is not None and cfg.guided_radius_px > 0:
            q, t = guided_match(
                kf.points,
                kf.descriptors,
                xy,
                descriptors,
                camera_from_points=prior,
                intrinsics=self.extractor.intrinsics,
                radius_px=cfg.guided_radius_px,
                ratio=cfg.match_ratio,
                offset_px=None if shift is None else shift[:, :2],
            )
            if len(q) >= 2 * cfg.min_inliers:
                return q, t
        return match(descriptors, kf.descriptors, ratio=cfg.match_ratio)
