"""A tolerant walk of an MCAP file: every intact chunk of a finished, unfinished or damaged file.

The file is memory-mapped and walked record by record (opcode, length, body). Where a record is
implausible (unknown opcode, a length past the end of the file) the walk skips to the next chunk
header it can find; chunk offsets named by an intact summary are tried as well. Each chunk is
decompressed with a bounded output and checked against its CRC: a damaged chunk is skipped and
counted, never fatal, like `mcap recover`. The messages the damaged chunks held are counted from
the summary's statistics (when it survived) or from the message indexes written after each chunk.
"""

from __future__ import annotations

import heapq
import io
import logging
import mmap
import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.reader import SeekingReader
from mcap.records import (
    Attachment,
    AttachmentIndex,
    Channel,
    ChunkIndex,
    MessageIndex,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
)

from capture.recording.mcap_records import (
    DECODE_ERRORS,
    HEAD,
    MAGIC,
    NAME_AT,
    RESYNC,
    Damage,
    DamagedError,
    RawMessage,
    chunk_payload,
    inner_records,
    message_key,
    read_message,
    reason_of,
)

logger = logging.getLogger(__name__)

__all__ = ["DECODE_ERRORS", "MAGIC", "ChunkInfo", "Damage", "McapSalvage", "RawMessage"]


@dataclass(slots=True)
class ChunkInfo:
    """An intact chunk: where it is and the log times of its messages."""

    offset: int
    start_ns: int
    end_ns: int


