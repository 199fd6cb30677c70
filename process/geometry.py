"""Rigid transforms and the pinhole model on `Intrinsics`: the small maths every stage shares.

Shapes are (..., 3) for points and (..., 2) for pixels; results keep the points' float dtype, so
float32 hot paths stay float32. Lens distortion is not handled here: callers with distorted
cameras go through OpenCV (`cv2.projectPoints`, `cv2.undistortPoints`).
"""

from __future__ import annotations

from typing import TypeVar

import numpy as np
import numpy.typing as npt

from capture.recording import Intrinsics

F = TypeVar("F", np.float32, np.float64)


def rigid_inverse(transform: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Return the inverse of a 4x4 rigid transform."""
    out = np.eye(4)
    rot = transform[:3, :3]
    out[:3, :3] = rot.T
    out[:3, 3] = -rot.T @ transform[:3, 3]
    return out


def transform_points(
    target_from_source: npt.NDArray[np.float64], points: npt.NDArray[F]
) -> npt.NDArray[F]:
    """Return (N, 3) points of the source frame in the target frame, in the points' dtype."""
    rot = target_from_source[:3, :3].astype(points.dtype)
    out: npt.NDArray[F] = points @ rot.T + target_from_source[:3, 3].astype(points.dtype)
    return out


def project(points: npt.NDArray[F], k: Intrinsics) -> npt.NDArray[F]:
    """Return the pixels (u, v) of camera-frame points with z > 0 (pinhole, no distortion)."""
    focal = np.array([k.fx, k.fy], points.dtype)
    centre = np.array([k.cx, k.cy], points.dtype)
    out: npt.NDArray[F] = points[..., :2] / points[..., 2:3] * focal + centre
    return out


def normalise(pixels: npt.NDArray[F], k: Intrinsics) -> npt.NDArray[F]:
    """Return normalised image coordinates (x/z, y/z) of pixels (pinhole, no distortion)."""
    focal = np.array([k.fx, k.fy], pixels.dtype)
    centre = np.array([k.cx, k.cy], pixels.dtype)
    out: npt.NDArray[F] = (pixels - centre) / focal
    return out
