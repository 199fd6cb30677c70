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
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import lz4.frame
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.reader import SeekingReader
from mcap.records import (
    Attachment,
    AttachmentIndex,
    Channel,
    ChunkIndex,
    Message,
    MessageIndex,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
)

logger = logging.getLogger(__name__)

MAGIC: Final = b"\x89MCAP0\r\n"
MAX_CHUNK_BYTES: Final = 1 << 31  # a chunk that claims more is damaged (ours are 64 MiB)
# Third-party decoders of untrusted bytes (zstandard, lz4, mcap's record parsers) raise errors
# with no common base (ZstdError, RuntimeError, UnicodeDecodeError, struct.error, ...): every
# one of them means "this chunk or record is damaged", which is skipped and counted.
DECODE_ERRORS: Final = (Exception,)
_HEAD: Final = struct.Struct("<BQ")
_MESSAGE_FIXED: Final = struct.Struct("<HIQQ")  # channel, sequence, log time, publish time
_CHUNK_FIXED: Final = struct.Struct("<QQQII")  # start, end, uncompressed size, crc, name length
_RESYNC: Final = (b"\x04\x00\x00\x00zstd", b"\x03\x00\x00\x00lz4")  # compression names
_NAME_AT: Final = 9 + 8 + 8 + 8 + 4  # offset of the compression name's length in a chunk


class DamagedError(Exception):
    """A chunk or record that cannot be read (internal: always caught and counted)."""


@dataclass(frozen=True, slots=True)
class RawMessage:
    """A message record: its header and, when it was asked for, its payload."""

    channel_id: int
    sequence: int
    log_time: int
    publish_time: int
    size: int  # of the payload in the file
    data: bytes  # the payload, or b"" when only counted


@dataclass(slots=True)
class ChunkInfo:
    """An intact chunk: where it is and the log times of its messages."""

    offset: int
    start_ns: int
    end_ns: int


