"""MCAP records read defensively: bounded chunk decompression, message headers without copies.

Used by `salvage.McapSalvage`; every function raises (DamagedError or the decoder's own error)
on damaged bytes, and the caller skips and counts what raised.
"""

from __future__ import annotations

import io
import struct
import zlib
from dataclasses import dataclass, field
from typing import Any, Final

import lz4.frame
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Channel, Message, Schema

MAGIC: Final = b"\x89MCAP0\r\n"
MAX_CHUNK_BYTES: Final = 1 << 31  # a chunk that claims more is damaged (ours are 64 MiB)
# Third-party decoders of untrusted bytes (zstandard, lz4, mcap's record parsers) raise errors
# with no common base (ZstdError, RuntimeError, UnicodeDecodeError, struct.error, ...): every
# one of them means "this chunk or record is damaged", which is skipped and counted.
DECODE_ERRORS: Final = (Exception,)
HEAD: Final = struct.Struct("<BQ")
MESSAGE_FIXED: Final = struct.Struct("<HIQQ")  # channel, sequence, log time, publish time
CHUNK_FIXED: Final = struct.Struct("<QQQII")  # start, end, uncompressed size, crc, name length
RESYNC: Final = (b"\x04\x00\x00\x00zstd", b"\x03\x00\x00\x00lz4")  # compression names
NAME_AT: Final = 9 + 8 + 8 + 8 + 4  # offset of the compression name's length in a chunk


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


def chunk_payload(buf: Any, pos: int) -> bytes:
    """Return the decompressed, CRC-checked records of the chunk at pos; raise if damaged."""
    opcode, length = HEAD.unpack_from(buf, pos)
    end = pos + HEAD.size + length
    _, _, size, crc, name_len = CHUNK_FIXED.unpack_from(buf, pos + HEAD.size)
    if opcode != Opcode.CHUNK or end > len(buf) or name_len > 16 or size > MAX_CHUNK_BYTES:
        raise DamagedError(f"implausible chunk header (size {size}, name length {name_len})")
    name = bytes(buf[pos + NAME_AT + 4 : pos + NAME_AT + 4 + name_len]).decode("ascii")
    data_at = pos + NAME_AT + 4 + name_len + 8
    (data_len,) = struct.unpack_from("<Q", buf, data_at - 8)
    if data_at + data_len > end:
        raise DamagedError(f"chunk data of {data_len} bytes runs past its record")
    data = decompress(name, bytes(buf[data_at : data_at + data_len]), size)
    if crc and zlib.crc32(data) != crc:
        raise DamagedError("chunk CRC mismatch")
    return data


def decompress(name: str, data: bytes, size: int) -> bytes:
    """Return a chunk's records, decompressed to exactly `size` bytes (no more is allocated)."""
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


def inner_records(data: bytes, *, wanted: set[int] | None) -> list[Schema | Channel | RawMessage]:
    """Return a chunk's schemas, channels and messages (data only of the wanted channels)."""
    records: list[Schema | Channel | RawMessage] = []
    pos = 0
    while pos < len(data):
        if pos + HEAD.size > len(data):
            raise DamagedError("chunk ends inside a record header")
        opcode, length = HEAD.unpack_from(data, pos)
        body_at, end = pos + HEAD.size, pos + HEAD.size + length
        if end > len(data):
            raise DamagedError("chunk record runs past the chunk")
        if opcode == Opcode.MESSAGE:
            if length < MESSAGE_FIXED.size:
                raise DamagedError(f"message record of {length} bytes (at least 22)")
            channel, sequence, log_time, publish_time = MESSAGE_FIXED.unpack_from(data, body_at)
            size = length - MESSAGE_FIXED.size
            keep = wanted is not None and channel in wanted
            payload = data[body_at + MESSAGE_FIXED.size : end] if keep else b""
            records.append(RawMessage(channel, sequence, log_time, publish_time, size, payload))
        elif opcode in (Opcode.SCHEMA, Opcode.CHANNEL):
            body = ReadDataStream(io.BytesIO(data[body_at:end]))
            records.append(Schema.read(body) if opcode == Opcode.SCHEMA else Channel.read(body))
        pos = end
    return records


def read_message(body: ReadDataStream, length: int) -> RawMessage:
    """Return a message record outside any chunk, payload included."""
    if length < MESSAGE_FIXED.size:
        raise DamagedError(f"message record of {length} bytes (at least 22)")
    msg = Message.read(body, length)
    size = length - MESSAGE_FIXED.size
    return RawMessage(msg.channel_id, msg.sequence, msg.log_time, msg.publish_time, size, msg.data)


def message_key(msg: RawMessage) -> tuple[int, int, int, int, int]:
    """Return what makes a message a duplicate of another (same channel, times, sequence, size)."""
    return msg.channel_id, msg.log_time, msg.publish_time, msg.sequence, msg.size


def reason_of(err: BaseException) -> str:
    """Return an error as a short one-line reason."""
    text = str(err).splitlines()[0][:100] if str(err) else ""
    return f"{type(err).__name__}: {text}" if text else type(err).__name__
