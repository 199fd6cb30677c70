"""Plausibility of camera calibration read from a recording: what no real camera can have."""

from __future__ import annotations

from typing import Final

import numpy as np

from capture.recording.frames import Extrinsics, Intrinsics

MIN_SIDE_PX: Final = 16  # smaller images carry no usable geometry
MAX_SIDE_PX: Final = 16384


def intrinsics_problem(k: Intrinsics) -> str:
    """Return why a camera model is impossible ("" when it is plausible)."""
    values = (k.fx, k.fy, k.cx, k.cy, *k.coeffs)
    if not all(np.isfinite(v) for v in values):
        return f"non-finite intrinsics (fx {k.fx}, fy {k.fy}, cx {k.cx}, cy {k.cy}, {k.coeffs})"
    if not (k.fx > 0 and k.fy > 0):
        return f"focal length fx {k.fx}, fy {k.fy} (expected > 0 pixels)"
    if not (MIN_SIDE_PX <= k.width <= MAX_SIDE_PX and MIN_SIDE_PX <= k.height <= MAX_SIDE_PX):
        return f"image size {k.width}x{k.height} (expected {MIN_SIDE_PX}..{MAX_SIDE_PX} a side)"
    if not (k.fx < 100 * k.width and k.fy < 100 * k.height):
        return f"focal length fx {k.fx}, fy {k.fy} for a {k.width}x{k.height} image"
    return ""


def extrinsics_problem(e: Extrinsics) -> str:
    """Return why a depth-to-colour transform is impossible ("" when it is a rigid motion)."""
    m4 = e.color_from_depth
    if not np.isfinite(m4).all():
        return "non-finite depth-to-colour extrinsics"
    rot = m4[:3, :3]
    if not np.allclose(rot.T @ rot, np.eye(3), atol=1e-3) or np.linalg.det(rot) < 0:
        return "depth-to-colour rotation is not a rotation matrix"
    if np.abs(m4[:3, 3]).max() > 1.0:
        return f"depth-to-colour translation {m4[:3, 3].tolist()} m (expected < 1 m)"
    return ""
