"""librealsense's recorder writes a .db3 of known frames; `convert` makes them our MCAP exactly."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from helpers_capture import (
    STAMP0_MS,
    SoftCamera,
    color_image,
    depth_image,
    expected_extrinsics,
    expected_intrinsics,
)

from capture.errors import CameraError
from capture.realsense.record import convert
from capture.recording import RecordingReader
from capture.recording import messages as m

FRAMES = 8


@pytest.fixture(scope="module")
def db3(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("rs") / "camera.db3"
    SoftCamera(fps=30).record_file(path, FRAMES)
    return path


def test_every_frame_once_and_bit_exact(db3: Path, tmp_path: Path) -> None:
    result = convert(db3, tmp_path / "out.mcap")
    assert result.frames_written == {"color": FRAMES, "depth": FRAMES}
    assert result.frames_dropped == {"color": 0, "depth": 0}
    with RecordingReader(tmp_path / "out.mcap") as rec:
        assert rec.finished and not rec.aligned
        ns = m.DEFAULT_NAMESPACE
        for suffix in (m.COLOR_IMAGE, m.COLOR_INFO, m.DEPTH_IMAGE, m.DEPTH_INFO):
            assert rec.topics[ns + suffix].count == FRAMES  # no duplicates from framesets
        frames = list(rec.frames())
    assert len(frames) == FRAMES
    for i, frame in enumerate(frames):
        np.testing.assert_array_equal(frame.color, color_image(i))
        raw_mm = np.rint(frame.depth_m * np.float32(1000.0)).astype(np.uint16)
        np.testing.assert_array_equal(raw_mm, depth_image(i))
        assert frame.stamp_ns == round((STAMP0_MS + i * 1000.0 / 30) * 1e6)
        assert frame.metadata["frame_number"] == str(i)


def test_the_recorded_calibration_comes_through(db3: Path, tmp_path: Path) -> None:
    convert(db3, tmp_path / "out.mcap", compression="lz4")
    with RecordingReader(tmp_path / "out.mcap") as rec:
        frame = next(iter(rec.frames()))
        device = rec.metadata["device"]
        capture = rec.metadata["capture"]
    assert frame.color_intrinsics == expected_intrinsics("color")
    assert frame.depth_intrinsics == expected_intrinsics("depth")
    assert frame.depth_to_color is not None
    # librealsense stores extrinsics as float32 transforms to a reference stream and composes
    # them again on playback: equal to the registered ones to float32 precision.
    np.testing.assert_allclose(
        frame.depth_to_color.color_from_depth, expected_extrinsics().color_from_depth, atol=1e-6
    )
    assert device["serial_number"] == "000123456789"
    assert device["name"] == "Intel RealSense D435 (software)"
    assert device["depth_scale_m"] == "0.001"
    assert capture["source"] == str(db3) and capture["frames_dropped"] == '{"color": 0, "depth": 0}'


def test_a_tenth_of_a_millimetre_unit_is_converted_to_millimetres(tmp_path: Path) -> None:
    src = tmp_path / "fine.db3"
    SoftCamera(depth_units_m=0.0001).record_file(src, 2)
    convert(src, tmp_path / "fine.mcap")
    with RecordingReader(tmp_path / "fine.mcap") as rec:
        assert rec.depth_scale_m == 0.001
        frames = list(rec.frames())
    for i, frame in enumerate(frames):
        expected_mm = (depth_image(i).astype(np.int64) + 5) // 10  # 0.1 mm units, half up
        np.testing.assert_array_equal(np.rint(frame.depth_m * np.float32(1000.0)), expected_mm)


@pytest.mark.parametrize(
    ("name", "content", "expected"),
    [
        ("missing.db3", None, "no such RealSense recording"),
        ("camera.mcap", b"\x89MCAP0\r\n", "expected a RealSense recording (.bag or .db3)"),
        ("broken.db3", b"not sqlite", "pyrealsense2 cannot play this recording"),
    ],
)  # fmt: skip
def test_bad_inputs_are_one_line_errors(
    tmp_path: Path, name: str, content: bytes | None, expected: str
) -> None:
    src = tmp_path / name
    if content is not None:
        src.write_bytes(content)
    with pytest.raises(CameraError) as info:
        convert(src, tmp_path / "out.mcap")
    text = str(info.value)
    assert text.startswith(expected) and text.endswith(str(src)) and "\n" not in text
    assert not (tmp_path / "out.mcap").exists()
