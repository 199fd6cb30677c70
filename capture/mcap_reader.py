"""RecordingReader: synchronised RGB-D frames out of any recording that follows RECORDING.md."""

from __future__ import annotations

import json
import logging
import struct
from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import IO, Any

import cv2
import numpy as np
import numpy.typing as npt
from mcap.exceptions import McapError
from mcap.reader import SeekingReader
from mcap.records import Attachment, Channel, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap_ros2.decoder import DecoderFactory
from scipy.spatial.transform import Rotation

from capture import ros_msgs as m
from capture.errors import RecordingError
from capture.frames import Extrinsics, GroundTruth, Intrinsics, RgbdFrame

logger = logging.getLogger(__name__)

MCAP_MAGIC = b"\x89MCAP0\r\n"
_COLOR_ENCODINGS = {"rgb8": (3, False), "bgr8": (3, True), "rgba8": (4, False), "bgra8": (4, True)}


@dataclass(frozen=True, slots=True)
class TopicInfo:
    """A topic of a recording: its message type and how many messages it has."""

    name: str
    datatype: str
    count: int


@dataclass(slots=True)
class _Topics:
    color: str
    color_info: str
    depth: str
    depth_info: str | None
    aligned: bool
    extrinsics: str | None
    color_metadata: str | None = None
    ground_truth: dict[str, str] = field(default_factory=dict)


@dataclass(slots=True)
class _Pending:
    stamp_ns: int
    log_ns: int
    color: npt.NDArray[np.uint8]
    metadata: dict[str, str] = field(default_factory=dict)


def intrinsics_from_msg(msg: Any) -> Intrinsics:
    """Return Intrinsics from a decoded sensor_msgs/CameraInfo."""
    k = list(msg.k)
    return Intrinsics(
        width=int(msg.width),
        height=int(msg.height),
        fx=float(k[0]),
        fy=float(k[4]),
        cx=float(k[2]),
        cy=float(k[5]),
        distortion_model=str(msg.distortion_model) or "plumb_bob",
        coeffs=tuple(float(c) for c in msg.d),
    )


def pose_from_msg(msg: Any) -> npt.NDArray[np.float64]:
    """Return the 4x4 matrix of a decoded geometry_msgs/PoseStamped."""
    p, q = msg.pose.position, msg.pose.orientation
    out = np.eye(4)
    out[:3, :3] = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
    out[:3, 3] = [p.x, p.y, p.z]
    return out


