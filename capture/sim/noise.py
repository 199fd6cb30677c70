"""A depth-error model of the Intel RealSense D435 stereo camera.

What the model does and where each part comes from:

- Random error grows with the square of the distance. Intel's formula for the depth RMS error
  of its D400 cameras is ``RMS = z^2 * subpixel / (focal_px * baseline)`` (Intel, "Tuning depth
  cameras for best performance", rev. 2019, section 1; and the D400 datasheet), with a subpixel
  matching accuracy of about 0.08 px for a well-textured scene and the D435's 50 mm baseline.
  The model draws the error in disparity (Gaussian with that subpixel spread) and converts it
  to depth, which gives exactly that RMS to first order. Measurements agree with the quadratic
  growth: Ahn et al., "Analysis and Noise Modeling of the Intel RealSense D435 for Mobile Robots"
  (UR 2019), and Giancola, Valenti and Sala, "A Survey on 3D Cameras: Metrological Comparison of
  Time-of-Flight, Structured-Light and Active Stereoscopy Technologies" (Springer 2018), who
  report errors of a few millimetres at 1 m rising to centimetres at 3-4 m.
- Output is quantised to the depth unit (1 mm by default, REP 118 16UC1), 0 = no depth.
- No depth below the minimum distance (about 0.28 m at 640x480, the limit of the disparity
  search range) or beyond the range limit (about 10 m).
- No depth where the right imager cannot see what the left (reference) imager sees: the
  occlusion shadow left of foreground objects and the band at the image's left edge (Intel,
  "Intel RealSense D400 Series Product Family Datasheet", section "Invalid depth band").
- No depth at depth discontinuities, where the matching window straddles two surfaces and the
  camera's filters reject the match (Intel's edge-preserving and hole behaviour, Ahn et al.).
- Holes on very dark surfaces (too little reflected IR pattern) and on glossy ones seen head-on
  (the projector's reflection saturates the imagers), and at grazing incidence.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from capture.errors import CaptureError
from capture.sim.render import DepthView


@dataclass(frozen=True, slots=True)
class D435DepthModel:
    """Parameters of the D435 depth-error model (defaults: the D435 at 640x480)."""

    baseline_m: float = 0.050
    subpixel: float = 0.08  # RMS matching error in pixels
    min_depth_m: float = 0.28
    max_depth_m: float = 10.0
    depth_unit_m: float = 0.001
    edge_jump: float = 0.05  # relative depth jump in a 3x3 window that invalidates a pixel
    dark_luminance: float = 0.12  # albedo below which the IR pattern is lost...
    dark_dropout: float = 0.5  # ...for this fraction of the pixels
    specular_cos: float = 0.996  # glossy surfaces seen within ~5 degrees of head-on
    grazing_cos: float = 0.1  # surfaces seen at more than ~84 degrees

    def __post_init__(self) -> None:
        if not (
            0 < self.min_depth_m < self.max_depth_m and self.baseline_m > 0 and self.subpixel >= 0
        ):
            raise CaptureError(
                f"expected 0 < min_depth_m < max_depth_m, baseline_m > 0, subpixel >= 0; got {self}"
            )

    def rms_error_m(self, depth_m: npt.ArrayLike, *, focal_px: float) -> npt.NDArray[np.float64]:
        """Return Intel's depth RMS error: z^2 * subpixel / (focal_px * baseline)."""
        z = np.asarray(depth_m, np.float64)
        return np.asarray(z**2 * self.subpixel / (focal_px * self.baseline_m), np.float64)

    def add_noise(
        self, depth_m: npt.NDArray[np.float32], *, focal_px: float, rng: np.random.Generator
    ) -> npt.NDArray[np.float32]:
        """Return depth with the disparity error drawn; 0 (no depth) stays 0.

        With disparity d = fB / z and an error e: z' = fB / (d + e) = z / (1 + e z / fB).
        """
        scale = rng.standard_normal(depth_m.shape, dtype=np.float32)
        scale *= np.float32(self.subpixel / (focal_px * self.baseline_m))
        scale *= depth_m
        scale += np.float32(1.0)
        np.maximum(scale, np.float32(1e-3), out=scale)  # a disparity below zero: far, not negative
        return np.asarray(depth_m / scale, np.float32)

    def invalid_mask(
        self, view: DepthView, *, focal_px: float, rng: np.random.Generator
    ) -> npt.NDArray[np.bool_]:
        """Return where the D435 reports no depth for an exact depth view."""
        z = view.depth_m
        mask = (z < self.min_depth_m) | (z > self.max_depth_m)
        mask |= stereo_occlusion(z, focal_px=focal_px, baseline_m=self.baseline_m)
        mask |= depth_edges(z, relative_jump=self.edge_jump)
        mask |= (view.luminance < self.dark_luminance) & (
            rng.random(z.shape, dtype=np.float32) < self.dark_dropout
        )
        mask |= view.glossy & (view.cos_incidence > self.specular_cos)
        mask |= view.cos_incidence < self.grazing_cos
        return mask

    def apply(
        self, view: DepthView, *, focal_px: float, rng: np.random.Generator
    ) -> npt.NDArray[np.uint16]:
        """Return the 16UC1 depth image (depth units, 0 = none) the D435 would report."""
        noisy = self.add_noise(view.depth_m, focal_px=focal_px, rng=rng)
        noisy[self.invalid_mask(view, focal_px=focal_px, rng=rng)] = 0.0
        units = np.rint(noisy / np.float32(self.depth_unit_m))
        return np.asarray(np.clip(units, 0, 65535), np.uint16)


