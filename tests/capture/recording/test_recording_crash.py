"""A killed writer or a full disk still leaves a recording that replays all but its last second."""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import IO, cast

import numpy as np
import pytest
from helpers_capture import (
    COLOR_H,
    COLOR_W,
    ROOT,
    FullDisk,
    color_image,
    expected_intrinsics,
)

from capture.errors import RecordingError
from capture.realsense.sink import StreamFrame, ThreadedWriter, finish_recording
from capture.recording import RecordingReader, RecordingWriter

HELPER = ROOT / "tests" / "helpers_capture.py"


def _recover(path: Path, caplog: pytest.LogCaptureFixture) -> tuple[bool, list[int]]:
    """Return (finished, frame numbers) read back, and check the single recovery warning."""
    with (
        caplog.at_level(logging.WARNING, logger="capture.recording.reader"),
        RecordingReader(path) as rec,
    ):
        finished = rec.finished
        frames = [f for f in rec.frames()]
    candidates = [color_image(i) for i in range(len(frames) + 20)]
    numbers = [
        next(i for i, c in enumerate(candidates) if np.array_equal(f.color, c)) for f in frames
    ]
    recovered = [r for r in caplog.records if "recovered" in r.getMessage()]
    assert len(recovered) == (0 if finished else 1)
    if recovered:
        assert f"recovered {len(frames)} frames: {path}" in recovered[0].getMessage()
    return finished, numbers


def test_sigkill_loses_at_most_the_last_second(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    out = tmp_path / "killed.mcap"
    env = {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{ROOT / 'tests'}"}
    child = subprocess.Popen(
        [sys.executable, str(HELPER), "kill-writer", str(out)],
        stdout=subprocess.PIPE, text=True, env=env,
    )  # fmt: skip
    assert child.stdout is not None
    written = -1
    deadline = time.monotonic() + 30.0
    while written < 30 and time.monotonic() < deadline:  # ~3 s of frames at 10 per second
        written = int(child.stdout.readline().split()[1])
    child.send_signal(signal.SIGKILL)
    child.wait(10)
    assert written >= 30
    finished, numbers = _recover(out, caplog)
    assert not finished
    assert numbers == list(range(len(numbers)))  # in order, none missing, none invented
    # Chunks close every second of recording: frames written more than 1 s (10 frames) before
    # the kill are on disk; one more may have been written after the last line was read.
    assert written - 11 <= len(numbers) <= written + 2, (written, len(numbers))


def test_a_full_disk_stops_the_writer_and_leaves_a_readable_file(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    path = tmp_path / "full.mcap"
    k = expected_intrinsics("color")
    frame_bytes = COLOR_W * COLOR_H * 5  # colour and aligned depth, before compression
    writer = RecordingWriter(
        path,
        compression="none",
        stream=cast(IO[bytes], FullDisk(path.open("wb"), 40 * frame_bytes)),
    )
    sink = ThreadedWriter(writer, color_intrinsics=k, depth_intrinsics=k, aligned=True,
                          blocking=True)  # fmt: skip
    sink.start()
    t0 = 1_000_000_000
    for i in range(100):  # 10 frames per second of recording: a chunk every 10 frames
        stamp = t0 + i * 100_000_000
        depth = np.full((COLOR_H, COLOR_W), 1000 + i, np.uint16)
        sink.submit(StreamFrame("color", i, stamp, stamp, color_image(i)))
        sink.submit(StreamFrame("depth", i, stamp, stamp, depth))
    stats = sink.stop()
    assert isinstance(sink.error, RecordingError)
    assert str(sink.error).startswith("disk full after ")
    assert str(sink.error).endswith(f"(what was written so far replays): {path}")
    with pytest.raises(RecordingError, match="disk full"):
        finish_recording(writer, sink.summary(stats))
    finished, numbers = _recover(path, caplog)
    assert not finished
    assert numbers == list(range(len(numbers)))
    assert 20 <= len(numbers) < 40, len(
        numbers
    )  # every chunk that fitted, not the one that did not