class RecordingReader:
    """Read a recording as a stream of synchronised `RgbdFrame` values.

    Usage: `with RecordingReader(path) as rec: for frame in rec.frames(): ...`.
    Recordings that were never finished (a killed writer) replay every complete chunk.
    """

    def __init__(
        self,
        path: Path,
        *,
        sync_tolerance_ns: int = 20_000_000,
        prefer_aligned: bool = True,
    ) -> None:
        self.path = Path(path)
        self.sync_tolerance_ns = sync_tolerance_ns
        self.prefer_aligned = prefer_aligned
        self.finished = False
        self.topics: dict[str, TopicInfo] = {}
        self.metadata: dict[str, dict[str, str]] = {}
        self.attachment_names: list[str] = []
        self.start_ns = 0
        self.end_ns = 0
        self.unpaired_color_frames = 0
        self._stream: IO[bytes] | None = None
        self._decoders = DecoderFactory()
        self._attachments: dict[str, bytes] = {}

    # -- opening ---------------------------------------------------------------------------
    def __enter__(self) -> RecordingReader:
        self.open()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def open(self) -> None:
        """Open the file, read its summary (or scan it if unfinished) and find its topics."""
        try:
            self._stream = self.path.open("rb")
        except OSError as err:
            raise RecordingError(f"cannot open recording: {err.strerror}: {self.path}") from err
        if self._stream.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            self.close()
            raise RecordingError(f"not an MCAP file (bad magic bytes); expected a .mcap recording: {self.path}")
        self._stream.seek(0)
        if not self._read_summary():
            self._scan_unfinished()
        self._topics = self._discover()

    def close(self) -> None:
        """Close the file."""
        if self._stream is not None:
            self._stream.close()
            self._stream = None

    def _read_summary(self) -> bool:
        assert self._stream is not None
        try:
            reader = SeekingReader(self._stream)
            summary = reader.get_summary()
        except (McapError, struct.error, ValueError, OSError):
            return False
        if summary is None or summary.statistics is None:
            return False
        counts = summary.statistics.channel_message_counts
        for cid, channel in summary.channels.items():
            schema = summary.schemas.get(channel.schema_id)
            self._add_topic(channel, schema, counts.get(cid, 0))
        self.start_ns = summary.statistics.message_start_time
        self.end_ns = summary.statistics.message_end_time
        for meta in reader.iter_metadata():
            self.metadata.setdefault(meta.name, {}).update(meta.metadata)
        self.attachment_names = [a.name for a in summary.attachment_indexes]
        self.finished = True
        return True

    def _add_topic(self, channel: Channel, schema: Schema | None, count: int) -> None:
        datatype = schema.name if schema is not None else ""
        old = self.topics.get(channel.topic)
        self.topics[channel.topic] = TopicInfo(channel.topic, datatype, count + (old.count if old else 0))

    def _scan_unfinished(self) -> None:
        counts: dict[int, int] = {}
        channels: dict[int, Channel] = {}
        schemas: dict[int, Schema] = {}
        times: list[int] = []
        for record in self._records():
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, Message):
                counts[record.channel_id] = counts.get(record.channel_id, 0) + 1
                times.append(record.log_time)
            elif isinstance(record, Metadata):
                self.metadata.setdefault(record.name, {}).update(record.metadata)
            elif isinstance(record, Attachment):
                self.attachment_names.append(record.name)
                self._attachments[record.name] = record.data
        for cid, channel in channels.items():
            self._add_topic(channel, schemas.get(channel.schema_id), counts.get(cid, 0))
        if times:
            self.start_ns, self.end_ns = min(times), max(times)
        self.finished = False

    def _records(self) -> Iterator[Any]:
        """Stream every complete record; a truncated tail (killed writer) ends the stream."""
        assert self._stream is not None
        self._stream.seek(0)
        try:
            yield from StreamReader(self._stream).records
        except (McapError, struct.error, EOFError, ValueError):
            return
        except Exception as err:  # zstd/lz4 errors on a half-written chunk have no common base
            logger.debug("recording ends in an incomplete record: %s", err)

    def _discover(self) -> _Topics:
        by_suffix: dict[str, list[str]] = {}
        for name in self.topics:
            for suffix in (
                m.COLOR_IMAGE, m.COLOR_COMPRESSED, m.COLOR_INFO, m.DEPTH_IMAGE, m.DEPTH_INFO,
                m.ALIGNED_DEPTH_IMAGE, m.ALIGNED_DEPTH_INFO, m.EXTRINSICS, m.COLOR_METADATA,
            ):  # fmt: skip
                if name.endswith(suffix):
                    by_suffix.setdefault(suffix, []).append(name)
        found = ", ".join(f"{t.name} ({t.datatype})" for t in self.topics.values()) or "none"

        def pick(suffix: str, datatype: str) -> str | None:
            names = [n for n in by_suffix.get(suffix, []) if self.topics[n].datatype == datatype]
            return min(names, key=len) if names else None

        color = pick(m.COLOR_IMAGE, m.IMAGE) or pick(m.COLOR_COMPRESSED, m.COMPRESSED_IMAGE)
        if color is None:
            raise RecordingError(
                f"no colour topic (sensor_msgs/msg/Image '*{m.COLOR_IMAGE}' or CompressedImage "
                f"'*{m.COLOR_COMPRESSED}'); found: {found}; is this an RGB-D recording?: {self.path}"
            )
        ns = color[: color.rindex("/color/")]
        aligned_topic = pick(m.ALIGNED_DEPTH_IMAGE, m.IMAGE)
        raw_topic = pick(m.DEPTH_IMAGE, m.IMAGE)
        use_aligned = aligned_topic is not None and (self.prefer_aligned or raw_topic is None)
        depth = aligned_topic if use_aligned else raw_topic
        if depth is None:
            raise RecordingError(
                f"no depth topic ('{ns}{m.DEPTH_IMAGE}' or '{ns}{m.ALIGNED_DEPTH_IMAGE}'); "
                f"found: {found}: {self.path}"
            )
        color_info = pick(m.COLOR_INFO, m.CAMERA_INFO)
        if color_info is None:
            raise RecordingError(
                f"no colour camera_info ('{ns}{m.COLOR_INFO}', sensor_msgs/msg/CameraInfo); "
                f"found: {found}: {self.path}"
            )
        depth_info = pick(m.ALIGNED_DEPTH_INFO if use_aligned else m.DEPTH_INFO, m.CAMERA_INFO)
        extrinsics = pick(m.EXTRINSICS, m.RS_EXTRINSICS)
        if not use_aligned and (extrinsics is None or depth_info is None):
            missing = "depth->colour extrinsics" if extrinsics is None else "depth camera_info"
            raise RecordingError(
                f"unaligned depth '{depth}' needs the {missing} to register it to colour, and the "
                f"recording has none; record with aligned depth or with the calibration: {self.path}"
            )
        gt = {
            key: topic
            for key, topic in (("pose", m.GT_POSE), ("labels", m.GT_LABELS), ("instances", m.GT_INSTANCES))
            if topic in self.topics
        }
        return _Topics(
            color, color_info, depth, depth_info, use_aligned, extrinsics,
            pick(m.COLOR_METADATA, m.RS_METADATA), gt,
        )  # fmt: skip

    # -- properties --------------------------------------------------------------------------
    def __len__(self) -> int:
        """Return the number of colour frames in the recording."""
        return self.topics[self._topics.color].count

    @property
    def aligned(self) -> bool:
        """Return whether the depth the reader replays is already in the colour camera."""
        return self._topics.aligned

    @property
    def has_ground_truth(self) -> bool:
        """Return whether the recording carries a ground-truth pose topic."""
        return "pose" in self._topics.ground_truth

    @property
    def has_ground_truth_labels(self) -> bool:
        """Return whether the recording carries ground-truth label images."""
        return "labels" in self._topics.ground_truth

    @property
    def depth_scale_m(self) -> float:
        """Return metres per depth unit: the `device` record's depth_scale_m, else 1 mm."""
        text = self.metadata.get("device", {}).get("depth_scale_m")
        return float(text) if text else 0.001

    @property
    def duration_ns(self) -> int:
        """Return the time between the first and the last message."""
        return self.end_ns - self.start_ns

    def attachment(self, name: str) -> bytes | None:
        """Return the data of the named attachment, or None when the recording has none."""
        if name in self._attachments:
            return self._attachments[name]
        if not self.finished or name not in self.attachment_names:
            return None
        assert self._stream is not None
        self._stream.seek(0)
        for att in SeekingReader(self._stream).iter_attachments():
            if att.name == name:
                return att.data
        return None

    # -- frames ----------------------------------------------------------------------------
    def _messages(self, topics: list[str]) -> Iterator[tuple[str, Any, int]]:
        """Yield (topic, decoded message, log_ns) in log-time order."""
        assert self._stream is not None
        wanted = set(topics)
        if self.finished:
            self._stream.seek(0)
            reader = SeekingReader(self._stream, decoder_factories=[self._decoders])
            for _, channel, message, decoded in reader.iter_decoded_messages(
                topics=topics, log_time_order=True
            ):
                yield channel.topic, decoded, message.log_time
            return
        schemas: dict[int, Schema] = {}
        channels: dict[int, Channel] = {}
        for record in self._records():
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, Message):
                channel = channels[record.channel_id]
                if channel.topic in wanted:
                    decoder = self._decoders.decoder_for(
                        channel.message_encoding, schemas.get(channel.schema_id)
                    )
                    if decoder is not None:
                        yield channel.topic, decoder(record.data), record.log_time

    def frames(self, *, start_ns: int | None = None, end_ns: int | None = None) -> Iterator[RgbdFrame]:
        """Yield synchronised frames whose colour stamp lies in [start_ns, end_ns]."""
        t = self._topics
        topics = [t.color, t.color_info, t.depth, *t.ground_truth.values()]
        topics += [x for x in (t.depth_info, t.extrinsics, t.color_metadata) if x is not None]
        state = _SyncState(self, t)
        emitted = 0
        for topic, msg, log_ns in self._messages(topics):
            for frame in state.push(topic, msg, log_ns):
                if (start_ns is None or frame.stamp_ns >= start_ns) and (end_ns is None or frame.stamp_ns <= end_ns):
                    yield _reindex(frame, emitted)
                    emitted += 1
        for frame in state.drain():
            if (start_ns is None or frame.stamp_ns >= start_ns) and (end_ns is None or frame.stamp_ns <= end_ns):
                yield _reindex(frame, emitted)
                emitted += 1
        self.unpaired_color_frames = state.unpaired
        if state.unpaired:
            logger.warning(
                "%d colour frames had no depth within %.0f ms and were skipped: %s",
                state.unpaired, self.sync_tolerance_ns / 1e6, self.path,
            )  # fmt: skip
        if not self.finished:
            logger.warning(
                "recording was not finished (writer killed?); recovered %d frames: %s", emitted, self.path
            )

    # -- decoding --------------------------------------------------------------------------
    def decode_color(self, topic: str, msg: Any) -> npt.NDArray[np.uint8]:
        """Return an (H, W, 3) RGB image from a decoded Image or CompressedImage."""
        if not hasattr(msg, "encoding"):  # CompressedImage
            bgr = cv2.imdecode(np.frombuffer(bytes(msg.data), np.uint8), cv2.IMREAD_COLOR)
            if bgr is None:
                raise RecordingError(f"'{topic}' holds an undecodable {msg.format!r} image: {self.path}")
            return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
        enc = str(msg.encoding).lower()
        if enc not in _COLOR_ENCODINGS:
            raise RecordingError(
                f"'{topic}' has encoding {msg.encoding!r}; expected one of {sorted(_COLOR_ENCODINGS)}: {self.path}"
            )
        channels, bgr_order = _COLOR_ENCODINGS[enc]
        img = _image_array(topic, msg, np.dtype(np.uint8), channels, self.path)[..., :3]
        return np.ascontiguousarray(img[..., ::-1] if bgr_order else img)

    def decode_depth(self, topic: str, msg: Any) -> npt.NDArray[np.float32]:
        """Return depth in metres (0 = none) from a decoded 16UC1/mono16/32FC1 Image."""
        enc = str(msg.encoding).upper()
        if enc in ("16UC1", "MONO16"):
            raw = _image_array(topic, msg, np.dtype(">u2" if msg.is_bigendian else "<u2"), 1, self.path)
            return (raw.astype(np.float32) * np.float32(self.depth_scale_m)).astype(np.float32)
        if enc == "32FC1":
            d = _image_array(topic, msg, np.dtype(">f4" if msg.is_bigendian else "<f4"), 1, self.path)
            return np.nan_to_num(d.astype(np.float32), nan=0.0, posinf=0.0, neginf=0.0)
        raise RecordingError(
            f"'{topic}' has depth encoding {msg.encoding!r}; expected 16UC1 (mm), mono16 or 32FC1 (m): {self.path}"
        )


