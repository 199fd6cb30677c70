"""Decoding of ROS 2 image messages and the pairing of colour with depth into RgbdFrame values."""

from __future__ import annotations

import json
from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import cv2
import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

from capture.errors import RecordingError
from capture.recording import messages as m
from capture.recording.checks import extrinsics_problem, intrinsics_problem
from capture.recording.frames import Extrinsics, GroundTruth, Intrinsics, RgbdFrame
from capture.recording.salvage import DECODE_ERRORS

COLOR_ENCODINGS: Final = {
    "rgb8": (3, False),
    "bgr8": (3, True),
    "rgba8": (4, False),
    "bgra8": (4, True),
}


@dataclass(slots=True)
class Topics:
    """The topics a recording's frames are read from (found by type and suffix)."""

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
    """Return the 4x4 matrix of a decoded geometry_msgs/PoseStamped.

    Raises:
        RecordingError: the position is not finite or the quaternion is not a rotation.
    """
    p, q = msg.pose.position, msg.pose.orientation
    quat = np.array([q.x, q.y, q.z, q.w], np.float64)
    xyz = np.array([p.x, p.y, p.z], np.float64)
    norm = float(np.linalg.norm(quat))
    if not (np.isfinite(quat).all() and np.isfinite(xyz).all() and abs(norm - 1.0) < 0.1):
        raise RecordingError(
            f"invalid pose: quaternion {quat.tolist()} (norm {norm:.3g}, expected 1), "
            f"position {xyz.tolist()}"
        )
    out = np.eye(4)
    out[:3, :3] = Rotation.from_quat(quat).as_matrix()
    out[:3, 3] = xyz
    return out


def image_array(
    topic: str, msg: Any, dtype: np.dtype[Any], channels: int, path: Path
) -> npt.NDArray[Any]:
    """Return the pixels of a decoded sensor_msgs/Image as (H, W) or (H, W, C), checking sizes."""
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    data = msg.data if isinstance(msg.data, bytes | bytearray | memoryview) else bytes(msg.data)
    row = w * channels * dtype.itemsize
    if step < row or len(data) < step * h:
        raise RecordingError(
            f"'{topic}' image of {w}x{h} {msg.encoding} needs {row * h} bytes (step {row}), "
            f"found {len(data)} bytes with step {step}: {path}"
        )
    rows = np.frombuffer(data, np.uint8, count=step * h).reshape(h, step)[:, :row]
    arr = np.ascontiguousarray(rows).view(dtype).reshape(h, w, channels)
    return arr[..., 0] if channels == 1 else arr


def decode_color(topic: str, msg: Any, path: Path) -> npt.NDArray[np.uint8]:
    """Return an (H, W, 3) RGB image from a decoded Image or CompressedImage."""
    if not hasattr(msg, "encoding"):  # CompressedImage
        bgr = cv2.imdecode(np.frombuffer(bytes(msg.data), np.uint8), cv2.IMREAD_COLOR)
        if bgr is None:
            raise RecordingError(f"'{topic}' holds an undecodable {msg.format!r} image: {path}")
        return np.asarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), dtype=np.uint8)
    enc = str(msg.encoding).lower()
    if enc not in COLOR_ENCODINGS:
        raise RecordingError(
            f"'{topic}' has colour encoding {msg.encoding!r}; expected one of "
            f"{sorted(COLOR_ENCODINGS)}: {path}"
        )
    channels, bgr_order = COLOR_ENCODINGS[enc]
    img: npt.NDArray[np.uint8] = image_array(topic, msg, np.dtype(np.uint8), channels, path)
    rgb_view = img[..., 2::-1] if bgr_order else img[..., :3]
    return np.ascontiguousarray(rgb_view)


def decode_depth(topic: str, msg: Any, path: Path, *, scale_m: float) -> npt.NDArray[np.float32]:
    """Return depth in metres (0 = none) from a decoded 16UC1/mono16/32FC1 Image."""
    enc = str(msg.encoding).upper()
    order = ">" if msg.is_bigendian else "<"
    if enc in ("16UC1", "MONO16"):
        raw = image_array(topic, msg, np.dtype(order + "u2"), 1, path)
        return raw.astype(np.float32) * np.float32(scale_m)
    if enc == "32FC1":
        d = image_array(topic, msg, np.dtype(order + "f4"), 1, path).astype(np.float32)
        return np.nan_to_num(d, nan=0.0, posinf=0.0, neginf=0.0)
    raise RecordingError(
        f"'{topic}' has depth encoding {msg.encoding!r}; expected 16UC1 (mm), mono16 or "
        f"32FC1 (m): {path}"
    )


