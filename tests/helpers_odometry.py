"""Rendered RGB-D frames with exact poses for odometry tests: a textured room, raycast by Open3D.

The room is a 6 x 2.7 x 6 m box with a few boxes standing in it. Every surface carries a smooth
solid (3-D) value-noise texture at three scales, so ORB finds corners everywhere and the colour of
a surface point does not depend on the viewpoint (brightness constancy holds). Colour and depth
are sampled at the pixel centre; depth is the exact z of that ray.
Camera frames are optical (x right, y down, z forward); the world has y pointing down as well.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
import numpy.typing as npt
import open3d as o3d
from scipy.spatial.transform import Rotation

from capture.recording import Extrinsics, Intrinsics, RgbdFrame

K_VGA = Intrinsics(640, 480, 525.0, 525.0, 319.5, 239.5)
ROOM_MIN = (-3.0, -1.2, -3.0)
ROOM_MAX = (3.0, 1.5, 3.0)
_BOXES = (  # (min corner, size) in metres
    ((-2.5, 0.7, -2.5), (1.2, 0.8, 0.8)),
    ((1.4, 0.3, -2.2), (0.9, 1.2, 0.9)),
    ((-0.6, 0.9, 1.8), (1.4, 0.6, 0.7)),
    ((2.2, -0.2, 1.0), (0.5, 1.7, 0.6)),
    ((-2.6, 0.1, 0.8), (0.6, 1.4, 1.2)),
)


@dataclass(frozen=True)
class RenderedFrame:
    """A rendered colour image, its depth and the true pose."""

    color: npt.NDArray[np.uint8]  # (H, W, 3) RGB
    depth_m: npt.NDArray[np.float32]  # (H, W), colour camera
    world_from_camera: npt.NDArray[np.float64]  # (4, 4)


@lru_cache(maxsize=1)
def _scene() -> o3d.t.geometry.RaycastingScene:
    scene = o3d.t.geometry.RaycastingScene()
    size = np.subtract(ROOM_MAX, ROOM_MIN)
    boxes = [(ROOM_MIN, tuple(size)), *_BOXES]
    for corner, extent in boxes:
        mesh = o3d.geometry.TriangleMesh.create_box(*extent)
        mesh.translate(np.asarray(corner, np.float64))
        scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
    return scene


def _hash_cells(cells: npt.NDArray[np.int64], salt: int) -> npt.NDArray[np.float32]:
    h = cells[:, 0] * 73856093 ^ cells[:, 1] * 19349663 ^ cells[:, 2] * 83492791 ^ salt * 2654435761
    h = (h ^ (h >> 13)) * 1274126177
    return ((h >> 7) & 1023).astype(np.float32) / 1023.0


def _value_noise(
    points: npt.NDArray[np.float64], scale: float, salt: int
) -> npt.NDArray[np.float32]:
    """Trilinearly interpolated random values on a lattice: smooth, like a real surface."""
    # An irrational offset keeps lattice planes off the room's walls.
    x = points / scale + 0.3183
    base = np.floor(x).astype(np.int64)
    frac = (x - base).astype(np.float32)
    frac = frac * frac * (3 - 2 * frac)  # smoothstep: no creases at the lattice planes
    out = np.zeros(len(points), np.float32)
    for corner in np.ndindex(2, 2, 2):
        weight = np.prod(np.where(np.array(corner) == 1, frac, 1 - frac), axis=1)
        out += weight * _hash_cells(base + np.array(corner), salt)
    return out


def solid_texture(points: npt.NDArray[np.float64]) -> npt.NDArray[np.float32]:
    """Return RGB in [0, 1] for world points (N, 3): smooth value noise at 4, 11 and 37 cm."""
    grey = np.zeros(len(points), np.float32)
    for scale, weight, salt in ((0.04, 0.45, 1), (0.11, 0.35, 2), (0.37, 0.2, 3)):
        grey += weight * _value_noise(points, scale, salt)
    tint = _value_noise(points, 0.23, 4) - 0.5
    rgb = np.stack([grey + 0.2 * tint, grey, grey - 0.2 * tint], axis=1)
    # Stretch the contrast: averaging octaves flattens it, and ORB needs corners.
    return np.clip((rgb - 0.5) * 2.2 + 0.5, 0.0, 1.0)


def _rays(
    world_from_camera: npt.NDArray[np.float64], intr: Intrinsics, offset: tuple[float, float]
) -> npt.NDArray[np.float32]:
    u, v = np.meshgrid(np.arange(intr.width) + offset[0], np.arange(intr.height) + offset[1])
    d = np.stack([(u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy, np.ones_like(u)], axis=-1)
    d_world = d.reshape(-1, 3) @ world_from_camera[:3, :3].T
    origin = np.broadcast_to(world_from_camera[:3, 3], d_world.shape)
    return np.concatenate([origin, d_world], axis=1).astype(np.float32)


def render(world_from_camera: npt.NDArray[np.float64], intr: Intrinsics = K_VGA) -> RenderedFrame:
    """Render the room from a camera pose: colour and exact depth at each pixel centre."""
    rays = _rays(world_from_camera, intr, (0.0, 0.0))
    t_hit = _scene().cast_rays(o3d.core.Tensor.from_numpy(rays))["t_hit"].numpy()
    # The ray's camera-frame z component is 1, so t_hit is the depth.
    t_hit = np.where(np.isfinite(t_hit), t_hit, 0.0)
    depth = t_hit.reshape(intr.height, intr.width).astype(np.float32)
    hits = rays[:, :3].astype(np.float64) + t_hit[:, None] * rays[:, 3:].astype(np.float64)
    color = np.clip(solid_texture(hits) * 255.0 + 0.5, 0, 255).astype(np.uint8)
    return RenderedFrame(color.reshape(intr.height, intr.width, 3), depth, world_from_camera)


def pose(
    position: tuple[float, float, float], *, yaw_deg: float = 0.0, pitch_deg: float = 0.0
) -> npt.NDArray[np.float64]:
    """Return world_from_camera at a position, turned by yaw (about y) then pitch (about x)."""
    out = np.eye(4)
    out[:3, :3] = Rotation.from_euler("yx", [yaw_deg, pitch_deg], degrees=True).as_matrix()
    out[:3, 3] = position
    return out


def loop_poses(
    n: int, *, radius_m: float = 0.6, turns: float = 1.0
) -> list[npt.NDArray[np.float64]]:
    """Return n poses on a circle that looks outward while walking, ending where it started."""
    poses = []
    for i in range(n):
        a = 2 * np.pi * turns * i / n
        position = (radius_m * np.sin(a), 0.05 * np.sin(3 * a), radius_m * np.cos(a))
        poses.append(
            pose(position, yaw_deg=float(np.degrees(a)) + 20.0, pitch_deg=5.0 * np.sin(2 * a))
        )
    return poses


def to_frame(
    rendered: RenderedFrame, *, index: int, intr: Intrinsics = K_VGA, stamp_ns: int | None = None
) -> RgbdFrame:
    """Wrap a rendered view as an aligned RgbdFrame at 30 frames/s."""
    return RgbdFrame(
        index=index,
        stamp_ns=stamp_ns if stamp_ns is not None else 1_000_000_000 + index * 33_333_333,
        color=rendered.color,
        depth_m=rendered.depth_m,
        color_intrinsics=intr,
        depth_intrinsics=intr,
        aligned=True,
    )


def rotation_deg(a: npt.NDArray[np.float64], b: npt.NDArray[np.float64]) -> float:
    """Return the angle in degrees of the rotation between two poses."""
    return float(np.degrees(Rotation.from_matrix(a[:3, :3].T @ b[:3, :3]).magnitude()))


K_QVGA = Intrinsics(320, 240, 262.5, 262.5, 159.75, 119.75)


def track_all(odometry: Any, frames: list[RgbdFrame]) -> list[Any]:
    """Track frames (depth already in the colour camera) and return the TrackResults."""
    return [odometry.track(f, f.depth_m) for f in frames]


def _rs_intrinsics(rs: Any, k: Intrinsics) -> Any:
    intr = rs.intrinsics()  # type: ignore[attr-defined]
    intr.width, intr.height, intr.fx, intr.fy, intr.ppx, intr.ppy = (
        k.width,
        k.height,
        k.fx,
        k.fy,
        k.cx,
        k.cy,
    )
    intr.model = rs.distortion.brown_conrady  # type: ignore[attr-defined]
    intr.coeffs = [0.0] * 5
    return intr


def rs_align(
    depth_mm: npt.NDArray[np.uint16],
    *,
    depth_k: Intrinsics,
    color_k: Intrinsics,
    color_from_depth: npt.NDArray[np.float64],
) -> npt.NDArray[np.uint16]:
    """Push one depth and one colour frame through a software device and rs.align(color)."""
    import pyrealsense2 as rs

    device = rs.software_device()
    sensors, profiles = [], []
    for uid, (name, stream, fmt, bpp, k) in enumerate(
        [
            ("Depth", rs.stream.depth, rs.format.z16, 2, depth_k),
            ("Color", rs.stream.color, rs.format.rgb8, 3, color_k),
        ]
    ):
        sensor = device.add_sensor(name)
        vs = rs.video_stream()
        vs.type, vs.index, vs.uid, vs.width, vs.height = stream, 0, uid, k.width, k.height
        vs.fps, vs.bpp, vs.fmt, vs.intrinsics = 30, bpp, fmt, _rs_intrinsics(rs, k)
        profiles.append(sensor.add_video_stream(vs))
        sensors.append(sensor)
    sensors[0].add_read_only_option(rs.option.depth_units, 0.001)
    extrinsics = rs.extrinsics()
    rot, trans = Extrinsics(color_from_depth).to_librealsense()
    extrinsics.rotation, extrinsics.translation = rot, trans
    profiles[0].register_extrinsics_to(profiles[1], extrinsics)
    device.create_matcher(rs.matchers.default)
    syncer = rs.syncer()
    for sensor, profile in zip(sensors, profiles, strict=True):
        sensor.open(profile)
        sensor.start(syncer)
    images: list[npt.NDArray[np.uint8] | npt.NDArray[np.uint16]] = [
        depth_mm,
        np.zeros((color_k.height, color_k.width, 3), np.uint8),
    ]
    for number in (1, 2):
        for sensor, profile, image in zip(sensors, profiles, images, strict=True):
            frame = rs.software_video_frame()
            frame.pixels, frame.bpp = (
                image.tobytes(),
                image.itemsize * (image.shape[2] if image.ndim == 3 else 1),
            )
            frame.stride = image.shape[1] * frame.bpp
            frame.timestamp, frame.frame_number = number * 33.3, number
            frame.domain = rs.timestamp_domain.hardware_clock
            frame.profile = profile.as_video_stream_profile()
            if image.ndim == 2:
                frame.depth_units = 0.001
            sensor.on_video_frame(frame)
    frames = syncer.wait_for_frames(5000)
    aligned = rs.align(rs.stream.color).process(frames)
    out = np.array(aligned.get_depth_frame().get_data(), np.uint16)
    for sensor in sensors:
        sensor.stop()
        sensor.close()
    return out