def _image_array(
    topic: str, msg: Any, dtype: np.dtype[Any], channels: int, path: Path
) -> npt.NDArray[Any]:
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    data = bytes(msg.data) if not isinstance(msg.data, bytes | bytearray | memoryview) else msg.data
    row = w * channels * dtype.itemsize
    if step < row or len(data) < step * h:
        raise RecordingError(
            f"'{topic}' image of {w}x{h} {msg.encoding} needs {row * h} bytes (step {row}), "
            f"found {len(data)} bytes with step {step}: {path}"
        )
    rows = np.frombuffer(data, np.uint8, count=step * h).reshape(h, step)[:, :row]
    arr = np.ascontiguousarray(rows).view(dtype).reshape(h, w, channels)
    return arr[..., 0] if channels == 1 else arr


def _reindex(frame: RgbdFrame, index: int) -> RgbdFrame:
    if frame.index == index:
        return frame
    return RgbdFrame(
        index, frame.stamp_ns, frame.color, frame.depth_m, frame.color_intrinsics,
        frame.depth_intrinsics, frame.aligned, frame.depth_to_color, frame.ground_truth, frame.metadata,
    )  # fmt: skip


class _SyncState:
    """Pairs colour with the nearest depth by stamp, holding a short window of messages."""

    WINDOW_NS = 300_000_000  # everything of one frame arrives within this much log time

    def __init__(self, reader: RecordingReader, topics: _Topics) -> None:
        self.r = reader
        self.t = topics
        self.pending: deque[_Pending] = deque()
        self.depths: deque[tuple[int, npt.NDArray[np.float32]]] = deque(maxlen=64)
        self.color_info: Intrinsics | None = None
        self.depth_info: Intrinsics | None = None
        self.extrinsics: Extrinsics | None = None
        self.gt: dict[str, dict[int, Any]] = {key: {} for key in topics.ground_truth}
        self.metadata: dict[int, dict[str, str]] = {}
        self.unpaired = 0

    def push(self, topic: str, msg: Any, log_ns: int) -> Iterator[RgbdFrame]:
        t = self.t
        if topic == t.color:
            stamp = m.stamp_ns_of(msg.header.stamp)
            self.pending.append(_Pending(stamp, log_ns, self.r.decode_color(topic, msg)))
        elif topic == t.depth:
            self.depths.append((m.stamp_ns_of(msg.header.stamp), self.r.decode_depth(topic, msg)))
        elif topic == t.color_info:
            self.color_info = intrinsics_from_msg(msg)
        elif topic == t.depth_info:
            self.depth_info = intrinsics_from_msg(msg)
        elif topic == t.extrinsics:
            self.extrinsics = Extrinsics.from_librealsense(msg.rotation, msg.translation)
        elif topic == t.color_metadata:
            self.metadata[m.stamp_ns_of(msg.header.stamp)] = _json_dict(msg.json_data)
        else:
            for key, gt_topic in t.ground_truth.items():
                if topic == gt_topic:
                    self.gt[key][m.stamp_ns_of(msg.header.stamp)] = msg
        while self.pending and log_ns - self.pending[0].log_ns > self.WINDOW_NS:
            frame = self._emit(self.pending.popleft())
            if frame is not None:
                yield frame

    def drain(self) -> Iterator[RgbdFrame]:
        while self.pending:
            frame = self._emit(self.pending.popleft())
            if frame is not None:
                yield frame

    def _emit(self, p: _Pending) -> RgbdFrame | None:
        r, t = self.r, self.t
        if self.color_info is None:
            raise RecordingError(f"colour frame at {p.stamp_ns} ns has no camera_info on '{t.color_info}': {r.path}")
        best = min(self.depths, key=lambda d: abs(d[0] - p.stamp_ns), default=None)
        if best is None or abs(best[0] - p.stamp_ns) > r.sync_tolerance_ns:
            self.unpaired += 1
            return None
        depth_info = self.depth_info or self.color_info
        _check_size(t.color, p.color.shape[:2], self.color_info, r.path)
        _check_size(t.depth, best[1].shape, depth_info, r.path)
        if not t.aligned and self.extrinsics is None:
            raise RecordingError(f"no '{t.extrinsics}' message before the first frame: {r.path}")
        return RgbdFrame(
            index=0,
            stamp_ns=p.stamp_ns,
            color=p.color,
            depth_m=best[1],
            color_intrinsics=self.color_info,
            depth_intrinsics=depth_info,
            aligned=t.aligned,
            depth_to_color=None if t.aligned else self.extrinsics,
            ground_truth=self._ground_truth(p.stamp_ns),
            metadata=self.metadata.pop(p.stamp_ns, {}),
        )

    def _ground_truth(self, stamp_ns: int) -> GroundTruth | None:
        if not self.gt:
            return None
        pose = self.gt.get("pose", {}).pop(stamp_ns, None)
        labels = self.gt.get("labels", {}).pop(stamp_ns, None)
        instances = self.gt.get("instances", {}).pop(stamp_ns, None)
        for table in self.gt.values():  # drop ground truth of skipped frames
            for old in [s for s in table if s < stamp_ns]:
                del table[old]
        return GroundTruth(
            world_from_camera=None if pose is None else pose_from_msg(pose),
            labels=None if labels is None else _image_array(self.t.ground_truth["labels"], labels, np.dtype(np.uint8), 1, self.r.path),
            instances=None if instances is None else _image_array(self.t.ground_truth["instances"], instances, np.dtype("<u2"), 1, self.r.path),
        )  # fmt: skip


def _check_size(topic: str, shape: tuple[int, ...], k: Intrinsics, path: Path) -> None:
    if (shape[0], shape[1]) != (k.height, k.width):
        raise RecordingError(
            f"'{topic}' image is {shape[1]}x{shape[0]} but its camera_info says {k.width}x{k.height}: {path}"
        )


def _json_dict(text: str) -> dict[str, str]:
    try:
        data = json.loads(text)
    except json.JSONDecodeError:
        return {}
    return {str(k): str(v) for k, v in data.items()} if isinstance(data, dict) else {}
