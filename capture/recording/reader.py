"""RecordingReader: synchronised RGB-D frames out of any recording that follows RECORDING.md."""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from types import TracebackType
from typing import IO, Any, cast

from mcap.reader import SeekingReader
from mcap.records import Channel, Message, Schema
from mcap_ros2.decoder import DecoderFactory

from capture.errors import RecordingError
from capture.recording import messages as m
from capture.recording.follow import GrowingFile
from capture.recording.frames import RgbdFrame
from capture.recording.index import McapIndex, TopicInfo, read_index, stream_records
from capture.recording.sync import (
    FrameSync,
    Topics,
    intrinsics_from_msg,
    pose_from_msg,
)

logger = logging.getLogger(__name__)

__all__ = ["RecordingReader", "TopicInfo", "intrinsics_from_msg", "pose_from_msg", "read_index"]


class RecordingReader:
    """Read a recording as a stream of synchronised `RgbdFrame` values.

    Usage: `with RecordingReader(path) as rec: for frame in rec.frames(): ...`.
    Recordings that were never finished (a killed writer) replay every complete chunk. With
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
        follow_idle_s: float | None = None,
        stop: threading.Event | None = None,
    ) -> None:
        self.path = Path(path)
        self.sync_tolerance_ns = sync_tolerance_ns
        self.prefer_aligned = prefer_aligned
        self.follow_idle_s = follow_idle_s
        self.stop = stop or threading.Event()
        self.unpaired_color_frames = 0
        self._index = McapIndex()
        self._stream: IO[bytes] | None = None
        self._growing: GrowingFile | None = None  # the same stream, when following
        self._decoders = DecoderFactory()

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
        if self.follow_idle_s is not None:
            self._open_following(self.follow_idle_s)
            return
        try:
            self._stream = self.path.open("rb")
        except OSError as err:
            raise RecordingError(f"cannot open recording: {err.strerror}: {self.path}") from err
        try:
            self._index = read_index(self._stream, self.path)
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
                with self.path.open("rb") as stream:
                    self._index = read_index(stream, self.path)
                self._topics = self._discover()
                break
            except (RecordingError, OSError) as err:
                last = err if isinstance(err, RecordingError) else RecordingError(str(err))
                time.sleep(0.1)
        else:
            raise RecordingError(
                f"followed the recording for {idle_s:g} s and found no complete frame topics"
                f" ({last}); is the capture running?: {self.path}"
            )
        if not self.finished:
            self._growing = GrowingFile(self.path, idle_s=idle_s, stop=self.stop)
            self._stream = cast(IO[bytes], self._growing)  # read, seek and tell are all it needs
        else:
            self._stream = self.path.open("rb")

    def close(self) -> None:
        """Close the file."""
        if self._stream is not None:
            self._stream.close()
            self._stream = None

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
        return float(text) if text else 0.001

    @property
    def duration_ns(self) -> int:
        """Return the time between the first and the last message."""
        return self.end_ns - self.start_ns

    def attachment(self, name: str) -> bytes | None:
        """Return the data of the named attachment, or None when the recording has none."""
        data = self._index.attachments.get(name)
        if data is not None or name not in self._index.attachments or self._stream is None:
            return data
        self._stream.seek(0)
        for att in SeekingReader(self._stream).iter_attachments():
            if att.name == name:
                return att.data
        return None

    # -- frames ----------------------------------------------------------------------------
    def _messages(self, topics: list[str]) -> Iterator[tuple[str, Any, int]]:
        """Yield (topic, decoded message, log_ns) in log-time order (file order if unfinished)."""
        if self._stream is None:
            raise RecordingError(
                f"recording is not open; use `with RecordingReader(path)`: {self.path}"
            )
        if self.finished:
            self._stream.seek(0)
            reader = SeekingReader(self._stream, decoder_factories=[self._decoders])
            for _, channel, message, decoded in reader.iter_decoded_messages(
                topics=topics, log_time_order=True
            ):
                yield channel.topic, decoded, message.log_time
            return
        wanted = set(topics)
        schemas: dict[int, Schema] = {}
        channels: dict[int, Channel] = {}
        for record in stream_records(self._stream):
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, Message) and channels[record.channel_id].topic in wanted:
                channel = channels[record.channel_id]
                decoder = self._decoders.decoder_for(
                    channel.message_encoding, schemas.get(channel.schema_id)
                )
                if decoder is not None:
                    yield channel.topic, decoder(record.data), record.log_time

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
        if sync.unpaired:
            logger.warning(
                "%d colour frames had no depth within %.0f ms and were skipped: %s",
                sync.unpaired,
                self.sync_tolerance_ns / 1e6,
                self.path,
            )
        if self.following:  # the writer may have finished: read what the file says now
            with self.path.open("rb") as stream:
                self._index = read_index(stream, self.path)
        if not self.finished:
            logger.warning(
                "recording was not finished (writer killed?); recovered %d frames: %s",
                emitted,
                self.path,
            )

    def _synced(self, sync: FrameSync, topics: list[str]) -> Iterator[RgbdFrame]:
        for topic, msg, log_ns in self._messages(topics):
            yield from sync.push(topic, msg, log_ns)
        yield from sync.drain()
