"""Refine a PnP pose with the current frame's depth as well: reprojection plus disparity residuals.

PnP alone sees only pixel positions. When the matched points are far (a wall 4 m away) a sideways
translation and a small turn move them alike, and PnP may settle centimetres off along that valley
while keeping every inlier. The current frame's depth at the keypoints tells the two apart (a
turn changes the depth of off-axis points, a sideways shift does not). As in ORB-SLAM's RGB-D mode,
each depth becomes a disparity-like residual in pixels, so one Gauss-Newton solve weighs both.
Hand-written because OpenCV's PnP refiners take no depth; it is a 6x6 solve on a few hundred points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

_VIRTUAL_BASELINE_M = 0.05  # disparity = f * b / z with a D435-like stereo baseline
_SIGMA_PX = 1.0  # keypoint position noise (ORB)
# Of the plane-fitted keypoint depth: D435 depth noise grows with z^2, so its disparity noise is
# about constant; ~0.04 px measured on the simulated D435 (2.4 cm at 4.3 m). A floor: the noise
# actually used is measured per pose (_disparity_sigma).
_SIGMA_DISPARITY_PX = 0.05
_HUBER = 2.0  # in sigmas
_MIN_DEPTHS = 6  # fewer keypoints with depth: the sensor's noise is assumed
_ITERATIONS = 8
_CONVERGED = 1e-6  # a smaller step (rad, m) moves a keypoint by < 0.001 px: stop


@dataclass(frozen=True, slots=True)
class Refined:
    """A refined pose, its robust cost and the information (Gauss-Newton Hessian) at it."""

    camera_from_reference: npt.NDArray[np.float64]  # (4, 4)
    cost: float  # robust (Huber) cost, comparable between starts
    # (6, 6) J^T W J at the pose, twist (rotation, translation) of a left update of
    # camera_from_reference: the information of reference_from_camera in GTSAM's (right,
    # camera-frame) convention, in units of the residuals' sigmas.
    information: npt.NDArray[np.float64]


def refine_with_depth(
    points: npt.NDArray[np.float32],
    normalised: npt.NDArray[np.float32],
    depth_m: npt.NDArray[np.float32],
    *,
    camera_from_reference: npt.NDArray[np.float64],
    focal_px: float,
    iterations: int = _ITERATIONS,
) -> Refined:
    """Return camera_from_reference refined on reprojection and depth residuals.

    Args:
        points: (N, 3) reference-frame points (PnP inliers).
        normalised: (N, 2) their observations in the current image, normalised (x/z, y/z).
        depth_m: (N,) current depth at those keypoints, NaN where unknown.
        camera_from_reference: (4, 4) the pose to start from.
        focal_px: the focal length that turns normalised units into pixels.
        iterations: Gauss-Newton iterations at most (0: only evaluate the pose).

    Returns:
        The refined pose, its robust cost and its information.
    """
    p = np.asarray(points, np.float64)
    obs = np.asarray(normalised, np.float64) * focal_px
    has_depth = np.isfinite(depth_m)
    inv_depth = np.where(has_depth, 1.0 / np.where(has_depth, depth_m, 1.0), 0.0)
    fb = focal_px * _VIRTUAL_BASELINE_M
    pose = np.array(camera_from_reference, np.float64)
    sigma_d = _disparity_sigma(p, pose, inv_depth[has_depth], has_depth, fb)

    def residuals(
        pose: npt.NDArray[np.float64],
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        q = p @ pose[:3, :3].T + pose[:3, 3]
        iz = 1.0 / np.maximum(q[:, 2], 1e-6)
        residual = np.concatenate(
            [
                (focal_px * q[:, :2] * iz[:, None] - obs).ravel() / _SIGMA_PX,
                np.where(has_depth, fb * (iz - inv_depth), 0.0) / sigma_d,
            ]
        )
        return residual, _jacobian(q, iz, focal_px, fb, has_depth, sigma_d)

    for _ in range(iterations):
        residual, jac = residuals(pose)
        weight = np.minimum(1.0, _HUBER / np.maximum(np.abs(residual), 1e-12))  # Huber (IRLS)
        h = jac.T @ (jac * weight[:, None])
        g = jac.T @ (weight * residual)
        try:
            step = -np.linalg.solve(h, g)
        except np.linalg.LinAlgError:
            break
        update = np.eye(4)
        update[:3, :3] = Rotation.from_rotvec(step[:3]).as_matrix()
        update[:3, 3] = step[3:]
        pose = update @ pose
        if np.linalg.norm(step) < _CONVERGED:
            break
    residual, jac = residuals(pose)
    return Refined(pose, _huber_cost(residual), _information(residual, jac))


def pose_information(
    points: npt.NDArray[np.float32],
    normalised: npt.NDArray[np.float32],
    depth_m: npt.NDArray[np.float32],
    *,
    camera_from_reference: npt.NDArray[np.float64],
    focal_px: float,
) -> npt.NDArray[np.float64]:
    """Return the information of a pose without refining it (see Refined.information)."""
    return refine_with_depth(
        points,
        normalised,
        depth_m,
        camera_from_reference=camera_from_reference,
        focal_px=focal_px,
        iterations=0,
    ).information


def _information(
    residual: npt.NDArray[np.float64], jac: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]:
    weight = np.minimum(1.0, _HUBER / np.maximum(np.abs(residual), 1e-12))  # Huber (IRLS)
    return np.asarray(jac.T @ (jac * weight[:, None]), np.float64)


def _disparity_sigma(
    points: npt.NDArray[np.float64],
    camera_from_reference: npt.NDArray[np.float64],
    inv_depth: npt.NDArray[np.float64],
    has_depth: npt.NDArray[np.bool_],
    fb: float,
) -> float:
    """Return the disparity noise to weigh the depth residuals by: the sensor's, or more.

    The robust spread (1.4826 x median absolute value) of the disparity residuals at the
    starting (PnP) pose, floored at _SIGMA_DISPARITY_PX. Where depth and colour disagree more
    than sensor noise (Kinect v1: depth taken up to 20 ms apart from the colour under fast
    rotation, rolling shutter) the depth term weighs less and cannot pull the pose away from
    the features; on a synchronised sensor it keeps its full weight.
    """
    if int(has_depth.sum()) < _MIN_DEPTHS:
        return _SIGMA_DISPARITY_PX
    q = points[has_depth] @ camera_from_reference[:3, :3].T + camera_from_reference[:3, 3]
    residual = fb * (1.0 / np.maximum(q[:, 2], 1e-6) - inv_depth)
    return max(_SIGMA_DISPARITY_PX, 1.4826 * float(np.median(np.abs(residual))))


def _huber_cost(residual: npt.NDArray[np.float64]) -> float:
    a = np.abs(residual)
    return float(np.sum(np.where(a <= _HUBER, 0.5 * a * a, _HUBER * (a - 0.5 * _HUBER))))


def _jacobian(
    q: npt.NDArray[np.float64],
    iz: npt.NDArray[np.float64],
    f: float,
    fb: float,
    has_depth: npt.NDArray[np.bool_],
    sigma_d: float,
) -> npt.NDArray[np.float64]:
    """Return d(residual)/d(twist) of a left-multiplied update (rotation, then translation)."""
    n = len(q)
    x, y = q[:, 0], q[:, 1]
    # d q / d twist = [-[q]x | I], rows x, y, z.
    dq = np.zeros((n, 3, 6))
    dq[:, 0, 1], dq[:, 0, 2] = q[:, 2], -y
    dq[:, 1, 0], dq[:, 1, 2] = -q[:, 2], x
    dq[:, 2, 0], dq[:, 2, 1] = y, -x
    dq[:, [0, 1, 2], [3, 4, 5]] = 1.0
    du = f * (iz[:, None] * dq[:, 0] - (x * iz * iz)[:, None] * dq[:, 2]) / _SIGMA_PX
    dv = f * (iz[:, None] * dq[:, 1] - (y * iz * iz)[:, None] * dq[:, 2]) / _SIGMA_PX
    dd = -fb * (iz * iz)[:, None] * dq[:, 2] / sigma_d
    dd[~has_depth] = 0.0
    uv = np.stack([du, dv], axis=1).reshape(2 * n, 6)
    return np.concatenate([uv, dd])
