"""The benchmark commands refuse bad arguments in one line (exit 2), without running anything."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks.__main__ import main as bench_main
from benchmarks.map_pictures import main as pictures_main


def test_an_unknown_area_is_named_with_the_known_ones(capsys: pytest.CaptureFixture[str]) -> None:
    assert bench_main(["refine", "nosuch"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no benchmark matches nosuch" in err and "refine" in err


@pytest.mark.parametrize("argv", [[], ["only-one"], ["{missing}", "out.png"]])
def test_map_pictures_wants_a_run_folder(
    argv: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = [a.format(missing=tmp_path / "missing") for a in argv]
    assert pictures_main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(("usage:", "map_pictures:"))
    assert not (tmp_path / "out.png").exists()
