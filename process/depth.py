"""Depth in the colour camera: registration of raw depth, then the optional filters of the config.

Registration follows librealsense's `rs2::align` as pyrealsense2 2.59 runs it (checked pixel by
pixel against it on software-device frames): each depth pixel's top-left and bottom-right corners
are deprojected at its depth, moved into the colour camera and projected, rounded as
`static_cast<int>(p + 0.5f)`; the pixel then covers the colour rectangle between them, clipped to
the image; where the depth camera has more pixels per degree than the colour camera, only the
top-left corner's pixel. Where several depth pixels cover one colour pixel the nearer surface
wins (a z-buffer) and, as in `rs2::align` and realsense-ros's aligned_depth_to_color, the value is
the depth camera's z (z_frame="color" writes the colour camera's z instead; on a D435 the two
differ by a few millimetres at the image border). The config's default z-buffer averages the
samples of the nearest surface instead of taking the nearest sample, which with sensor noise is
biased towards the camera. Holes stay holes: only depth pixels write. Distortion is honoured with
OpenCV's model of the coefficients (`plumb_bob` / `rational_polynomial`); the D435's depth camera
has none and its colour camera near none, so the usual case takes the fast pinhole path.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np
import numpy.typing as npt

from capture.recording import Intrinsics, RgbdFrame
from process.errors import ConfigError, StageError
from process.geometry import normalise

DepthImage = npt.NDArray[np.float32]  # (H, W) metres, 0 = no depth

_MAX_RECT_PX = 16  # a depth pixel never covers more colour pixels than this per axis
Z_BUFFERS = ("nearest", "mean")


@dataclass(frozen=True, slots=True)
class DepthConfig:
    """Depth registration and filters; everything but the range clip is off by default."""

    z_buffer: str = "mean"  # "mean": unbiased by sensor noise; "nearest": exactly rs2::align
    min_depth_m: float = 0.1  # closer depth is dropped (D435 minimum range is ~0.2 m)
    max_depth_m: float = 10.0  # farther depth is dropped
    hole_filling: bool = False  # fill holes from their neighbours (librealsense hole filling)
    hole_filling_px: int = 1  # how many pixels a hole may be filled inward
    hole_filling_mode: str = "farthest"  # "farthest" or "nearest" of the neighbours
    smoothing: bool = False  # edge-preserving (bilateral) smoothing
    smoothing_diameter_px: int = 5
    smoothing_sigma_m: float = 0.03  # depth steps larger than this are edges, kept sharp
    smoothing_sigma_px: float = 2.0

    def __post_init__(self) -> None:
        if not 0.0 <= self.min_depth_m < self.max_depth_m:
            raise ConfigError(
                f"depth: expected 0 <= min_depth_m < max_depth_m, found {self.min_depth_m}"
                f" and {self.max_depth_m}; fix [depth] in the config"
            )
        if self.z_buffer not in Z_BUFFERS:
            raise ConfigError(f"depth.z_buffer must be one of {Z_BUFFERS}, found {self.z_buffer!r}")
        if not 1 <= self.hole_filling_px <= 32:
            raise ConfigError(
                f"depth.hole_filling_px must be in 1..32, found {self.hole_filling_px}"
            )
        if self.hole_filling_mode not in ("farthest", "nearest"):
            raise ConfigError(
                "depth.hole_filling_mode must be 'farthest' or 'nearest',"
                f" found {self.hole_filling_mode!r}"
            )
        if not 3 <= self.smoothing_diameter_px <= 15:
            raise ConfigError(
                f"depth.smoothing_diameter_px must be in 3..15, found {self.smoothing_diameter_px}"
            )
        if not (self.smoothing_sigma_m > 0 and self.smoothing_sigma_px > 0):
            raise ConfigError(
                f"depth: smoothing sigmas must be > 0, found {self.smoothing_sigma_m}"
                f" and {self.smoothing_sigma_px}"
            )


class DepthProcessor:
    """Turn a frame's depth into filtered depth in the colour camera."""

    def __init__(self, cfg: DepthConfig) -> None:
        self.cfg = cfg

    def process(self, frame: RgbdFrame) -> DepthImage:
        """Return the frame's depth in the colour camera (registered unless aligned), filtered."""
        if frame.aligned:
            depth = np.asarray(frame.depth_m, np.float32)
        elif frame.depth_to_color is None:
            raise StageError(
                f"frame {frame.index} has unaligned depth but no depth-to-colour extrinsics;"
                " record with extrinsics or with aligned depth"
            )
        else:
            depth = register_depth(
                frame.depth_m,
                depth_intrinsics=frame.depth_intrinsics,
                color_intrinsics=frame.color_intrinsics,
                color_from_depth=frame.depth_to_color.color_from_depth,
                z_buffer=self.cfg.z_buffer,
            )
        return filter_depth(depth, self.cfg)


