"""When a frame becomes a keyframe, and when a dense correction of its pose is trusted."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from capture.recording import Intrinsics
from process.geometry import rigid_inverse
from process.odometry.dense import DenseAligner, pose_difference
from process.odometry.features import Keyframe, visible_share

if TYPE_CHECKING:
    from process.odometry.config import OdometryConfig


def needs_keyframe(
    kf: Keyframe,
    kf_from_camera: npt.NDArray[np.float64],
    n_inliers: int,
    *,
    cfg: OdometryConfig,
    intrinsics: Intrinsics,
) -> bool:
    """Return whether a frame tracked against kf moved, turned or lost enough to be a keyframe.

    The first frame tracked against kf sets `kf.first_inliers`.
    """
    moved_m, turned_deg = pose_difference(np.eye(4), kf_from_camera)
    if moved_m > cfg.keyframe_translation_m or turned_deg > cfg.keyframe_rotation_deg:
        return True
    if kf.first_inliers == 0:
        kf.first_inliers = n_inliers
    if n_inliers < max(cfg.keyframe_min_inliers, cfg.keyframe_min_inlier_ratio * kf.first_inliers):
        return True
    share = visible_share(kf.points, rigid_inverse(kf_from_camera), intrinsics)
    return share < cfg.keyframe_min_overlap


@dataclass(frozen=True, slots=True)
class FeatureCheck:
    """The PnP inliers behind a pose: a dense correction must keep explaining them."""

    points: npt.NDArray[np.float32]  # (N, 3) keyframe frame
    normalised: npt.NDArray[np.float32]  # (N, 2) their keypoints in the current image, x/z y/z
    focal_px: float

    def rms_px(self, kf_from_camera: npt.NDArray[np.float64]) -> float:
        """Return the RMS reprojection error of the inliers at a pose."""
        camera_from_kf = rigid_inverse(kf_from_camera)
        q = self.points @ camera_from_kf[:3, :3].T + camera_from_kf[:3, 3]
        z = np.maximum(q[:, 2], 1e-6)
        err = q[:, :2] / z[:, None] - self.normalised
        return self.focal_px * float(np.sqrt(np.mean(np.sum(err**2, axis=1))))


def refine_densely(
    dense: DenseAligner,
    source: Any,
    target: Any,
    kf_from_camera: npt.NDArray[np.float64],
    *,
    cfg: OdometryConfig,
    quick: bool = False,
    check: FeatureCheck | None = None,
) -> npt.NDArray[np.float64]:
    """Return the densely refined relative pose, or the given one where refinement fails.

    With a check, a correction that makes the PnP inliers reproject worse by more than
    cfg.dense_max_reprojection_px (RMS) is refused: on blurred or rolling-shutter images
    (Kinect v1 under fast rotation) the photometric term pulls away from the features.
    """
    result = dense.align(source, target, init_target_from_source=kf_from_camera, quick=quick)
    if result is None or result.fitness < cfg.dense_min_fitness:
        return kf_from_camera
    moved_m, turned_deg = pose_difference(kf_from_camera, result.target_from_source)
    if moved_m > cfg.dense_max_correction_m or turned_deg > cfg.dense_max_correction_deg:
        return kf_from_camera
    if check is not None and len(check.points) > 0:
        worse = check.rms_px(result.target_from_source) - check.rms_px(kf_from_camera)
        if worse > cfg.dense_max_reprojection_px:
            return kf_from_camera
    return result.target_from_source
