"""RecordingWriter: frames into a crash-safe ROS 2 MCAP as RECORDING.md specifies."""

from __future__ import annotations

import json
import logging
import socket
from collections.abc import Mapping
from datetime import datetime
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import IO

import cv2
import numpy as np
import numpy.typing as npt

from capture.errors import RecordingError
from capture.recording import messages as m
from capture.recording.frames import Extrinsics, Intrinsics, RgbdFrame
from capture.recording.ros_writer import McapMessageWriter

logger = logging.getLogger(__name__)


def tool_version() -> str:
    """Return the installed version of semreplay."""
    try:
        return version("semreplay")
    except PackageNotFoundError:
        return "0+unknown"


def capture_record(
    tool: str,
    *,
    source: str,
    config: Mapping[str, object],
    start_time: str | None = None,
    host: str | None = None,
    **extra: object,
) -> dict[str, object]:
    """Return the `capture` metadata record of RECORDING.md (the one builder of it).

    Args:
        tool: the command that wrote the recording, e.g. "semreplay-capture record".
        source: what was recorded: "live", a file, a dataset folder, "simulator".
        config: the effective capture settings.
        start_time: ISO 8601 start of the capture (default: now, local time).
        host: the machine (default: this host's name).
        **extra: more fields, e.g. frames_written and frames_dropped at the end of a capture.
    """
    now = datetime.now().astimezone().isoformat(timespec="seconds")
    return {
        "tool": tool,
        "version": tool_version(),
        "source": source,
        "config": dict(config),
        "host": socket.gethostname() if host is None else host,
        "start_time": now if start_time is None else start_time,
        **extra,
    }


def camera_info(stamp_ns: int, frame_id: str, k: Intrinsics) -> dict[str, object]:
    """Return a sensor_msgs/CameraInfo dict for intrinsics."""
    return m.camera_info(
        stamp_ns,
        frame_id,
        width=k.width,
        height=k.height,
        k=(k.fx, k.fy, k.cx, k.cy),
        distortion_model=k.distortion_model,
        coeffs=k.coeffs,
    )


