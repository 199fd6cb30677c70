"""The index of a recording: its topics, metadata, times and damage, from a tolerant walk.

A finished file, one that was never finished (a killed writer) and a damaged one are all read
the same way (`salvage.McapSalvage`): every intact chunk counts, the damaged ones are counted.
"""

from __future__ import annotations

import logging
import stat
from dataclasses import dataclass, field
from pathlib import Path

from capture.errors import RecordingError
from capture.recording.salvage import MAGIC, Damage, McapSalvage

logger = logging.getLogger(__name__)

MCAP_MAGIC = MAGIC


@dataclass(frozen=True, slots=True)
class TopicInfo:
    """A topic of a recording: its message type and how many messages it has."""

    name: str
    datatype: str
    count: int


@dataclass(slots=True)
class McapIndex:
    """What a recording holds (intact data only) and what of it was lost."""

    finished: bool = False
    topics: dict[str, TopicInfo] = field(default_factory=dict)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    attachments: list[str] = field(default_factory=list)
    start_ns: int = 0
    end_ns: int = 0
    damage: Damage = field(default_factory=Damage)
    lost: dict[str, int] = field(default_factory=dict)  # messages lost per topic, where known
    duplicates: int = 0  # repeated messages (duplicated chunks or records), dropped
    damage_chunks_at_open: int = 0  # damaged chunks found by the walk (more may be found later)


def check_regular_file(path: Path) -> None:
    """Raise RecordingError unless path is a regular file (not missing, a folder, a FIFO...)."""
    try:
        mode = path.stat().st_mode
    except OSError as err:
        raise RecordingError(f"cannot open recording: {err.strerror}: {path}") from err
    if not stat.S_ISREG(mode):
        raise RecordingError(
            f"expected a recording file (.mcap), found a folder, pipe or device: {path}"
        )


def open_index(path: Path, *, verify: bool = True) -> tuple[McapIndex, McapSalvage]:
    """Walk the recording at path; return its index and the walker that reads its messages.

    verify=False trusts an intact summary (see `McapSalvage.scan`): damaged chunks are then
    found, skipped and counted while the messages are read.

    Raises:
        RecordingError: not a regular file, not MCAP, or nothing in it is readable.
    """
    check_regular_file(path)
    try:
        salvage = McapSalvage(path)
    except (OSError, ValueError) as err:
        reason = getattr(err, "strerror", None) or str(err)
        raise RecordingError(f"cannot open recording: {reason}: {path}") from err
    if not salvage.has_magic:
        salvage.close()
        raise RecordingError(
            f"not an MCAP file (bad magic bytes); expected a .mcap recording: {path}"
        )
    salvage.scan(verify=verify)
    if not (salvage.channels or salvage.metadata or salvage.finished):
        salvage.close()
        found = "; ".join(salvage.damage.reasons[:2]) or "no record after the magic bytes"
        raise RecordingError(
            f"nothing in this MCAP file is readable ({found}); it is damaged beyond recovery,"
            f" re-record or restore it: {path}"
        )
    return _index_of(salvage), salvage


def _index_of(salvage: McapSalvage) -> McapIndex:
    index = McapIndex(
        finished=salvage.finished,
        metadata=salvage.metadata,
        attachments=list(salvage.attachments),
        start_ns=salvage.start_ns,
        end_ns=salvage.end_ns,
        damage=salvage.damage,
        duplicates=salvage.duplicates,
        damage_chunks_at_open=salvage.damage.chunks_lost,
    )
    for cid, channel in sorted(salvage.channels.items()):
        schema = salvage.schemas.get(channel.schema_id)
        old = index.topics.get(channel.topic)
        count = salvage.counts.get(cid, 0) + (old.count if old else 0)
        datatype = schema.name if schema else (old.datatype if old else "")
        index.topics[channel.topic] = TopicInfo(channel.topic, datatype, count)
        lost = salvage.damage.lost_by_channel.get(cid, 0)
        if lost:
            index.lost[channel.topic] = index.lost.get(channel.topic, 0) + lost
    return index


def damage_note(index: McapIndex, path: Path) -> str:
    """Return one line on what was lost ("" when nothing was)."""
    d = index.damage
    if not d.any and not index.duplicates:
        return ""
    parts = []
    if d.chunks_lost:
        parts.append(f"{d.chunks_lost} damaged chunk(s) skipped")
    if d.records_skipped:
        parts.append(f"{d.records_skipped} unreadable record(s) skipped")
    if d.bytes_skipped:
        parts.append(f"{d.bytes_skipped} unreadable byte(s) skipped")
    if index.lost:
        parts.append(
            "messages lost: " + ", ".join(f"{t} {n}" for t, n in sorted(index.lost.items()))
        )
    if index.duplicates:
        parts.append(f"{index.duplicates} duplicated message(s) dropped")
    return f"recording is damaged: {'; '.join(parts)}: {path}"
