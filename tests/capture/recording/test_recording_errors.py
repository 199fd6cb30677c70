"""Bad recordings give one-line errors that name what was expected, what was found and the file."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from capture.errors import RecordingError
from capture.recording import Intrinsics, RecordingReader, RecordingWriter
from capture.recording import messages as m

K = Intrinsics(32, 24, 30.0, 30.0, 16.0, 12.0)
NS = m.DEFAULT_NAMESPACE
T_NS = 5_000_000_000


def _read_all(path: Path) -> str:
    with pytest.raises(RecordingError) as info, RecordingReader(path) as rec:
        list(rec.frames())
    text = str(info.value)
    assert "\n" not in text
    assert text.endswith(str(path))
    return text


def _image(encoding: str, *, width: int = 32, height: int = 24, bpp: int = 3) -> dict[str, object]:
    data = bytes(width * height * bpp)
    return m.image(T_NS, m.COLOR_FRAME_ID, width=width, height=height, encoding=encoding,
                   step=width * bpp, data=data)  # fmt: skip


def _info(k: Intrinsics) -> dict[str, object]:
    return m.camera_info(T_NS, m.COLOR_FRAME_ID, width=k.width, height=k.height,
                         k=(k.fx, k.fy, k.cx, k.cy), distortion_model="plumb_bob",
                         coeffs=k.coeffs)  # fmt: skip


def _recording(path: Path, messages: list[tuple[str, str, dict[str, object]]]) -> Path:
    with RecordingWriter(path) as w:
        for topic, datatype, msg in messages:
            w.write_message(topic, datatype, msg, stamp_ns=T_NS, log_ns=T_NS)
    return path


COLOR = (NS + m.COLOR_IMAGE, m.IMAGE, _image("rgb8"))
COLOR_INFO = (NS + m.COLOR_INFO, m.CAMERA_INFO, _info(K))
DEPTH = (NS + m.ALIGNED_DEPTH_IMAGE, m.IMAGE, _image("16UC1", bpp=2))
DEPTH_INFO = (NS + m.ALIGNED_DEPTH_INFO, m.CAMERA_INFO, _info(K))


def test_a_missing_file(tmp_path: Path) -> None:
    text = _read_all(tmp_path / "nothing.mcap")
    assert text.startswith("cannot open recording: No such file or directory")


@pytest.mark.parametrize("content", [b"", b"hello, not a recording\n", b"\x89PNG\r\n\x1a\n" * 8])
def test_not_an_mcap(tmp_path: Path, content: bytes) -> None:
    path = tmp_path / "x.mcap"
    path.write_bytes(content)
    assert _read_all(path).startswith("not an MCAP file (bad magic bytes)")


def test_no_colour_topic_lists_what_was_found(tmp_path: Path) -> None:
    path = _recording(tmp_path / "c.mcap", [DEPTH, DEPTH_INFO])
    text = _read_all(path)
    assert text.startswith("no colour topic")
    assert f"found: {NS}{m.ALIGNED_DEPTH_IMAGE} ({m.IMAGE})" in text


def test_no_depth_topic(tmp_path: Path) -> None:
    text = _read_all(_recording(tmp_path / "d.mcap", [COLOR, COLOR_INFO]))
    assert text.startswith(f"no depth topic ('{NS}{m.DEPTH_IMAGE}'")
    assert f"found: {NS}{m.COLOR_IMAGE} ({m.IMAGE}), {NS}{m.COLOR_INFO}" in text


def test_no_colour_camera_info(tmp_path: Path) -> None:
    text = _read_all(_recording(tmp_path / "i.mcap", [COLOR, DEPTH, DEPTH_INFO]))
    assert text.startswith(f"no colour camera_info ('{NS}{m.COLOR_INFO}'")


def test_unaligned_depth_without_extrinsics(tmp_path: Path) -> None:
    raw = (NS + m.DEPTH_IMAGE, m.IMAGE, _image("16UC1", bpp=2))
    raw_info = (NS + m.DEPTH_INFO, m.CAMERA_INFO, _info(K))
    text = _read_all(_recording(tmp_path / "u.mcap", [COLOR, COLOR_INFO, raw, raw_info]))
    assert f"unaligned depth '{NS}{m.DEPTH_IMAGE}' needs the depth->colour extrinsics" in text


@pytest.mark.parametrize(
    ("bad", "expected"),
    [
        ((NS + m.COLOR_IMAGE, m.IMAGE, _image("yuv422", bpp=2)), "has colour encoding 'yuv422'"),
        ((NS + m.ALIGNED_DEPTH_IMAGE, m.IMAGE, _image("8UC1", bpp=1)), "has depth encoding '8UC1'"),
        (
            (NS + m.COLOR_IMAGE, m.IMAGE, _image("rgb8", width=16, height=12)),
            "image is 16x12 but its camera_info says 32x24",
        ),
        (
            (NS + m.COLOR_IMAGE, m.IMAGE, {**_image("rgb8"), "data": bytes(100)}),
            "needs 2304 bytes (step 96), found 100 bytes",
        ),
    ],
    ids=["colour-encoding", "depth-encoding", "size-mismatch", "short-data"],
)
def test_bad_images_name_the_topic_and_what_was_found(
    tmp_path: Path, bad: tuple[str, str, dict[str, object]], expected: str
) -> None:
    messages = [COLOR, COLOR_INFO, DEPTH, DEPTH_INFO]
    messages = [bad if msg[0] == bad[0] else msg for msg in messages]
    text = _read_all(_recording(tmp_path / "bad.mcap", messages))
    assert f"'{bad[0]}'" in text
    assert expected in text


@pytest.mark.parametrize(
    ("call", "expected"),
    [
        (lambda w: w.write_color(np.zeros((4, 4), np.uint8), stamp_ns=0, intrinsics=K),
         r"colour must be \(H, W, 3\) uint8, got \(4, 4\) uint8: .*w\.mcap$"),
        (lambda w: w.write_depth(np.zeros((4, 4), np.float32), stamp_ns=0, intrinsics=K),
         r"depth must be \(H, W\) uint16 mm, got \(4, 4\) float32: .*w\.mcap$"),
    ],
)  # fmt: skip
def test_the_writer_refuses_wrong_arrays(
    tmp_path: Path, call: Callable[[RecordingWriter], None], expected: str
) -> None:
    with RecordingWriter(tmp_path / "w.mcap") as w, pytest.raises(RecordingError, match=expected):
        call(w)


def test_the_writer_refuses_an_unknown_compression_and_an_unwritable_path(tmp_path: Path) -> None:
    with pytest.raises(
        RecordingError, match=r"unknown compression 'gzip'; expected one of .*w\.mcap$"
    ):
        RecordingWriter(tmp_path / "w.mcap", compression="gzip")
    (tmp_path / "a_file").write_text("not a folder")
    with pytest.raises(RecordingError, match=r"cannot create recording: .*a_file/w.mcap$"):
        RecordingWriter(tmp_path / "a_file" / "w.mcap")
    RecordingWriter(tmp_path / "new" / "folder" / "w.mcap").finish()  # missing folders are made
    assert (tmp_path / "new" / "folder" / "w.mcap").is_file()
