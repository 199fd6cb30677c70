"""benchmarks.viewer_screenshot refuses what it cannot show in one line."""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers_browser import have_chromium

from benchmarks import viewer_screenshot


@pytest.mark.skipif(have_chromium() is not None, reason=str(have_chromium()))
def test_a_missing_rrd_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    missing = tmp_path / "none.rrd"
    assert viewer_screenshot.main([str(missing), str(tmp_path / "out.png")]) == 2
    out = capsys.readouterr().out.strip().splitlines()
    assert out == [f"expected a .rrd file, found nothing at {missing}"]
    assert not (tmp_path / "out.png").exists()


@pytest.mark.skipif(have_chromium() is not None, reason=str(have_chromium()))
def test_a_file_that_is_not_an_rrd_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    text = tmp_path / "notes.rrd"
    text.write_text("not a recording\n")
    assert viewer_screenshot.main([str(text), str(tmp_path / "out.png"), "--port", "9290"]) == 2
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1 and out[0].startswith(f"no screenshot of {text}: ")
    assert not (tmp_path / "out.png").exists()