def check_size(topic: str, shape: tuple[int, ...], k: Intrinsics, path: Path) -> None:
    """Raise when an image's size disagrees with its camera_info."""
    if (shape[0], shape[1]) != (k.height, k.width):
        raise RecordingError(
            f"'{topic}' image is {shape[1]}x{shape[0]} but its camera_info says "
            f"{k.width}x{k.height}: {path}"
        )


def json_dict(text: str) -> dict[str, str]:
    """Return a JSON object as a str->str dict ({} when it is not one)."""
    try:
        data = json.loads(text)
    except json.JSONDecodeError:
        return {}
    return {str(k): str(v) for k, v in data.items()} if isinstance(data, dict) else {}


class FrameSync:
    """Pair colour with the nearest depth by stamp, holding a short window of messages.

    A message or frame that cannot be used (undecodable, impossible calibration, a stamp that
    repeats or goes back) is skipped and counted, never fatal; `notes()` says what was skipped
    and `why_none()` why no frame came out at all.
    """

    WINDOW_NS: Final = 300_000_000  # everything of one frame arrives within this much log time

    def __init__(
        self, topics: Topics, *, path: Path, tolerance_ns: int, depth_scale_m: float
    ) -> None:
        self.t = topics
        self.path = path
        self.tolerance_ns = tolerance_ns
        self.depth_scale_m = depth_scale_m
        self.pending: deque[_Pending] = deque()
        self.depths: deque[tuple[int, npt.NDArray[np.float32]]] = deque(maxlen=64)
        self.color_info: Intrinsics | None = None
        self.depth_info: Intrinsics | None = None
        self.extrinsics: Extrinsics | None = None
        self.gt: dict[str, dict[int, Any]] = {key: {} for key in topics.ground_truth}
        self.metadata: dict[int, dict[str, str]] = {}
        self.unpaired = 0
        self.emitted = 0
        self.colors = 0
        self.depth_count = 0
        self.last_color_ns: int | None = None
        self.skipped: dict[str, int] = {}  # what was skipped -> how many
        self.reasons: dict[str, str] = {}  # what was skipped -> the first reason
        self.no_depth = 0  # frames replayed although their depth has no valid pixel

    def _skip(self, what: str, reason: str) -> None:
        self.skipped[what] = self.skipped.get(what, 0) + 1
        self.reasons.setdefault(what, reason)

    def push(self, topic: str, msg: Any, log_ns: int) -> Iterator[RgbdFrame]:
        """Take one decoded message; yield the frames that can no longer gain a partner."""
        try:
            self._take(topic, msg, log_ns)
        except DECODE_ERRORS as err:  # a damaged message: skip it, say so at the end
            self._skip(f"unusable '{topic}' message(s)", _reason(err))
        while self.pending and log_ns - self.pending[0].log_ns > self.WINDOW_NS:
            frame = self._emit_or_skip(self.pending.popleft())
            if frame is not None:
                yield frame

    def _take(self, topic: str, msg: Any, log_ns: int) -> None:
        t = self.t
        if topic == t.color:
            self._color(msg, log_ns)
        elif topic == t.depth:
            depth = decode_depth(topic, msg, self.path, scale_m=self.depth_scale_m)
            self.depths.append((m.stamp_ns_of(msg.header.stamp), depth))
            self.depth_count += 1
        elif topic in (t.color_info, t.depth_info):
            k = intrinsics_from_msg(msg)
            problem = intrinsics_problem(k)
            if problem:
                self._skip(f"invalid camera_info on '{topic}'", problem)
            elif topic == t.color_info:
                self.color_info = k
            else:
                self.depth_info = k
        elif topic == t.extrinsics:
            e = Extrinsics.from_librealsense(msg.rotation, msg.translation)
            problem = extrinsics_problem(e)
            if problem:
                self._skip(f"invalid extrinsics on '{topic}'", problem)
            else:
                self.extrinsics = e
        elif topic == t.color_metadata:
            self.metadata[m.stamp_ns_of(msg.header.stamp)] = json_dict(msg.json_data)
        else:
            for key, gt_topic in t.ground_truth.items():
                if topic == gt_topic:
                    self.gt[key][m.stamp_ns_of(msg.header.stamp)] = msg

    def _color(self, msg: Any, log_ns: int) -> None:
        self.colors += 1
        stamp = m.stamp_ns_of(msg.header.stamp)
        if self.last_color_ns is not None and stamp <= self.last_color_ns:
            self._skip(
                "colour frame(s) with a stamp not after the previous one (repeated or going back)",
                f"{stamp} ns after {self.last_color_ns} ns",
            )
            return
        color = decode_color(self.t.color, msg, self.path)
        self.last_color_ns = stamp
        self.pending.append(_Pending(stamp, log_ns, color))

    def drain(self) -> Iterator[RgbdFrame]:
        """Yield the frames still waiting at the end of the recording."""
        while self.pending:
            frame = self._emit_or_skip(self.pending.popleft())
            if frame is not None:
                yield frame

    def notes(self) -> list[str]:
        """Return one line per kind of skipped message or frame."""
        notes = [f"{n} {what} skipped ({self.reasons[what]})" for what, n in self.skipped.items()]
        if self.no_depth:
            notes.append(
                f"{self.no_depth} of {self.emitted} frame(s) have no valid depth pixel (all zero, "
                "NaN or inf): they add nothing to the map"
            )
        return notes

    def why_none(self, path: Path) -> str:
        """Return the one-line error for a recording that gave no frame at all."""
        if self.colors == 0:
            return f"no readable colour frame on '{self.t.color}'; is the recording empty?: {path}"
        if self.skipped:
            # A bad calibration is the cause of the unusable frames: name it first.
            what, n = min(
                self.skipped.items(),
                key=lambda kv: (
                    not kv[0].startswith(("invalid camera_info", "invalid extr")),
                    -kv[1],
                ),
            )
            return (
                f"no frame could be replayed: {n} {what} ({self.reasons[what]}); "
                f"fix or re-record the recording: {path}"
            )
        if self.unpaired:
            return (
                f"no colour frame had a depth frame within {self.tolerance_ns / 1e6:.0f} ms "
                f"({self.colors} colour, {self.depth_count} depth messages); are colour and depth "
                f"stamped on the same clock?: {path}"
            )
        return f"no frame could be replayed from {self.colors} colour messages: {path}"

    def _emit_or_skip(self, p: _Pending) -> RgbdFrame | None:
        try:
            frame = self._emit(p)
        except DECODE_ERRORS as err:
            self._skip("unusable frame(s)", _reason(err))
            return None
        if frame is not None:
            self.emitted += 1
            self.no_depth += not bool((frame.depth_m > 0).any())
        return frame

    def _emit(self, p: _Pending) -> RgbdFrame | None:
        t = self.t
        if self.color_info is None:
            raise RecordingError(f"no valid camera_info on '{t.color_info}' before it")
        best = min(self.depths, key=lambda d: abs(d[0] - p.stamp_ns), default=None)
        if best is None or abs(best[0] - p.stamp_ns) > self.tolerance_ns:
            self.unpaired += 1
            return None
        depth_info = self.depth_info or self.color_info
        check_size(t.color, p.color.shape[:2], self.color_info, self.path)
        check_size(t.depth, best[1].shape, depth_info, self.path)
        if not t.aligned and self.extrinsics is None:
            raise RecordingError(f"no valid '{t.extrinsics}' message before it")
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
            metadata=self._metadata(p.stamp_ns),
        )

    def _metadata(self, stamp_ns: int) -> dict[str, str]:
        for old in [s for s in self.metadata if s < stamp_ns]:  # of skipped frames
            del self.metadata[old]
        return self.metadata.pop(stamp_ns, {})

    def _ground_truth(self, stamp_ns: int) -> GroundTruth | None:
        if not self.gt:
            return None
        pose = self.gt.get("pose", {}).pop(stamp_ns, None)
        labels = self.gt.get("labels", {}).pop(stamp_ns, None)
        instances = self.gt.get("instances", {}).pop(stamp_ns, None)
        for table in self.gt.values():  # drop ground truth of skipped frames
            for old in [s for s in table if s < stamp_ns]:
                del table[old]
        gt_topics = self.t.ground_truth
        return GroundTruth(
            world_from_camera=None if pose is None else self._pose(pose),
            labels=None
            if labels is None
            else self._gt_image(gt_topics["labels"], labels, np.dtype(np.uint8)),
            instances=None
            if instances is None
            else self._gt_image(gt_topics["instances"], instances, np.dtype("<u2")),
        )

    def _pose(self, msg: Any) -> npt.NDArray[np.float64] | None:
        try:
            return pose_from_msg(msg)
        except DECODE_ERRORS as err:
            self._skip("invalid ground-truth pose(s)", _reason(err))
            return None

    def _gt_image(self, topic: str, msg: Any, dtype: np.dtype[Any]) -> npt.NDArray[Any] | None:
        try:
            img = image_array(topic, msg, dtype, 1, self.path)
            check_size(topic, img.shape, self.color_info or Intrinsics(0, 0, 0, 0, 0, 0), self.path)
        except DECODE_ERRORS as err:
            self._skip(f"invalid ground-truth image(s) on '{topic}'", _reason(err))
            return None
        return img


def _reason(err: BaseException) -> str:
    text = str(err).splitlines()[0] if str(err) else type(err).__name__
    text = text.rsplit(": /", 1)[0]  # the path is said once, at the end of the line
    return text[:160]