@dataclass(slots=True)
class Damage:
    """What a walk could not read."""

    chunks_lost: int = 0
    lost_by_channel: dict[int, int] = field(default_factory=dict)  # where the file says
    records_skipped: int = 0
    bytes_skipped: int = 0
    truncated: bool = False  # the file ends inside a record
    reasons: list[str] = field(default_factory=list)  # the first few, for the log

    def note(self, reason: str) -> None:
        """Remember a reason (the first five)."""
        if len(self.reasons) < 5:
            self.reasons.append(reason)

    @property
    def any(self) -> bool:
        """Return whether anything was lost."""
        return bool(
            self.chunks_lost or self.records_skipped or self.bytes_skipped or self.lost_by_channel
        )


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

    def _walk(self, pos: int, *, from_index: bool = False) -> None:
        """Walk records from pos; from_index: pos came from the summary, trust it less."""
        buf, size = self._buf, len(self._buf)
        if from_index and not self._plausible(pos):
            return  # a stale or damaged index entry: the linear walk covers the data
        while pos + _HEAD.size <= size:
            opcode, length = _HEAD.unpack_from(buf, pos)
            end = pos + _HEAD.size + length
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
        if pos + _HEAD.size > len(self._buf):
            return pos == len(self._buf)
        opcode, length = _HEAD.unpack_from(self._buf, pos)
        return bool(1 <= opcode <= 0x0F and pos + _HEAD.size + length <= len(self._buf))

    def _next_chunk(self, pos: int) -> int | None:
        """Return the offset of the next plausible compressed chunk header at or after pos."""
        best: int | None = None
        for name in _RESYNC:
            at = self._buf.find(name, pos + _NAME_AT - 1)
            while at >= 0:
                start = at - _NAME_AT
                if start >= pos and self._plausible_chunk(start):
                    break
                at = self._buf.find(name, at + 1)
            if at >= 0 and (best is None or at - _NAME_AT < best):
                best = at - _NAME_AT
        return best

    def _plausible_chunk(self, pos: int) -> bool:
        opcode, length = _HEAD.unpack_from(self._buf, pos)
        return bool(opcode == Opcode.CHUNK and pos + _HEAD.size + length <= len(self._buf))

    def _footer_summary_start(self) -> int | None:
        size = len(self._buf)
        footer = size - len(MAGIC) - _HEAD.size - 20
        if footer < len(MAGIC) or bytes(self._buf[size - len(MAGIC) :]) != MAGIC:
            return None
        opcode, length = _HEAD.unpack_from(self._buf, footer)
        if opcode != Opcode.FOOTER or length != 20:
            return None
        start: int = struct.unpack_from("<Q", self._buf, footer + _HEAD.size)[0]
        return start if len(MAGIC) <= start < footer else None

    def _record(self, opcode: int, pos: int, end: int) -> bool:
        """Take one top-level record; return False when it could not be read (counted)."""
        try:
            if opcode == Opcode.CHUNK:
                return self._chunk(pos)
            body = ReadDataStream(io.BytesIO(self._buf[pos + _HEAD.size : end]))
            length = end - pos - _HEAD.size
            if opcode == Opcode.SCHEMA:
                self._add_schema(Schema.read(body))
            elif opcode == Opcode.CHANNEL:
                self._add_channel(Channel.read(body))
            elif opcode == Opcode.MESSAGE:
                msg = _message(body, length)
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
            self.damage.note(f"record {opcode:#04x} at offset {pos}: {_reason(err)}")
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
        opcode, length = _HEAD.unpack_from(self._buf, pos)
        end = pos + _HEAD.size + length
        if 1 <= opcode <= 0x0F and end <= len(self._buf):
            self._seen.add(pos)
            self._record(opcode, pos, end)

    def _in_file(self, offset: int) -> bool:
        return len(MAGIC) <= offset <= len(self._buf) - _HEAD.size

    def _add_schema(self, schema: Schema) -> None:
        self.schemas.setdefault(schema.id, schema)

    def _add_channel(self, channel: Channel) -> None:
        self.channels.setdefault(channel.id, channel)

    # -- chunks ------------------------------------------------------------------------------
    def _chunk(self, pos: int) -> bool:
        try:
            records = _inner_records(self.chunk_data(pos), wanted=None)
        except DECODE_ERRORS as err:
            self._last_chunk_lost = True
            self.damage.chunks_lost += 1
            self.damage.note(f"chunk at offset {pos}: {_reason(err)}")
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
        key = _key(msg)
        if key in self._keys:
            self.duplicates += 1
            return False
        self._keys.add(key)
        self.counts[msg.channel_id] = self.counts.get(msg.channel_id, 0) + 1
        return True

    def chunk_records(self, pos: int) -> list[Schema | Channel | RawMessage]:
        """Return the schemas, channels and messages of the chunk at pos; raise if damaged."""
        return _inner_records(self.chunk_data(pos), wanted=set(self.channels) | {-1})

    def chunk_data(self, pos: int) -> bytes:
        """Return the decompressed, CRC-checked records of the chunk at pos; raise if damaged."""
        buf = self._buf
        opcode, length = _HEAD.unpack_from(buf, pos)
        end = pos + _HEAD.size + length
        _, _, size, crc, name_len = _CHUNK_FIXED.unpack_from(buf, pos + _HEAD.size)
        if opcode != Opcode.CHUNK or end > len(buf) or name_len > 16 or size > MAX_CHUNK_BYTES:
            raise DamagedError(f"implausible chunk header (size {size}, name length {name_len})")
        name = bytes(buf[pos + _NAME_AT + 4 : pos + _NAME_AT + 4 + name_len]).decode("ascii")
        data_at = pos + _NAME_AT + 4 + name_len + 8
        (data_len,) = struct.unpack_from("<Q", buf, data_at - 8)
        if data_at + data_len > end:
            raise DamagedError(f"chunk data of {data_len} bytes runs past its record")
        data = _decompress(name, bytes(buf[data_at : data_at + data_len]), size)
        if crc and zlib.crc32(data) != crc:
            raise DamagedError("chunk CRC mismatch")
        return data

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
                    if msg.channel_id in channel_ids and _key(msg) not in keys:
                        keys.add(_key(msg))  # duplicates were counted by the scan
                        heapq.heappush(heap, (msg.log_time, order, msg))
                        order += 1
                i += 1
            if heap:
                yield heapq.heappop(heap)[2]

    def _unit(self, pos: int, *, chunk: bool, wanted: set[int]) -> list[RawMessage]:
        try:
            if chunk:
                records = _inner_records(self.chunk_data(pos), wanted=wanted)
                return [r for r in records if isinstance(r, RawMessage)]
            _, length = _HEAD.unpack_from(self._buf, pos)
            body = self._buf[pos + _HEAD.size : pos + _HEAD.size + length]
            return [_message(ReadDataStream(io.BytesIO(body)), length)]
        except DECODE_ERRORS as err:  # a chunk the summary vouched for (scan(verify=False))
            self.damage.chunks_lost += 1
            self.damage.note(f"chunk at offset {pos}: {_reason(err)}")
            return []

    def attachment(self, name: str) -> bytes | None:
        """Return the data of the named attachment, or None when absent or unreadable."""
        pos = self.attachments.get(name)
        if pos is None:
            return None
        try:
            _, length = _HEAD.unpack_from(self._buf, pos)
            body = self._buf[pos + _HEAD.size : pos + _HEAD.size + length]
            att = Attachment.read(ReadDataStream(io.BytesIO(body)))
            (crc,) = struct.unpack_from("<I", body, len(body) - 4)
            if crc and zlib.crc32(body[:-4]) != crc:
                raise DamagedError("attachment CRC mismatch")
        except DECODE_ERRORS as err:
            logger.warning("attachment %r is unreadable (%s): %s", name, _reason(err), self.path)
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


