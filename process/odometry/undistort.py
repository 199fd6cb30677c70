"""Undistort a frame once so that every later step (ORB, PnP, dense alignment) is pinhole.

Kinect v1 colour images (TUM freiburg 1 and 2) come with lens distortion (k1 0.26, ...: about
25 px at the corners). Open3D's dense RGB-D odometry knows only a pinhole camera, so on the raw
image it aligns every off-centre pixel along a slightly wrong ray. Remapping the grey image
(bilinear) and its registered depth (nearest: no blending across depth edges) costs about a
millisecond per frame; the keypoints shown on the timeline are mapped back to the raw image.
"""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt

from capture.recording import Intrinsics


class Undistorter:
    """Remap a distorted camera's images onto a pinhole camera with the same matrix."""

    def __init__(self, intrinsics: Intrinsics) -> None:
        k = intrinsics
        self.pinhole = Intrinsics(k.width, k.height, k.fx, k.fy, k.cx, k.cy)
        self._matrix = k.matrix.astype(np.float64)
        self._dist = np.asarray(k.coeffs, np.float64)
        self._maps = cv2.initUndistortRectifyMap(
            self._matrix, self._dist, None, self._matrix, (k.width, k.height), cv2.CV_16SC2
        )

    def gray(self, gray: npt.NDArray[np.uint8]) -> npt.NDArray[np.uint8]:
        """Return the grey image seen by the pinhole camera (bilinear)."""
        return np.asarray(cv2.remap(gray, *self._maps, cv2.INTER_LINEAR), np.uint8)

    def depth(self, depth_m: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
        """Return the registered depth seen by the pinhole camera (nearest, 0 outside)."""
        return np.asarray(cv2.remap(depth_m, *self._maps, cv2.INTER_NEAREST), np.float32)

    def to_distorted(self, xy: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
        """Return pinhole pixels mapped back into the raw (distorted) image; NaN stays NaN."""
        out = np.full(xy.shape, np.nan, np.float32)
        ok = np.all(np.isfinite(xy), axis=1)
        if not ok.any():
            return out
        k = self.pinhole
        rays = np.stack(
            [(xy[ok, 0] - k.cx) / k.fx, (xy[ok, 1] - k.cy) / k.fy, np.ones(int(ok.sum()))], axis=1
        )
        raw, _ = cv2.projectPoints(
            rays.astype(np.float64), np.zeros(3), np.zeros(3), self._matrix, self._dist
        )
        out[ok] = np.asarray(raw, np.float32).reshape(-1, 2)
        return out