def filter_depth(depth_m: DepthImage, cfg: DepthConfig) -> DepthImage:
    """Apply the range clip, then hole filling and smoothing if the config asks for them."""
    out = np.where((depth_m >= cfg.min_depth_m) & (depth_m <= cfg.max_depth_m), depth_m, 0.0)
    out = out.astype(np.float32)
    if cfg.hole_filling:
        out = fill_holes(out, radius_px=cfg.hole_filling_px, mode=cfg.hole_filling_mode)
    if cfg.smoothing:
        valid = out > 0
        # Bilateral: zeros differ from real depth by far more than sigma_m, so they get no weight.
        smooth = cv2.bilateralFilter(
            out, cfg.smoothing_diameter_px, cfg.smoothing_sigma_m, cfg.smoothing_sigma_px
        )
        out = np.where(valid, smooth, 0.0).astype(np.float32)
    return out


def fill_holes(depth_m: DepthImage, *, radius_px: int = 1, mode: str = "farthest") -> DepthImage:
    """Fill zero pixels from their 3x3 neighbours, `radius_px` times, never changing valid depth."""
    out = depth_m.copy()
    kernel = np.ones((3, 3), np.uint8)
    for _ in range(radius_px):
        holes = out == 0
        if not holes.any():
            break
        if mode == "farthest":
            fill = cv2.dilate(out, kernel)
        else:
            inf = np.where(holes, np.float32(np.inf), out)
            fill = cv2.erode(inf, kernel)
            fill[~np.isfinite(fill)] = 0.0
        out[holes] = fill[holes]
    return out


def register_depth(
    depth_m: DepthImage,
    *,
    depth_intrinsics: Intrinsics,
    color_intrinsics: Intrinsics,
    color_from_depth: npt.NDArray[np.float64],
    z_frame: str = "depth",
    z_buffer: str = "nearest",
) -> DepthImage:
    """Return the depth image seen from the colour camera (z in metres, 0 = none), z-buffered.

    Args:
        depth_m: (h, w) depth in metres in the depth camera, 0 = no depth.
        depth_intrinsics: the depth camera.
        color_intrinsics: the colour camera; the output has its size.
        color_from_depth: (4, 4) transform of depth-camera points into the colour camera.
        z_frame: "depth" writes (and z-buffers on) the depth camera's z, exactly as `rs2::align`
            and realsense-ros's aligned_depth_to_color do; "color" writes the colour camera's z.
        z_buffer: where several depth pixels cover a colour pixel, "nearest" keeps the nearest
            value (`rs2::align`), "mean" the mean of the values within 5 % of the nearest (the
            same surface). With sensor noise the nearest of a few samples is biased towards the
            camera (by ~2 cm at 4 m on a D435); their mean is not, and is less noisy.
    """
    if z_buffer not in Z_BUFFERS:
        raise StageError(f"z_buffer must be one of {Z_BUFFERS}, found {z_buffer!r}")
    if z_frame not in ("depth", "color"):
        raise StageError(f"z_frame must be 'depth' or 'color', found {z_frame!r}")
    z = np.asarray(depth_m, np.float32)
    if z.shape != (depth_intrinsics.height, depth_intrinsics.width):
        raise StageError(
            f"depth image is {z.shape[1]}x{z.shape[0]} but its intrinsics say"
            f" {depth_intrinsics.width}x{depth_intrinsics.height}; the recording is inconsistent"
        )
    rot = tuple(float(v) for v in np.asarray(color_from_depth, np.float64)[:3, :3].ravel())
    t = np.asarray(color_from_depth, np.float32)[:3, 3]
    top_left, bottom_right = _corner_directions(depth_intrinsics, rot)
    x0, y0, z_c = _project_corners(top_left, z, t, color_intrinsics)
    if _depth_is_denser(depth_intrinsics, color_intrinsics):
        x1, y1 = x0, y0  # librealsense then maps each depth pixel to one colour pixel
    else:
        x1, y1, _ = _project_corners(bottom_right, z, t, color_intrinsics)
    # Clip each rectangle to the image (librealsense skips the outside pixels one by one).
    w_c, h_c = color_intrinsics.width, color_intrinsics.height
    np.maximum(x0, 0, out=x0)
    np.maximum(y0, 0, out=y0)
    x1 = np.minimum(x1, w_c - 1)
    y1 = np.minimum(y1, h_c - 1)
    width = x1 - x0 + 1
    height = y1 - y0 + 1
    idx = np.flatnonzero((z > 0) & (z_c > 0) & (width > 0) & (height > 0))
    z_out = (z if z_frame == "depth" else z_c).ravel()[idx]
    base = (y0 * w_c + x0).ravel()[idx]
    width = np.minimum(width.ravel()[idx], _MAX_RECT_PX)
    height = np.minimum(height.ravel()[idx], _MAX_RECT_PX)
    out = np.full(h_c * w_c, np.inf, np.float32)
    targets, values = [], []
    for dy in range(int(height.max(initial=0))):
        for dx in range(int(width.max(initial=0))):
            pick = np.flatnonzero((height > dy) & (width > dx))
            target = (base[pick] + (dy * w_c + dx)).astype(np.int32)
            # Scatter-min is the z-buffer: the nearer surface wins where rectangles overlap.
            np.minimum.at(out, target, z_out[pick])
            if z_buffer == "mean":
                targets.append(target)
                values.append(z_out[pick])
    if z_buffer == "mean" and targets:  # none when no depth pixel lands in the image
        out = _mean_of_nearest(out, np.concatenate(targets), np.concatenate(values))
    out[np.isinf(out)] = 0.0
    return out.reshape(h_c, w_c)


