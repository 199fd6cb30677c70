"""Small recordings with one plausible-but-bad property each (issue 16's adversarial inputs)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from capture.recording import Extrinsics, Intrinsics, RecordingWriter
from capture.recording import messages as m

W, H = 64, 48
FRAMES = 8
STEP_NS = 33_333_333
T0 = 1_000_000_000


@dataclass
class Case:
    """What to spoil in a small recording."""

    fx: float = 60.0
    size: tuple[int, int] = (W, H)
    extrinsics_translation: tuple[float, float, float] = (0.015, 0.0, 0.0)
    zero_depth_frames: int = 0  # the first n depth frames are all zero
    nan_depth_32f: bool = False  # aligned 32FC1 depth, all NaN
    quaternion: tuple[float, float, float, float] | None = None  # every ground-truth pose's
    same_stamps: bool = False  # every message stamped alike
    duplicate_messages: bool = False  # every message written twice
    depth_offset_ns: int = 0  # depth stamps shifted (never pairing when large)
    extra: dict[str, Any] = field(default_factory=dict)


def write_case(path: Path, case: Case) -> Path:
    """Write a recording of FRAMES frames of a textured plane with the case's flaw."""
    rng = np.random.default_rng(1)
    w, h = case.size
    texture = rng.integers(0, 255, (h + 4, w + 2 * FRAMES, 3), dtype=np.uint8)
    k = Intrinsics(w, h, case.fx, case.fx, w / 2 - 0.5, h / 2 - 0.5)
    times = 2 if case.duplicate_messages else 1
    with RecordingWriter(path) as writer:
        if not case.nan_depth_32f:
            rotation = [1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0]
            msg = {"rotation": rotation, "translation": list(case.extrinsics_translation)}
            writer.write_message(
                writer.namespace + m.EXTRINSICS, m.RS_EXTRINSICS, msg, stamp_ns=T0, log_ns=T0
            )
        for i in range(FRAMES):
            stamp = T0 if case.same_stamps else T0 + i * STEP_NS
            for _ in range(times):
                _frame(writer, case, k, texture, i, stamp)
    return path


def _frame(
    writer: RecordingWriter, case: Case, k: Intrinsics, texture: Any, i: int, stamp: int
) -> None:
    w, h = case.size
    color = np.ascontiguousarray(texture[2 : 2 + h, i : i + w])
    writer.write_color(color, stamp_ns=stamp, intrinsics=k)
    depth_stamp = stamp + case.depth_offset_ns
    if case.nan_depth_32f:
        data = np.full((h, w), np.nan, "<f4").tobytes()
        img = m.image(
            depth_stamp,
            m.COLOR_FRAME_ID,
            width=w,
            height=h,
            encoding="32FC1",
            step=4 * w,
            data=data,
        )
        writer.write_message(
            writer.namespace + m.ALIGNED_DEPTH_IMAGE, m.IMAGE, img, stamp_ns=depth_stamp,
            log_ns=stamp,
        )  # fmt: skip
        info = _camera_info(depth_stamp, k)
        writer.write_message(
            writer.namespace + m.ALIGNED_DEPTH_INFO, m.CAMERA_INFO, info, stamp_ns=depth_stamp,
            log_ns=stamp,
        )  # fmt: skip
    else:
        depth = np.full((h, w), 0 if i < case.zero_depth_frames else 2000, np.uint16)
        writer.write_depth(depth, stamp_ns=depth_stamp, intrinsics=k, aligned=False, log_ns=stamp)
    pose = np.eye(4)
    pose[0, 3] = 0.002 * i
    if case.quaternion is None:
        writer.write_ground_truth(stamp_ns=stamp, world_from_camera=pose)
    else:
        x, y, z, qw = case.quaternion
        msg = m.pose_stamped(stamp, m.WORLD_FRAME_ID, pose)
        msg["pose"] = {"position": {"x": 0.0, "y": 0.0, "z": 0.0}, "orientation": {
            "x": x, "y": y, "z": z, "w": qw}}  # fmt: skip
        writer.write_message(m.GT_POSE, m.POSE_STAMPED, msg, stamp_ns=stamp, log_ns=stamp)


def _camera_info(stamp: int, k: Intrinsics) -> dict[str, object]:
    return m.camera_info(
        stamp,
        m.COLOR_FRAME_ID,
        width=k.width,
        height=k.height,
        k=(k.fx, k.fy, k.cx, k.cy),
        distortion_model="plumb_bob",
        coeffs=k.coeffs,
    )


def spoil_extrinsics(values: list[float]) -> Extrinsics:
    """Return an Extrinsics from a column-major rotation (for tests of the checks)."""
    return Extrinsics.from_librealsense(values, [0.0, 0.0, 0.0])
