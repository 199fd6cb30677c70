"""Damaged recordings: every intact chunk replays, the lost ones are counted, info agrees."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from benchmarks.fuzz import top_level_records, write_base_recording
from capture.cli import app
from capture.errors import RecordingError
from capture.recording import RecordingReader
from capture.recording.info import describe
from capture.recording.salvage import McapSalvage, RawMessage

COLOR = "/camera/camera/color/image_raw"
DEPTH = "/camera/camera/depth/image_rect_raw"
FRAMES = 10


@pytest.fixture(scope="module")
def base(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    """Return the bytes of a 10-frame recording written in 16 small chunks."""
    path = write_base_recording(tmp_path_factory.mktemp("base") / "base.mcap", frames=FRAMES)
    return path.read_bytes()


def _chunks(data: bytes, tmp_path: Path) -> list[tuple[int, int, dict[str, list[int]]]]:
    """Return (start, end, {topic: log times}) of each chunk of an intact file."""
    path = tmp_path / "intact.mcap"
    path.write_bytes(data)
    walker = McapSalvage(path)
    walker.scan()
    out = []
    for opcode, start, end in top_level_records(data):
        if opcode != 0x06:
            continue
        topics: dict[str, list[int]] = {}
        for record in walker.chunk_records(start):
            if isinstance(record, RawMessage):
                topic = walker.channels[record.channel_id].topic
                topics.setdefault(topic, []).append(record.log_time)
        out.append((start, end, topics))
    walker.close()
    return out


def _replay(path: Path) -> tuple[list[int], list[str]]:
    with RecordingReader(path) as rec:
        stamps = [f.stamp_ns for f in rec.frames()]
        return stamps, rec.warnings


def _expected(chunks: list[tuple[int, int, dict[str, list[int]]]], lost: set[int]) -> int:
    """Return the frames whose colour and depth both survive when the chunks `lost` are gone."""
    kept = [c for i, c in enumerate(chunks) if i not in lost]
    colors = {t for _, _, topics in kept for t in topics.get(COLOR, [])}
    depths = {t for _, _, topics in kept for t in topics.get(DEPTH, [])}
    return len(colors & depths)


def test_the_base_recording_has_many_chunks_and_reads_whole(base: bytes, tmp_path: Path) -> None:
    chunks = _chunks(base, tmp_path)
    assert len(chunks) >= 10
    path = tmp_path / "r.mcap"
    path.write_bytes(base)
    stamps, warnings = _replay(path)
    assert len(stamps) == FRAMES and warnings == []
    assert describe(path).damage == ""


def test_a_dropped_chunk_loses_only_its_frames_and_says_how_many(
    base: bytes, tmp_path: Path
) -> None:
    chunks = _chunks(base, tmp_path)
    i = next(i for i, c in enumerate(chunks) if i > 2 and COLOR in c[2])
    start, end, topics = chunks[i]
    path = tmp_path / "dropped.mcap"
    path.write_bytes(base[:start] + base[end:])
    stamps, warnings = _replay(path)
    assert len(stamps) == _expected(chunks, {i}) < FRAMES
    lost_colour = len(topics[COLOR])
    assert any("messages lost: " in w and f"{COLOR} {lost_colour}" in w for w in warnings)
    info = describe(path)
    assert info.frames == len(stamps)  # info and run agree
    assert f"{COLOR} {lost_colour}" in info.damage


def test_a_corrupt_chunk_in_a_file_without_summary_is_skipped_and_counted(
    base: bytes, tmp_path: Path
) -> None:
    chunks = _chunks(base, tmp_path)
    i = len(chunks) // 2
    start, end, _ = chunks[i]
    damaged = bytearray(base[: chunks[-1][1]])  # no summary, no footer: an unfinished file
    damaged[(start + end) // 2] ^= 0xFF  # inside the compressed data
    path = tmp_path / "flipped.mcap"
    path.write_bytes(bytes(damaged))
    stamps, warnings = _replay(path)
    assert len(stamps) == _expected(chunks, {i})
    assert any("1 damaged chunk(s) skipped" in w for w in warnings)
    with RecordingReader(path) as rec:
        assert not rec.finished
    assert describe(path).frames == len(stamps)


def test_a_zeroed_range_over_a_chunk_header_still_reads_the_chunks_after_it(
    base: bytes, tmp_path: Path
) -> None:
    chunks = _chunks(base, tmp_path)
    i = len(chunks) // 2
    start = chunks[i][0]
    path = tmp_path / "zeroed.mcap"
    path.write_bytes(base[:start] + bytes(64) + base[start + 64 :])
    stamps, _ = _replay(path)
    assert len(stamps) == _expected(chunks, {i})
    last = max(t for _, _, topics in chunks for t in topics.get(COLOR, []))
    assert stamps[-1] == last  # the walk found the chunks after the damage


def test_duplicated_and_swapped_chunks_replay_each_frame_once_in_order(
    base: bytes, tmp_path: Path
) -> None:
    records = top_level_records(base)
    pieces = [base[s:e] for _, s, e in records]
    at = [i for i, (op, _, _) in enumerate(records) if op == 0x06]
    pieces[at[3]], pieces[at[6]] = pieces[at[6]], pieces[at[3]]  # swapped
    pieces.insert(at[5], pieces[at[4]])  # chunk 4 twice
    path = tmp_path / "surgery.mcap"
    path.write_bytes(base[:8] + b"".join(pieces) + base[records[-1][2] :])
    stamps, warnings = _replay(path)
    assert len(stamps) == FRAMES
    assert np.all(np.diff(stamps) > 0)
    assert any("duplicated message(s) dropped" in w for w in warnings)
    assert describe(path).frames == FRAMES


@pytest.mark.parametrize("fraction", [0.05, 0.2, 0.35, 0.5, 0.65, 0.8, 0.95, 0.999])
def test_info_and_run_agree_on_truncated_files(
    base: bytes, tmp_path: Path, fraction: float
) -> None:
    path = tmp_path / "cut.mcap"
    path.write_bytes(base[: int(len(base) * fraction)])
    try:
        stamps, _ = _replay(path)
    except RecordingError:
        stamps = []
    info = describe(path)
    assert (info.frames or 0) == len(stamps)


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (b"", "not an MCAP file"),
        (b"ply\nformat ascii 1.0\n", "not an MCAP file"),
        (b"\x89MCAP0\r\n" + bytes(3000), "nothing in this MCAP file is readable"),
    ],
)
def test_files_with_nothing_recoverable_are_one_line(
    tmp_path: Path, data: bytes, message: str
) -> None:
    path = tmp_path / "junk.mcap"
    path.write_bytes(data)
    result = CliRunner().invoke(app, ["info", str(path)])
    assert result.exit_code == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {message}")


def test_a_corrupt_attachment_is_none_not_wrong_bytes(tmp_path: Path) -> None:
    from capture.recording import RecordingWriter

    path = tmp_path / "att.mcap"
    payload = b"ply\n" + bytes(range(256)) * 8
    with RecordingWriter(path) as writer:
        writer.write_attachment("cloud.ply", payload, media_type="model/ply", log_ns=1)
    data = bytearray(path.read_bytes())
    for flip, expected in ((False, payload), (True, None)):
        if flip:
            data[data.find(payload) + 100] ^= 0x01
            path.write_bytes(bytes(data))
        walker = McapSalvage(path)
        walker.scan()
        assert walker.attachment("cloud.ply") == expected
        walker.close()


def test_a_corrupt_chunk_behind_an_intact_summary_is_found_while_replaying(
    base: bytes, tmp_path: Path
) -> None:
    chunks = _chunks(base, tmp_path)
    i = len(chunks) // 2
    start, end, _ = chunks[i]
    damaged = bytearray(base)
    damaged[(start + end) // 2] ^= 0xFF
    path = tmp_path / "flipped.mcap"
    path.write_bytes(bytes(damaged))
    stamps, warnings = _replay(path)  # the summary is trusted at open: no decompression then
    assert len(stamps) == _expected(chunks, {i})
    assert any("1 damaged chunk(s) skipped while replaying" in w for w in warnings)
    info = describe(path)  # info checks every chunk
    assert info.frames == len(stamps)
    assert "1 damaged chunk(s) skipped" in info.damage


def test_a_damaged_summary_is_not_trusted(base: bytes, tmp_path: Path) -> None:
    records = top_level_records(base)
    stats = next(s for op, s, _ in records if op == 0x0B)  # the Statistics record
    damaged = bytearray(base)
    damaged[stats + 9 + 8] ^= 0x40  # its schema count: the summary's CRC no longer matches
    path = tmp_path / "summary.mcap"
    path.write_bytes(bytes(damaged))
    walker = McapSalvage(path)
    assert not walker._summary_crc_ok()
    walker.close()
    stamps, _ = _replay(path)  # read by the walk instead, every frame intact
    assert len(stamps) == FRAMES
