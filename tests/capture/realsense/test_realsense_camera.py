"""With a real D435 attached (`pytest -m camera`): record two seconds and replay them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from capture.cli import app
from capture.recording import RecordingReader

pytestmark = pytest.mark.camera


@pytest.mark.parametrize("align", [False, True])
def test_a_real_d435_records_two_seconds_without_drops(tmp_path: Path, align: bool) -> None:
    out = tmp_path / "d435.mcap"
    args = ["record", str(out), "--duration", "2", *(["--align"] if align else [])]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    with RecordingReader(out) as rec:
        assert rec.finished and rec.aligned == align
        assert rec.metadata["device"]["name"].startswith("Intel RealSense D4")
        frames = list(rec.frames())
    assert len(frames) >= 50  # 2 s at 30 fps, allowing for the start-up
    assert all(np.count_nonzero(f.depth_m) > 0.3 * f.depth_m.size for f in frames[10:])
    stamps = np.diff([f.stamp_ns for f in frames])
    assert np.all(stamps > 0) and np.median(stamps) == pytest.approx(33_333_333, rel=0.1)