class RecordingWriter(McapMessageWriter):
    """Write colour, depth, calibration and ground truth to a ROS 2 MCAP file.

    A chunk is closed and flushed to the operating system at least every `chunk_interval_s`
    of recording (and of wall time), so a killed process loses at most that much.
    """

    def __init__(
        self,
        path: Path,
        *,
        namespace: str = m.DEFAULT_NAMESPACE,
        compression: str = "zstd",
        chunk_interval_s: float = 1.0,
        chunk_size_bytes: int = 64 * 1024 * 1024,
        color_jpeg: bool = False,
        jpeg_quality: int = 90,
        stream: IO[bytes] | None = None,
    ) -> None:
        """Create the file at `path` (or write to `stream`, then `path` only names it)."""
        self.namespace = namespace.rstrip("/")
        self.color_jpeg = color_jpeg
        self.jpeg_quality = jpeg_quality
        super().__init__(
            path,
            compression=compression,
            chunk_interval_s=chunk_interval_s,
            chunk_size_bytes=chunk_size_bytes,
            stream=stream,
        )

    def write_calibration(self, depth_to_color: Extrinsics, *, stamp_ns: int) -> None:
        """Write the depth->colour extrinsics and the matching /tf_static (once, first)."""
        rotation, translation = depth_to_color.to_librealsense()
        self.write_message(
            self.namespace + m.EXTRINSICS,
            m.RS_EXTRINSICS,
            {"rotation": rotation, "translation": translation},
            stamp_ns=stamp_ns,
            log_ns=stamp_ns,
        )
        msg = m.tf_static(depth_to_color.color_from_depth, stamp_ns)
        self.write_message(m.TF_STATIC, m.TF_MESSAGE, msg, stamp_ns=stamp_ns, log_ns=stamp_ns)

    def write_color(
        self,
        color: npt.NDArray[np.uint8],
        *,
        stamp_ns: int,
        intrinsics: Intrinsics,
        log_ns: int | None = None,
        metadata: Mapping[str, object] | None = None,
    ) -> None:
        """Write a colour image (H, W, 3) RGB with its camera_info (and metadata)."""
        log = stamp_ns if log_ns is None else log_ns
        if color.ndim != 3 or color.shape[2] != 3 or color.dtype != np.uint8:
            raise RecordingError(
                f"colour must be (H, W, 3) uint8, got {color.shape} {color.dtype}: {self.path}"
            )
        if self.color_jpeg:
            topic, datatype, msg = self._jpeg_message(color, stamp_ns)
        else:
            h, w = color.shape[:2]
            topic, datatype = self.namespace + m.COLOR_IMAGE, m.IMAGE
            data = np.ascontiguousarray(color).tobytes()
            msg = m.image(
                stamp_ns,
                m.COLOR_FRAME_ID,
                width=w,
                height=h,
                encoding="rgb8",
                step=3 * w,
                data=data,
            )
        self.write_message(topic, datatype, msg, stamp_ns=stamp_ns, log_ns=log)
        info = camera_info(stamp_ns, m.COLOR_FRAME_ID, intrinsics)
        self.write_message(
            self.namespace + m.COLOR_INFO, m.CAMERA_INFO, info, stamp_ns=stamp_ns, log_ns=log
        )
        if metadata is not None:
            self._write_rs_metadata(m.COLOR_METADATA, m.COLOR_FRAME_ID, metadata, stamp_ns, log)

    def _jpeg_message(
        self, color: npt.NDArray[np.uint8], stamp_ns: int
    ) -> tuple[str, str, dict[str, object]]:
        bgr = cv2.cvtColor(color, cv2.COLOR_RGB2BGR)
        ok, jpg = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, self.jpeg_quality])
        if not ok:
            raise RecordingError(
                f"JPEG encoding of a {color.shape} colour frame failed: {self.path}"
            )
        msg: dict[str, object] = {
            "header": m.header(stamp_ns, m.COLOR_FRAME_ID),
            "format": "rgb8; jpeg compressed bgr8",
            "data": jpg.tobytes(),
        }
        return self.namespace + m.COLOR_COMPRESSED, m.COMPRESSED_IMAGE, msg

    def write_depth(
        self,
        depth_mm: npt.NDArray[np.uint16],
        *,
        stamp_ns: int,
        intrinsics: Intrinsics,
        aligned: bool = False,
        log_ns: int | None = None,
        metadata: Mapping[str, object] | None = None,
    ) -> None:
        """Write a 16UC1 depth image in millimetres (0 = none) with its camera_info."""
        log = stamp_ns if log_ns is None else log_ns
        if depth_mm.ndim != 2 or depth_mm.dtype != np.uint16:
            raise RecordingError(
                f"depth must be (H, W) uint16 mm, got {depth_mm.shape} {depth_mm.dtype}: "
                f"{self.path}"
            )
        h, w = depth_mm.shape
        image_topic, info_topic, frame_id = (
            (m.ALIGNED_DEPTH_IMAGE, m.ALIGNED_DEPTH_INFO, m.COLOR_FRAME_ID)
            if aligned
            else (m.DEPTH_IMAGE, m.DEPTH_INFO, m.DEPTH_FRAME_ID)
        )
        data = np.ascontiguousarray(depth_mm, dtype="<u2").tobytes()
        msg = m.image(
            stamp_ns, frame_id, width=w, height=h, encoding="16UC1", step=2 * w, data=data
        )
        self.write_message(
            self.namespace + image_topic, m.IMAGE, msg, stamp_ns=stamp_ns, log_ns=log
        )
        info = camera_info(stamp_ns, frame_id, intrinsics)
        self.write_message(
            self.namespace + info_topic, m.CAMERA_INFO, info, stamp_ns=stamp_ns, log_ns=log
        )
        if metadata is not None:
            self._write_rs_metadata(m.DEPTH_METADATA, frame_id, metadata, stamp_ns, log)

    def _write_rs_metadata(
        self, suffix: str, frame_id: str, data: Mapping[str, object], stamp_ns: int, log_ns: int
    ) -> None:
        msg = {"header": m.header(stamp_ns, frame_id), "json_data": json.dumps(dict(data))}
        topic = self.namespace + suffix
        self.write_message(topic, m.RS_METADATA, msg, stamp_ns=stamp_ns, log_ns=log_ns)

    def write_ground_truth(
        self,
        *,
        stamp_ns: int,
        world_from_camera: npt.NDArray[np.float64] | None = None,
        labels: npt.NDArray[np.uint8] | None = None,
        instances: npt.NDArray[np.uint16] | None = None,
        log_ns: int | None = None,
    ) -> None:
        """Write the ground-truth pose (world_from_color_optical), label and instance images."""
        log = stamp_ns if log_ns is None else log_ns
        if world_from_camera is not None:
            msg = m.pose_stamped(stamp_ns, m.WORLD_FRAME_ID, world_from_camera)
            self.write_message(m.GT_POSE, m.POSE_STAMPED, msg, stamp_ns=stamp_ns, log_ns=log)
        for topic, img, encoding, dtype in (
            (m.GT_LABELS, labels, "mono8", np.dtype(np.uint8)),
            (m.GT_INSTANCES, instances, "mono16", np.dtype("<u2")),
        ):
            if img is None:
                continue
            h, w = img.shape
            data = np.ascontiguousarray(img, dtype=dtype).tobytes()
            msg = m.image(
                stamp_ns,
                m.COLOR_FRAME_ID,
                width=w,
                height=h,
                encoding=encoding,
                step=w * dtype.itemsize,
                data=data,
            )
            self.write_message(topic, m.IMAGE, msg, stamp_ns=stamp_ns, log_ns=log)

    def write_frame(self, frame: RgbdFrame, *, log_ns: int | None = None) -> None:
        """Write a whole frame value (colour, depth in mm, ground truth)."""
        depth_mm = np.round(np.clip(frame.depth_m, 0.0, 65.535) * 1000.0).astype(np.uint16)
        stamp = frame.stamp_ns
        self.write_color(
            frame.color, stamp_ns=stamp, intrinsics=frame.color_intrinsics, log_ns=log_ns
        )
        self.write_depth(
            depth_mm,
            stamp_ns=stamp,
            intrinsics=frame.depth_intrinsics,
            aligned=frame.aligned,
            log_ns=log_ns,
        )
        gt = frame.ground_truth
        if gt is not None:
            self.write_ground_truth(
                stamp_ns=stamp,
                world_from_camera=gt.world_from_camera,
                labels=gt.labels,
                instances=gt.instances,
                log_ns=log_ns,
            )
