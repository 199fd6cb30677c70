"""RecordingReader: synchronised RGB-D frames out of any recording that follows RECORDING.md."""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

from mcap.records import Channel, Message, Schema
from mcap_ros2.decoder import DecoderFactory

from capture.errors import RecordingError
from capture.recording import messages as m
from capture.recording.follow import GrowingFile, follow_records
from capture.recording.frames import RgbdFrame
from capture.recording.index import McapIndex, TopicInfo, damage_note, open_index
from capture.recording.salvage import DECODE_ERRORS, McapSalvage
from capture.recording.sync import (
    FrameSync,
    Topics,
    intrinsics_from_msg,
    pose_from_msg,
)

logger = logging.getLogger(__name__)

__all__ = ["RecordingReader", "TopicInfo", "intrinsics_from_msg", "pose_from_msg"]


class RecordingReader:
    """Read a recording as a stream of synchronised `RgbdFrame` values.

    Usage: `with RecordingReader(path) as rec: for frame in rec.frames(): ...`.
    Recordings that were never finished (a killed writer) or are damaged replay every intact
    chunk; what was lost or skipped is said once in the log and kept in `warnings`. With
    `follow_idle_s`, a recording still being written is followed: frames are yielded as the
    writer's chunks arrive, until the writer finishes the file, stays idle for that many
    seconds, or `stop` is set.
    """

    def __init__(
        self,
        path: Path,
        *,
        sync_tolerance_ns: int = 20_000_000,
        prefer_aligned: bool = True,
        verify: bool = False,
        follow_idle_s: float | None = None,
        stop: threading.Event | None = None,
    ) -> None:
        """Prepare to read path; verify=True checks every chunk at open() (exact counts)."""
        self.path = Path(path)
        self.verify = verify
        self.follow_idle_s = follow_idle_s
        self.stop = stop or threading.Event()
        self.sync_tolerance_ns = sync_tolerance_ns
        self.prefer_aligned = prefer_aligned
        self.unpaired_color_frames = 0
        self.warnings: list[str] = []  # what the last open() and frames() distrusted or skipped
        self._index = McapIndex()
        self._index_read = False
        self._salvage: McapSalvage | None = None
        self._growing: GrowingFile | None = None  # the file, when following it
        self._decoders = DecoderFactory()
        self._undecodable = 0

    # -- opening ---------------------------------------------------------------------------
    def __enter__(self) -> RecordingReader:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def open(self) -> None:
        """Open the file, read its summary (or scan it if unfinished) and find its topics."""
        self.warnings = []
        if self.follow_idle_s is not None:
            self._open_following(self.follow_idle_s)
            return
        self._index, self._salvage = open_index(self.path, verify=self.verify)
        self._index_read = True
        note = damage_note(self._index, self.path)
        if note:
            self._warn(note)
        try:
            self._topics = self._discover()
        except RecordingError:
            self.close()
            raise

    def _open_following(self, idle_s: float) -> None:
        """Wait until the writer has written the topics a replay needs, then follow the file."""
        last: RecordingError | None = None
        deadline = time.monotonic() + idle_s
        while time.monotonic() < deadline and not self.stop.is_set():
            try:
                self._index, self._salvage = open_index(self.path, verify=False)
                self._index_read = True
                self._topics = self._discover()
                break
            except (RecordingError, OSError) as err:
                self.close()
                last = err if isinstance(err, RecordingError) else RecordingError(str(err))
                time.sleep(0.1)
        else:
            raise RecordingError(
                f"followed the recording for {idle_s:g} s and found no complete frame topics"
                f" ({last}); is the capture running?: {self.path}"
            )
        if not self.finished:
            self._growing = GrowingFile(self.path, idle_s=idle_s, stop=self.stop)

    def close(self) -> None:
        """Close the file."""
        if self._salvage is not None:
            self._salvage.close()
            self._salvage = None
        if self._growing is not None:
            self._growing.close()
            self._growing = None

    def _warn(self, text: str) -> None:
        if text in self.warnings:  # a second pass over the frames says nothing new
            return
        logger.warning("%s", text)
        self.warnings.append(text)

    def _discover(self) -> Topics:
        found = ", ".join(f"{t.name} ({t.datatype})" for t in self.topics.values()) or "none"

        def pick(suffix: str, datatype: str) -> str | None:
            names = [
                t.name
                for t in self.topics.values()
                if t.name.endswith(suffix) and t.datatype == datatype
            ]
            return min(names, key=len) if names else None

        color = pick(m.COLOR_IMAGE, m.IMAGE) or pick(m.COLOR_COMPRESSED, m.COMPRESSED_IMAGE)
        if color is None:
            raise RecordingError(
                f"no colour topic (sensor_msgs/msg/Image '*{m.COLOR_IMAGE}' or CompressedImage "
                f"'*{m.COLOR_COMPRESSED}'); found: {found}; is this an RGB-D recording?: "
                f"{self.path}"
            )
        ns = color[: color.rindex("/color/")]
        aligned_topic = pick(m.ALIGNED_DEPTH_IMAGE, m.IMAGE)
        raw_topic = pick(m.DEPTH_IMAGE, m.IMAGE)
        use_aligned = aligned_topic is not None and (self.prefer_aligned or raw_topic is None)
        depth = aligned_topic if use_aligned else raw_topic
        if depth is None:
            raise RecordingError(
                f"no depth topic ('{ns}{m.DEPTH_IMAGE}' or '{ns}{m.ALIGNED_DEPTH_IMAGE}', "
                f"sensor_msgs/msg/Image); found: {found}: {self.path}"
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
                f"recording has none; record with aligned depth or with the calibration: "
                f"{self.path}"
            )
        gt_topics = (("pose", m.GT_POSE), ("labels", m.GT_LABELS), ("instances", m.GT_INSTANCES))
        gt = {key: topic for key, topic in gt_topics if topic in self.topics}
        metadata = pick(m.COLOR_METADATA, m.RS_METADATA)
        return Topics(color, color_info, depth, depth_info, use_aligned, extrinsics, metadata, gt)

    # -- properties --------------------------------------------------------------------------
    @property
    def following(self) -> bool:
        """Return whether frames come from a recording that is still being written."""
        return self._growing is not None

    @property
    def index(self) -> McapIndex | None:
        """Return what the walk of the file found, or None before open() read it.

        open() sets it even when it then refuses the recording (not RGB-D).
        """
        return self._index if self._index_read else None

    @property
    def finished(self) -> bool:
        """Return whether the file was finished (has a summary) rather than recovered."""
        return self._index.finished

    @property
    def topics(self) -> dict[str, TopicInfo]:
        """Return every topic of the recording by name."""
        return self._index.topics

    @property
    def metadata(self) -> dict[str, dict[str, str]]:
        """Return the MCAP metadata records by name (`device`, `capture`, ...)."""
        return self._index.metadata

    @property
    def attachment_names(self) -> list[str]:
        """Return the names of the recording's attachments."""
        return list(self._index.attachments)

    @property
    def start_ns(self) -> int:
        """Return the log time of the first message."""
        return self._index.start_ns

    @property
    def end_ns(self) -> int:
        """Return the log time of the last message."""
        return self._index.end_ns

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
        if not text:
            return 0.001
        try:
            scale = float(text)
        except ValueError:
            scale = float("nan")
        if not 1e-6 <= scale <= 1.0:  # also NaN
            self._warn(
                f"device depth_scale_m {text!r} is not metres per unit in [1e-6, 1]; using "
                f"0.001 (1 mm, the D435's): {self.path}"
            )
            return 0.001
        return scale

    @property
    def duration_ns(self) -> int:
        """Return the time between the first and the last message."""
        return self.end_ns - self.start_ns

    @property
    def lost_frames(self) -> int:
        """Return the colour frames the damaged parts of the file held, where it says."""
        return self._index.lost.get(self._topics.color, 0)

    def attachment(self, name: str) -> bytes | None:
        """Return the data of the named attachment, or None when absent or unreadable."""
        if self.following:  # written at the end of the capture: look at the file as it is now
            _, salvage = open_index(self.path, verify=False)
            try:
                return salvage.attachment(name)
            finally:
                salvage.close()
        return None if self._salvage is None else self._salvage.attachment(name)

    # -- frames ----------------------------------------------------------------------------
    def _messages(self, topics: list[str]) -> Iterator[tuple[str, Any, int]]:
        """Yield (topic, decoded message, log_ns) in log-time order; skip undecodable ones."""
        if self._salvage is None:
            raise RecordingError(
                f"recording is not open; use `with RecordingReader(path)`: {self.path}"
            )
        self._undecodable = 0
        if self._growing is not None:
            yield from self._followed_messages(set(topics), self._growing)
            return
        salvage = self._salvage
        ids = {cid for cid, c in salvage.channels.items() if c.topic in set(topics)}
        for record in salvage.messages(ids):
            channel = salvage.channels[record.channel_id]
            decoded = self._decode(channel, salvage.schemas.get(channel.schema_id), record.data)
            if decoded is not None:
                yield channel.topic, decoded, record.log_time

    def _followed_messages(
        self, wanted: set[str], growing: GrowingFile
    ) -> Iterator[tuple[str, Any, int]]:
        """Yield the messages of a file being written, in file order, as they arrive."""
        schemas: dict[int, Schema] = {}
        channels: dict[int, Channel] = {}
        for record in follow_records(growing, self.path):
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, Message):
                channel = channels.get(record.channel_id)
                if channel is None or channel.topic not in wanted:
                    continue
                decoded = self._decode(channel, schemas.get(channel.schema_id), record.data)
                if decoded is not None:
                    yield channel.topic, decoded, record.log_time

    def _decode(self, channel: Channel, schema: Schema | None, data: bytes) -> Any:
        """Return a decoded message, or None (counted) when its schema or bytes are corrupt."""
        try:
            decoder = self._decoders.decoder_for(channel.message_encoding, schema)
            if decoder is None:
                raise RecordingError(f"no ROS 2 schema for '{channel.topic}'")
            return decoder(data)
        except DECODE_ERRORS as err:
            self._undecodable += 1
            logger.debug("undecodable message on %s: %s", channel.topic, err)
            return None

    def frames(
        self, *, start_ns: int | None = None, end_ns: int | None = None
    ) -> Iterator[RgbdFrame]:
        """Yield synchronised frames whose colour stamp lies in [start_ns, end_ns]."""
        t = self._topics
        topics = [t.color, t.color_info, t.depth, *t.ground_truth.values()]
        topics += [x for x in (t.depth_info, t.extrinsics, t.color_metadata) if x is not None]
        sync = FrameSync(
            t, path=self.path, tolerance_ns=self.sync_tolerance_ns, depth_scale_m=self.depth_scale_m
        )
        lo = -(2**63) if start_ns is None else start_ns
        hi = 2**63 if end_ns is None else end_ns
        emitted = 0
        for frame in self._synced(sync, topics):
            if lo <= frame.stamp_ns <= hi:
                yield replace(frame, index=emitted)
                emitted += 1
        self.unpaired_color_frames = sync.unpaired
        self._report(sync, emitted)

    def _report(self, sync: FrameSync, emitted: int) -> None:
        """Say what was skipped; raise when nothing at all could be replayed."""
        lost = self._salvage.damage.chunks_lost if self._salvage else 0
        if lost > self._index.damage_chunks_at_open:
            new = lost - self._index.damage_chunks_at_open
            self._warn(f"{new} damaged chunk(s) skipped while replaying: {self.path}")
        if self._undecodable:
            self._warn(f"{self._undecodable} undecodable message(s) skipped: {self.path}")
        for text in sync.notes():
            self._warn(f"{text}: {self.path}")
        if sync.unpaired:
            self._warn(
                f"{sync.unpaired} colour frame(s) had no depth within "
                f"{self.sync_tolerance_ns / 1e6:.0f} ms and were skipped: {self.path}"
            )
        if self.following:  # the writer may have finished: read what the file says now
            self._index, salvage = open_index(self.path, verify=False)
            salvage.close()
        if not self.finished:
            self._warn(
                f"recording was not finished (writer killed?); recovered {emitted} frames: "
                f"{self.path}"
            )
        if sync.emitted == 0:
            raise RecordingError(sync.why_none(self.path))

    def _synced(self, sync: FrameSync, topics: list[str]) -> Iterator[RgbdFrame]:
        for topic, msg, log_ns in self._messages(topics):
            yield from sync.push(topic, msg, log_ns)
        yield from sync.drain()
