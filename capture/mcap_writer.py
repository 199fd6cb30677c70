"""RecordingWriter: frames into a crash-safe ROS 2 MCAP as RECORDING.md specifies."""

from __future__ import annotations

import errno
import json
import logging
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from types import TracebackType
from typing import IO, Any

import cv2
import numpy as np
import numpy.typing as npt
from mcap.well_known import SchemaEncoding
from mcap_ros2._dynamic import serialize_dynamic

from capture import ros_msgs as m
from capture.errors import RecordingError
from capture.frames import Extrinsics, Intrinsics, RgbdFrame
from capture.mcap_chunked import COMPRESSIONS, McapChunkWriter

logger = logging.getLogger(__name__)


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


class RecordingWriter:
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
        if compression not in COMPRESSIONS:
            raise RecordingError(
                f"unknown compression {compression!r}; expected one of {list(COMPRESSIONS)}: {path}"
            )
        self.path = Path(path)
        self.namespace = namespace.rstrip("/")
        self.color_jpeg = color_jpeg
        self.jpeg_quality = jpeg_quality
        self._interval_ns = int(chunk_interval_s * 1e9)
        try:
            if stream is None:
                self.path.parent.mkdir(parents=True, exist_ok=True)
            self._stream: IO[bytes] = self.path.open("wb") if stream is None else stream
        except OSError as err:
            raise RecordingError(f"cannot create recording: {err.strerror}: {self.path}") from err
        self._mcap = McapChunkWriter(
            self._stream, compression=compression, chunk_size_bytes=chunk_size_bytes
        )
        self._encoders: dict[str, tuple[int, Callable[[Any], bytes]]] = {}
        self._channels: dict[str, int] = {}
        self._sequence: dict[str, int] = {}
        self._chunk_first_log_ns: int | None = None
        self._chunk_opened_mono = time.monotonic()
        self._finished = False
        self.counts: dict[str, int] = {}
        self.bytes_written = 0
        self._guard(lambda: self._mcap.start(profile="ros2", library="semreplay"))

    # -- low level -------------------------------------------------------------------------
    def _guard(self, write: Callable[[], object]) -> None:
        """Run a write, turning a full disk or other OS failure into a RecordingError."""
        try:
            write()
        except OSError as err:
            if err.errno == errno.ENOSPC:
                raise RecordingError(
                    f"disk full after {sum(self.counts.values())} messages; free space and record "
                    f"again (what was written so far replays): {self.path}"
                ) from err
            raise RecordingError(f"cannot write recording: {err.strerror}: {self.path}") from err

    def _channel(self, topic: str, datatype: str) -> tuple[int, Callable[[Any], bytes]]:
        if datatype not in self._encoders:
            text = m.MSG_DEFS[datatype]
            schema_id = self._mcap.register_schema(datatype, SchemaEncoding.ROS2, text.encode())
            # The dynamic serializer passes uint8[] payloads through as one bytes copy, so it
            # costs ~0.03 ms per 640x480 image: no hand-written CDR is needed for speed.
            self._encoders[datatype] = (schema_id, serialize_dynamic(datatype, text)[datatype])
        schema_id, encoder = self._encoders[datatype]
        if topic not in self._channels:
            self._channels[topic] = self._mcap.register_channel(topic, "cdr", schema_id)
        return self._channels[topic], encoder

    def write_message(
        self, topic: str, datatype: str, msg: Mapping[str, Any], *, stamp_ns: int, log_ns: int
    ) -> None:
        """Write one message; `stamp_ns` is the publish time, `log_ns` the receive time."""
        if self._finished:
            raise RecordingError(f"recording already finished; cannot write {topic}: {self.path}")
        channel_id, encoder = self._channel(topic, datatype)
        data = encoder(msg)
        first = self._chunk_first_log_ns
        if first is not None and log_ns - first >= self._interval_ns:
            self.flush()  # so that a chunk never spans the interval of recording time
        seq = self._sequence.get(topic, 0)
        self._sequence[topic] = seq + 1
        self._guard(
            lambda: self._mcap.add_message(
                channel_id, log_ns=log_ns, publish_ns=stamp_ns, sequence=seq, data=data
            )
        )
        self.counts[topic] = self.counts.get(topic, 0) + 1
        self.bytes_written += len(data)
        if self._chunk_first_log_ns is None:
            self._chunk_first_log_ns = log_ns
        self.flush_if_due()

    def flush_if_due(self) -> None:
        """Close the open chunk if it has been open for the chunk interval of wall time."""
        if (time.monotonic() - self._chunk_opened_mono) * 1e9 >= self._interval_ns:
            self.flush()

    def flush(self) -> None:
        """Close the open chunk and hand it to the operating system."""
        if not self._finished:
            self._guard(self._mcap.flush)
        self._chunk_first_log_ns = None
        self._chunk_opened_mono = time.monotonic()

    # -- records of RECORDING.md -----------------------------------------------------------
    def write_metadata(self, name: str, data: Mapping[str, object]) -> None:
        """Write an MCAP metadata record; values are stored as strings (JSON for non-strings)."""
        text = {k: v if isinstance(v, str) else json.dumps(v) for k, v in data.items()}
        self._guard(lambda: self._mcap.add_metadata(name, text))

    def write_attachment(self, name: str, data: bytes, *, media_type: str, log_ns: int) -> None:
        """Write an MCAP attachment (e.g. the ground-truth cloud)."""
        self._guard(
            lambda: self._mcap.add_attachment(name, data, media_type=media_type, log_ns=log_ns)
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

    def finish(self, capture_summary: Mapping[str, object] | None = None) -> None:
        """Write the final metadata, the summary and the footer, and close the file."""
        if self._finished:
            return
        if capture_summary is not None:
            self.write_metadata("capture", capture_summary)
        self._guard(self._mcap.finish)
        self._finished = True
        self._stream.close()
        logger.debug("finished %s: %s", self.path, self.counts)

    def close_unfinished(self) -> None:
        """Close the file without a summary, as a crash would (for tests and failure paths)."""
        if not self._finished:
            self._finished = True
            try:
                self._stream.close()
            except OSError:  # the buffered tail cannot reach a full disk; complete chunks did
                logger.debug("closing %s lost its unflushed tail", self.path)

    @property
    def finished(self) -> bool:
        """Return whether the file is closed (finished or abandoned)."""
        return self._finished

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if exc_type is None:
            self.finish()
            return
        # Ctrl-C and errors still leave a finished file where the disk allows it.
        try:
            self.finish()
        except Exception:
            self.close_unfinished()