class McapSalvage:
    """The readable contents of an MCAP file, found by a tolerant walk (see the module doc)."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}
        self.metadata: dict[str, dict[str, str]] = {}
        self.attachments: dict[str, int] = {}  # name -> record offset
        self.chunks: list[ChunkInfo] = []
        self.loose: list[tuple[int, int]] = []  # (log time, offset) of messages outside chunks
        self.counts: dict[int, int] = {}  # messages per channel id, in intact data
        self.summary_counts: dict[int, int] | None = None
        self.finished = False
        self.damage = Damage()
        self.start_ns = 0
        self.end_ns = 0
        self.duplicates = 0  # messages that repeat another (same channel, times, sequence, size)
        self._keys: set[tuple[int, int, int, int, int]] = set()
        self._seen: set[int] = set()
        self._last_chunk_lost = False
        with self.path.open("rb") as f:
            size = f.seek(0, io.SEEK_END)
            self._buf: Any = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) if size else b""

    def close(self) -> None:
        """Release the memory map."""
        if isinstance(self._buf, mmap.mmap):
            self._buf.close()

    @property
    def has_magic(self) -> bool:
        """Return whether the file starts with the MCAP magic bytes."""
        return bytes(self._buf[: len(MAGIC)]) == MAGIC

    # -- the walk ----------------------------------------------------------------------------
    def scan(self, *, verify: bool = True) -> None:
        """Find the file's contents.

        verify=True walks the file and decompresses every chunk (exact counts of what is
        intact); verify=False trusts an intact summary whose chunk headers are where it says,
        and leaves the chunks to be checked as they are read (`messages()` skips and counts a
        damaged one), falling back to the full walk when there is no such summary.
        """
        if not verify and self._from_summary():
            return
        self._walk(len(MAGIC))
        summary_start = self._footer_summary_start()
        if summary_start is not None and summary_start not in self._seen:
            self._walk(summary_start, from_index=True)
        self._times()
        self._lost_from_summary()

    def _from_summary(self) -> bool:
        """Take the index from an intact summary; return False (and change nothing) if none."""
        try:
            if not self._summary_crc_ok():
                return False
            with self.path.open("rb") as f:
                summary = SeekingReader(f).get_summary()
            if summary is None or summary.statistics is None:
                return False
            stats = summary.statistics
            chunks = [
                ChunkInfo(c.chunk_start_offset, c.message_start_time, c.message_end_time)
                for c in summary.chunk_indexes
            ]
            plausible = all(self._plausible_chunk(c.offset) for c in chunks)
            if not plausible or (stats.message_count and not chunks):
                return False
        except DECODE_ERRORS:
            return False
        self.schemas, self.channels = dict(summary.schemas), dict(summary.channels)
        self.chunks = chunks
        self.counts = dict(stats.channel_message_counts)
        self.summary_counts = dict(self.counts)
        self.finished = True
        for entry in summary.metadata_indexes:
            if self._in_file(entry.offset):
                self._walk_one(entry.offset)
        for att in summary.attachment_indexes:
            if self._in_file(att.offset):
                self.attachments.setdefault(att.name, att.offset)
        self._times()
        return True

    def _summary_crc_ok(self) -> bool:
        """Return whether the footer's CRC (if any) matches the summary section it covers."""
        start = self._footer_summary_start()
        if start is None:
            return False
        footer = len(self._buf) - len(MAGIC) - HEAD.size - 20
        (crc,) = struct.unpack_from("<I", self._buf, footer + HEAD.size + 16)
        return bool(crc == 0 or zlib.crc32(self._buf[start : footer + HEAD.size + 16]) == crc)

    def _walk(self, pos: int, *, from_index: bool = False) -> None:
        """Walk records from pos; from_index: pos came from the summary, trust it less."""
        buf, size = self._buf, len(self._buf)
        if from_index and not self._plausible(pos):
            return  # a stale or damaged index entry: the linear walk covers the data
        while pos + HEAD.size <= size:
            opcode, length = HEAD.unpack_from(buf, pos)
            end = pos + HEAD.size + length
            if not 1 <= opcode <= 0x0F or end > size:
                nxt = self._next_chunk(pos + 1)
                self.damage.truncated = self.damage.truncated or nxt is None
                skipped = (size if nxt is None else nxt) - pos
                if nxt is None and bytes(buf[pos:]) == MAGIC:
                    return  # the closing magic of a finished file
                self.damage.bytes_skipped += skipped
                self.damage.note(f"{skipped} unreadable bytes at offset {pos}")
                if nxt is None:
                    return
                pos = nxt
                continue
            if pos in self._seen:
                return  # walked from here already
            self._seen.add(pos)
            if opcode == Opcode.FOOTER:
                self.finished = self.summary_counts is not None
                return
            if self._record(opcode, pos, end) or self._plausible(end):
                pos = end
            else:  # a damaged chunk whose length is garbage too: look for the next one
                nxt = self._next_chunk(pos + 1)
                if nxt is None:
                    return
                pos = nxt

    def _plausible(self, pos: int) -> bool:
        if pos + HEAD.size > len(self._buf):
            return pos == len(self._buf)
        opcode, length = HEAD.unpack_from(self._buf, pos)
        return bool(1 <= opcode <= 0x0F and pos + HEAD.size + length <= len(self._buf))

    def _next_chunk(self, pos: int) -> int | None:
        """Return the offset of the next plausible compressed chunk header at or after pos."""
        best: int | None = None
        for name in RESYNC:
            at = self._buf.find(name, pos + NAME_AT - 1)
            while at >= 0:
                start = at - NAME_AT
                if start >= pos and self._plausible_chunk(start):
                    break
                at = self._buf.find(name, at + 1)
            if at >= 0 and (best is None or at - NAME_AT < best):
                best = at - NAME_AT
        return best

    def _plausible_chunk(self, pos: int) -> bool:
        opcode, length = HEAD.unpack_from(self._buf, pos)
        return bool(opcode == Opcode.CHUNK and pos + HEAD.size + length <= len(self._buf))

    def _footer_summary_start(self) -> int | None:
        size = len(self._buf)
        footer = size - len(MAGIC) - HEAD.size - 20
        if footer < len(MAGIC) or bytes(self._buf[size - len(MAGIC) :]) != MAGIC:
            return None
        opcode, length = HEAD.unpack_from(self._buf, footer)
        if opcode != Opcode.FOOTER or length != 20:
            return None
        start: int = struct.unpack_from("<Q", self._buf, footer + HEAD.size)[0]
        return start if len(MAGIC) <= start < footer else None

    def _record(self, opcode: int, pos: int, end: int) -> bool:
        """Take one top-level record; return False when it could not be read (counted)."""
        try:
            if opcode == Opcode.CHUNK:
                return self._chunk(pos)
            body = ReadDataStream(io.BytesIO(self._buf[pos + HEAD.size : end]))
            length = end - pos - HEAD.size
            if opcode == Opcode.SCHEMA:
                self._add_schema(Schema.read(body))
            elif opcode == Opcode.CHANNEL:
                self._add_channel(Channel.read(body))
            elif opcode == Opcode.MESSAGE:
                msg = read_message(body, length)
                if self._first(msg):
                    self.loose.append((msg.log_time, pos))
            elif opcode == Opcode.MESSAGE_INDEX and self._last_chunk_lost:
                index = MessageIndex.read(body)
                lost = self.damage.lost_by_channel
                lost[index.channel_id] = lost.get(index.channel_id, 0) + len(index.records)
            elif opcode == Opcode.METADATA:
                meta = Metadata.read(body)
                self.metadata.setdefault(meta.name, {}).update(meta.metadata)
            elif opcode == Opcode.ATTACHMENT:
                self.attachments.setdefault(Attachment.read(body).name, pos)
            else:
                self._summary_record(opcode, body)
        except DECODE_ERRORS as err:
            self.damage.records_skipped += 1
            self.damage.note(f"record {opcode:#04x} at offset {pos}: {reason_of(err)}")
            return False
        return True

    def _summary_record(self, opcode: int, body: ReadDataStream) -> None:
        if opcode == Opcode.STATISTICS:
            stats = Statistics.read(body)
            self.summary_counts = dict(stats.channel_message_counts)
        elif opcode == Opcode.CHUNK_INDEX:
            offset = ChunkIndex.read(body).chunk_start_offset
            if offset not in self._seen and self._in_file(offset):
                self._walk(offset, from_index=True)
        elif opcode == Opcode.METADATA_INDEX:
            offset = MetadataIndex.read(body).offset
            if offset not in self._seen and self._in_file(offset):
                self._walk_one(offset)
        elif opcode == Opcode.ATTACHMENT_INDEX:
            entry = AttachmentIndex.read(body)
            if self._in_file(entry.offset):
                self.attachments.setdefault(entry.name, entry.offset)

    def _walk_one(self, pos: int) -> None:
        opcode, length = HEAD.unpack_from(self._buf, pos)
        end = pos + HEAD.size + length
        if 1 <= opcode <= 0x0F and end <= len(self._buf):
            self._seen.add(pos)
            self._record(opcode, pos, end)

    def _in_file(self, offset: int) -> bool:
        return len(MAGIC) <= offset <= len(self._buf) - HEAD.size

    def _add_schema(self, schema: Schema) -> None:
        self.schemas.setdefault(schema.id, schema)

    def _add_channel(self, channel: Channel) -> None:
        self.channels.setdefault(channel.id, channel)

    # -- chunks ------------------------------------------------------------------------------
    def _chunk(self, pos: int) -> bool:
        try:
            records = inner_records(self.chunk_data(pos), wanted=None)
        except DECODE_ERRORS as err:
            self._last_chunk_lost = True
            self.damage.chunks_lost += 1
            self.damage.note(f"chunk at offset {pos}: {reason_of(err)}")
            return False
        self._last_chunk_lost = False
        times = []
        for record in records:
            if isinstance(record, Schema):
                self._add_schema(record)
            elif isinstance(record, Channel):
                self._add_channel(record)
            elif self._first(record):
                times.append(record.log_time)
        if times:
            self.chunks.append(ChunkInfo(pos, min(times), max(times)))
        return True

    def _first(self, msg: RawMessage) -> bool:
        """Count a message unless it repeats one already seen (a duplicated chunk or record)."""
        key = message_key(msg)
        if key in self._keys:
            self.duplicates += 1
            return False
        self._keys.add(key)
        self.counts[msg.channel_id] = self.counts.get(msg.channel_id, 0) + 1
        return True

    def chunk_records(self, pos: int) -> list[Schema | Channel | RawMessage]:
        """Return the schemas, channels and messages of the chunk at pos; raise if damaged."""
        return inner_records(self.chunk_data(pos), wanted=set(self.channels) | {-1})

    def chunk_data(self, pos: int) -> bytes:
        """Return the decompressed, CRC-checked records of the chunk at pos; raise if damaged.

        The chunk's pages are then given back (MADV_DONTNEED): the file is mapped whole, and
        pages once read would otherwise stay resident, so the resident set would grow with the
        recording (300 simulated frames: 670 MB instead of 380).
        """
        try:
            return chunk_payload(self._buf, pos)
        finally:
            self._release(pos)

    def _release(self, pos: int) -> None:
        if not isinstance(self._buf, mmap.mmap) or pos + HEAD.size > len(self._buf):
            return
        _, length = HEAD.unpack_from(self._buf, pos)
        start = pos - pos % mmap.PAGESIZE
        end = min(len(self._buf), pos + HEAD.size + length)
        if end > start:
            self._buf.madvise(mmap.MADV_DONTNEED, start, end - start)

    def messages(self, channel_ids: set[int]) -> Iterator[RawMessage]:
        """Yield the messages of these channels from the intact data, in log-time order.

        Chunks are read one at a time (ordered by their first message), merged with a heap
        where their times overlap, so memory stays at a few chunks whatever the file's size.
        """
        units = [(c.start_ns, c.offset, True) for c in self.chunks]
        units += [(t, offset, False) for t, offset in self.loose]
        units.sort()
        heap: list[tuple[int, int, RawMessage]] = []
        keys: set[tuple[int, int, int, int, int]] = set()
        order = 0
        i = 0
        while i < len(units) or heap:
            while i < len(units) and (not heap or units[i][0] <= heap[0][0]):
                for msg in self._unit(units[i][1], chunk=units[i][2], wanted=channel_ids):
                    if msg.channel_id in channel_ids and message_key(msg) not in keys:
                        keys.add(message_key(msg))  # duplicates were counted by the scan
                        heapq.heappush(heap, (msg.log_time, order, msg))
                        order += 1
                i += 1
            if heap:
                yield heapq.heappop(heap)[2]

    def _unit(self, pos: int, *, chunk: bool, wanted: set[int]) -> list[RawMessage]:
        try:
            if chunk:
                records = inner_records(self.chunk_data(pos), wanted=wanted)
                return [r for r in records if isinstance(r, RawMessage)]
            _, length = HEAD.unpack_from(self._buf, pos)
            body = self._buf[pos + HEAD.size : pos + HEAD.size + length]
            return [read_message(ReadDataStream(io.BytesIO(body)), length)]
        except DECODE_ERRORS as err:  # a chunk the summary vouched for (scan(verify=False))
            self.damage.chunks_lost += 1
            self.damage.note(f"chunk at offset {pos}: {reason_of(err)}")
            return []

    def attachment(self, name: str) -> bytes | None:
        """Return the data of the named attachment, or None when absent or unreadable."""
        pos = self.attachments.get(name)
        if pos is None:
            return None
        try:
            _, length = HEAD.unpack_from(self._buf, pos)
            body = self._buf[pos + HEAD.size : pos + HEAD.size + length]
            att = Attachment.read(ReadDataStream(io.BytesIO(body)))
            (crc,) = struct.unpack_from("<I", body, len(body) - 4)
            if crc and zlib.crc32(body[:-4]) != crc:
                raise DamagedError("attachment CRC mismatch")
        except DECODE_ERRORS as err:
            logger.warning("attachment %r is unreadable (%s): %s", name, reason_of(err), self.path)
            return None
        return att.data if att.name == name else None

    # -- after the walk ------------------------------------------------------------------------
    def _times(self) -> None:
        starts = [c.start_ns for c in self.chunks] + [t for t, _ in self.loose]
        ends = [c.end_ns for c in self.chunks] + [t for t, _ in self.loose]
        if starts:
            self.start_ns, self.end_ns = min(starts), max(ends)

    def _lost_from_summary(self) -> None:
        if self.summary_counts is None:
            return
        lost = {
            cid: n - self.counts.get(cid, 0)
            for cid, n in self.summary_counts.items()
            if n > self.counts.get(cid, 0)
        }
        for cid, n in lost.items():
            self.damage.lost_by_channel[cid] = max(n, self.damage.lost_by_channel.get(cid, 0))
