"""The benchmark commands refuse bad arguments in one line (exit 2); map_pictures draws."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from helpers_refine import grid_patch, labelled

from benchmarks.__main__ import main as bench_main
from benchmarks.map_pictures import TITLE_PX
from benchmarks.map_pictures import main as pictures_main
from process import outputs
from process.cloud import write_ply


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


def test_map_pictures_titles_each_view_above_the_map(tmp_path: Path) -> None:
    """Two top views side by side, each under a white band holding only its black title."""
    floor = grid_patch((0.0, 3.0), (0.0, 2.0), step=0.03)
    table = grid_patch((0.0, 1.0), (0.0, 0.6), z=0.75, step=0.03)  # in the top-left corner
    cloud = labelled(
        np.concatenate([floor, table]), np.r_[np.full(len(floor), 2), np.full(len(table), 4)]
    )
    for name in (outputs.MAP_FUSED, outputs.MAP_REFINED):
        write_ply(tmp_path / name, cloud)
    out = tmp_path / "maps.png"
    assert pictures_main([str(tmp_path), str(out)]) == 0
    image = cv2.imread(str(out))
    assert image is not None
    band = image[:TITLE_PX].reshape(-1, 3).astype(int)
    grey = (band.max(axis=1) - band.min(axis=1)) < 8  # white paper, black text, antialiasing
    assert grey.all() and (band < 60).all(axis=1).any()  # some title text, no map colour
    assert (image[TITLE_PX:] != 255).any(axis=2).any()  # the maps below


@pytest.mark.parametrize("content", [None, b"not a checkpoint"])
def test_seg_models_refuses_a_bad_checkpoint_in_one_line(
    content: bytes | None, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from benchmarks.seg_models import main as seg_models_main

    checkpoint = tmp_path / "student.safetensors"
    if content is not None:
        checkpoint.write_bytes(content)
    assert seg_models_main([str(checkpoint)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("seg_models:") and "student" in err
