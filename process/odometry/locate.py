"""Locate an image against one keyframe: matching, PnP, then refinement with the current depth."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from process.odometry.features import FeatureExtractor, Keyframe
from process.odometry.matching import guided_match, match
from process.odometry.pnp import PnpResult, PnpSolver
from process.odometry.pose_refine import refine_with_depth

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


class Locator:
    """Find the pose of an image (keypoints, descriptors, depth) relative to a keyframe."""

    def __init__(self, cfg: OdometryConfig, *, extractor: FeatureExtractor) -> None:
        self.cfg = cfg
        self.extractor = extractor
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
    ) -> Located | str:
        """Return the located pose, or why it failed (a phrase for the timeline)."""
        q, t = self._match(kf, xy, descriptors, prior)
        pnp = self.pnp.solve(kf.points[t], xy[q], min_inliers=self.cfg.min_inliers, prior=prior)
        if pnp is None:
            return f"{len(xy)} features, {len(q)} matches, < {self.cfg.min_inliers} PnP inliers"
        pnp = self._with_depth(pnp, kf.points[t[pnp.inliers]], xy[q[pnp.inliers]], depth)
        return Located(kf, pnp, q, t)

    def _with_depth(
        self,
        pnp: PnpResult,
        points: npt.NDArray[np.float32],
        xy: npt.NDArray[np.float32],
        depth: npt.NDArray[np.float32],
    ) -> PnpResult:
        """Refine a PnP pose with the current depth at its inlier keypoints, if configured.

        The pose gets its information as a pose-graph edge either way.
        """
        z = self.extractor.lift(xy, depth)[:, 2]
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
            )
            if len(q) >= 2 * cfg.min_inliers:
                return q, t
        return match(descriptors, kf.descriptors, ratio=cfg.match_ratio)