def _mean_of_nearest(
    nearest: npt.NDArray[np.float32], target: npt.NDArray[np.int32], values: npt.NDArray[np.float32]
) -> npt.NDArray[np.float32]:
    """Return per pixel the mean of the values within 5 % of the nearest (the same surface)."""
    near = values <= nearest[target] * np.float32(1.05)
    total = np.zeros(len(nearest), np.float32)
    count = np.zeros(len(nearest), np.float32)
    # ufunc.at is the fastest scatter-add here (faster than bincount with a boolean selection).
    np.add.at(total, target, np.where(near, values, np.float32(0.0)))
    np.add.at(count, target, near.astype(np.float32))
    return np.where(count > 0, total / np.maximum(count, 1), np.inf).astype(np.float32)


def _project_corners(
    directions: npt.NDArray[np.float32],
    z: npt.NDArray[np.float32],
    t: npt.NDArray[np.float32],
    intr: Intrinsics,
) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.int32], npt.NDArray[np.float32]]:
    """Project points z * direction + t; return librealsense-rounded pixels and colour z."""
    qz = z * directions[2] + t[2]
    qx = z * directions[0] + t[0]
    qy = z * directions[1] + t[1]
    safe = np.where(qz > 0, qz, np.float32(1.0))
    if intr.is_distorted:
        pts = np.stack([qx.ravel(), qy.ravel(), safe.ravel()], axis=1).astype(np.float64)
        uv, _ = cv2.projectPoints(
            pts, np.zeros(3), np.zeros(3), intr.matrix, np.asarray(intr.coeffs, np.float64)
        )
        u = uv[:, 0, 0].reshape(z.shape).astype(np.float32)
        v = uv[:, 0, 1].reshape(z.shape).astype(np.float32)
    else:
        u = qx / safe * np.float32(intr.fx) + np.float32(intr.cx)
        v = qy / safe * np.float32(intr.fy) + np.float32(intr.cy)
    # librealsense rounds with static_cast<int>(p + 0.5f); astype truncates toward zero as well.
    u = np.clip(u + np.float32(0.5), -1e6, 1e6).astype(np.int32)
    v = np.clip(v + np.float32(0.5), -1e6, 1e6).astype(np.int32)
    return u, v, qz


def _depth_is_denser(depth: Intrinsics, color: Intrinsics) -> bool:
    """Return whether depth has at least the colour camera's pixels per degree (rs2_fov rule)."""
    special = {((640, 240), (320, 180)), ((640, 480), (640, 360))}
    if ((depth.width, depth.height), (color.width, color.height)) in special:
        return False
    d, c = _pixels_per_degree(depth), _pixels_per_degree(color)
    return d[0] >= c[0] and d[1] >= c[1]


def _pixels_per_degree(intr: Intrinsics) -> tuple[float, float]:
    fov_x = np.degrees(
        np.arctan2(intr.cx + 0.5, intr.fx) + np.arctan2(intr.width - (intr.cx + 0.5), intr.fx)
    )
    fov_y = np.degrees(
        np.arctan2(intr.cy + 0.5, intr.fy) + np.arctan2(intr.height - (intr.cy + 0.5), intr.fy)
    )
    return intr.width / float(fov_x), intr.height / float(fov_y)


@lru_cache(maxsize=8)
def _corner_directions(
    intr: Intrinsics, rot: tuple[float, ...]
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.float32]]:
    """Return R (x, y, 1) at every pixel's top-left and bottom-right corner, each (3, h, w).

    Corner (x - 0.5, y - 0.5) is deprojected with the depth camera's distortion (if any).
    """
    u, v = np.meshgrid(
        np.arange(intr.width + 1, dtype=np.float64) - 0.5,
        np.arange(intr.height + 1, dtype=np.float64) - 0.5,
    )
    if intr.is_distorted:
        pts = np.stack([u.ravel(), v.ravel()], axis=1)[:, None, :]
        und = cv2.undistortPoints(
            pts,
            intr.matrix,
            np.asarray(intr.coeffs, np.float64),
            criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 20, 1e-9),
        ).reshape(intr.height + 1, intr.width + 1, 2)
        x, y = und[..., 0], und[..., 1]
    else:
        x, y = np.moveaxis(normalise(np.stack([u, v], axis=-1), intr), -1, 0)
    rays = np.stack([x, y, np.ones_like(x)])  # (3, h+1, w+1)
    dirs = np.einsum("ij,jhw->ihw", np.array(rot).reshape(3, 3), rays).astype(np.float32)
    top_left = np.ascontiguousarray(dirs[:, :-1, :-1])
    bottom_right = np.ascontiguousarray(dirs[:, 1:, 1:])
    top_left.setflags(write=False)  # cached: shared by every call
    bottom_right.setflags(write=False)
    return top_left, bottom_right