def _decompress(name: str, data: bytes, size: int) -> bytes:
    if name == "zstd":
        declared = zstandard.frame_content_size(data)
        if declared not in (-1, size):
            raise DamagedError(f"zstd frame declares {declared} bytes, chunk header {size}")
        out: bytes = zstandard.ZstdDecompressor().decompress(data, max_output_size=size)
    elif name == "lz4":
        out = lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=size)
    elif name == "":
        out = data
    else:
        raise DamagedError(f"unknown chunk compression {name!r}")
    if len(out) != size:
        raise DamagedError(f"chunk decompressed to {len(out)} bytes, header says {size}")
    return out


def _inner_records(data: bytes, *, wanted: set[int] | None) -> list[Schema | Channel | RawMessage]:
    """Return a chunk's schemas, channels and messages (data only of the wanted channels)."""
    records: list[Schema | Channel | RawMessage] = []
    pos = 0
    while pos < len(data):
        if pos + _HEAD.size > len(data):
            raise DamagedError("chunk ends inside a record header")
        opcode, length = _HEAD.unpack_from(data, pos)
        body_at, end = pos + _HEAD.size, pos + _HEAD.size + length
        if end > len(data):
            raise DamagedError("chunk record runs past the chunk")
        if opcode == Opcode.MESSAGE:
            if length < _MESSAGE_FIXED.size:
                raise DamagedError(f"message record of {length} bytes (at least 22)")
            channel, sequence, log_time, publish_time = _MESSAGE_FIXED.unpack_from(data, body_at)
            size = length - _MESSAGE_FIXED.size
            keep = wanted is not None and channel in wanted
            payload = data[body_at + _MESSAGE_FIXED.size : end] if keep else b""
            records.append(RawMessage(channel, sequence, log_time, publish_time, size, payload))
        elif opcode in (Opcode.SCHEMA, Opcode.CHANNEL):
            body = ReadDataStream(io.BytesIO(data[body_at:end]))
            records.append(Schema.read(body) if opcode == Opcode.SCHEMA else Channel.read(body))
        pos = end
    return records


def _message(body: ReadDataStream, length: int) -> RawMessage:
    if length < _MESSAGE_FIXED.size:
        raise DamagedError(f"message record of {length} bytes (at least 22)")
    msg = Message.read(body, length)
    size = length - _MESSAGE_FIXED.size
    return RawMessage(msg.channel_id, msg.sequence, msg.log_time, msg.publish_time, size, msg.data)


def _key(msg: RawMessage) -> tuple[int, int, int, int, int]:
    return msg.channel_id, msg.log_time, msg.publish_time, msg.sequence, msg.size


def _reason(err: BaseException) -> str:
    text = str(err).splitlines()[0][:100] if str(err) else ""
    return f"{type(err).__name__}: {text}" if text else type(err).__name__