def stereo_occlusion(
    depth_m: npt.NDArray[np.float32], *, focal_px: float, baseline_m: float
) -> npt.NDArray[np.bool_]:
    """Return pixels of the left (reference) imager that the right imager cannot see.

    The right imager sits `baseline_m` along +x, so a point at column u with disparity d lands at
    column u - d there. A pixel is hidden when a pixel to its right lands further left (a nearer
    surface in front of it), or when it lands outside the right image (the left band).
    """
    h, w = depth_m.shape
    disparity = np.where(
        depth_m > 0, focal_px * baseline_m / np.where(depth_m > 0, depth_m, 1.0), 0.0
    )
    right_u = np.arange(w, dtype=np.float32)[None, :] - disparity.astype(np.float32)
    # Smallest right-image column of all pixels strictly to the right of each pixel.
    after = np.minimum.accumulate(right_u[:, ::-1], axis=1)[:, ::-1]
    after = np.concatenate([after[:, 1:], np.full((h, 1), np.inf, np.float32)], axis=1)
    return np.asarray((after < right_u - 1e-3) | (right_u < 0), np.bool_)


def depth_edges(depth_m: npt.NDArray[np.float32], *, relative_jump: float) -> npt.NDArray[np.bool_]:
    """Return pixels whose 3x3 neighbourhood spans a depth jump larger than relative_jump * z."""
    kernel = np.ones((3, 3), np.uint8)
    z = np.where(depth_m > 0, depth_m, np.float32(0.0)).astype(np.float32)
    spread = cv2.dilate(z, kernel) - cv2.erode(z, kernel)
    return np.asarray(spread > relative_jump * z, np.bool_)


class ColorSensorNoise:
    """Gaussian read noise of the colour sensor, drawn from a pool so a frame costs one add."""

    def __init__(self, rng: np.random.Generator, *, size: int, sigma: float = 2.0) -> None:
        self._pool = np.rint(rng.normal(0.0, sigma, size + 65536)).astype(np.int16)
        self._rng = rng
        self._size = size

    def apply(self, color: npt.NDArray[np.uint8]) -> npt.NDArray[np.uint8]:
        """Return the image with noise added (a fresh random window of the pool)."""
        start = int(self._rng.integers(0, len(self._pool) - self._size + 1))
        noise = self._pool[start : start + color.size].reshape(color.shape)
        return np.asarray(np.clip(color + noise, 0, 255), np.uint8)
