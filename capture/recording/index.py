"""The index of a recording: its topics, metadata and times, from the summary or from a scan.

A file that was never finished (a killed writer) has no summary; it is then read as a stream of
records, up to the last complete one.
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from mcap.exceptions import McapError
from mcap.reader import SeekingReader
from mcap.records import Attachment, Channel, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

from capture.errors import RecordingError

logger = logging.getLogger(__name__)

MCAP_MAGIC = b"\x89MCAP0\r\n"


@dataclass(frozen=True, slots=True)
class TopicInfo:
    """A topic of a recording: its message type and how many messages it has."""

    name: str
    datatype: str
    count: int


@dataclass(slots=True)
class McapIndex:
    """What a recording holds, from its summary or, for an unfinished file, from a scan."""

    finished: bool = False
    topics: dict[str, TopicInfo] = field(default_factory=dict)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    attachments: dict[str, bytes | None] = field(default_factory=dict)  # None: read on demand
    start_ns: int = 0
    end_ns: int = 0

    def add_topic(self, channel: Channel, schema: Schema | None, count: int) -> None:
        """Count a channel's messages under its topic."""
        old = self.topics.get(channel.topic)
        total = count + (old.count if old else 0)
        self.topics[channel.topic] = TopicInfo(channel.topic, schema.name if schema else "", total)


def stream_records(stream: IO[bytes]) -> Iterator[Any]:
    """Yield every complete record; a truncated tail (killed writer) ends the stream."""
    stream.seek(0)
    try:
        yield from StreamReader(stream).records
    except (McapError, struct.error, EOFError, ValueError):
        return
    except Exception as err:  # zstd/lz4 errors on a half-written chunk have no common base
        logger.debug("recording ends in an incomplete record: %s", err)


def _read_summary(stream: IO[bytes]) -> McapIndex | None:
    try:
        reader = SeekingReader(stream)
        summary = reader.get_summary()
        if summary is None or summary.statistics is None:
            return None
        index = McapIndex(finished=True)
        counts = summary.statistics.channel_message_counts
        for cid, channel in summary.channels.items():
            index.add_topic(channel, summary.schemas.get(channel.schema_id), counts.get(cid, 0))
        index.start_ns = summary.statistics.message_start_time
        index.end_ns = summary.statistics.message_end_time
        for meta in reader.iter_metadata():
            index.metadata.setdefault(meta.name, {}).update(meta.metadata)
        index.attachments = dict.fromkeys(a.name for a in summary.attachment_indexes)
    except (McapError, struct.error, ValueError, OSError, EOFError):
        return None
    return index


def _scan(stream: IO[bytes]) -> McapIndex:
    index = McapIndex(finished=False)
    counts: dict[int, int] = {}
    channels: dict[int, Channel] = {}
    schemas: dict[int, Schema] = {}
    times: list[int] = []
    for record in stream_records(stream):
        if isinstance(record, Schema):
            schemas[record.id] = record
        elif isinstance(record, Channel):
            channels[record.id] = record
        elif isinstance(record, Message):
            counts[record.channel_id] = counts.get(record.channel_id, 0) + 1
            times.append(record.log_time)
        elif isinstance(record, Metadata):
            index.metadata.setdefault(record.name, {}).update(record.metadata)
        elif isinstance(record, Attachment):
            index.attachments[record.name] = record.data
    for cid, channel in channels.items():
        index.add_topic(channel, schemas.get(channel.schema_id), counts.get(cid, 0))
    if times:
        index.start_ns, index.end_ns = min(times), max(times)
    return index


def read_index(stream: IO[bytes], path: Path) -> McapIndex:
    """Return the index of an open MCAP stream, scanning it when it was never finished."""
    if stream.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
        raise RecordingError(
            f"not an MCAP file (bad magic bytes); expected a .mcap recording: {path}"
        )
    stream.seek(0)
    return _read_summary(stream) or _scan(stream)
