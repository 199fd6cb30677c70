"""`semreplay-process refine` without gravity says which up it took and how to give one."""

from __future__ import annotations

import json
from pathlib import Path

from typer.testing import CliRunner

from benchmarks.generator4 import gen4_scene
from process import outputs
from process.cli import app
from process.cloud import write_ply

runner = CliRunner()


def test_without_gravity_the_command_names_the_up_it_took_and_the_setting(tmp_path: Path) -> None:
    scene = gen4_scene(seed=0, object_points=5000)  # turned to a random frame
    cloud = tmp_path / "map.ply"
    write_ply(cloud, scene.cloud)
    guessed = runner.invoke(app, ["refine", str(cloud), "--out", str(tmp_path / "a")])
    assert guessed.exit_code == 0, guessed.output
    section = json.loads((tmp_path / "a" / outputs.METRICS).read_text())["refinement"]
    up = section["up"]
    note = next(line for line in guessed.output.splitlines() if line.startswith("gravity:"))
    assert f"[{up[0]:.3f}," in note and "set [refine] up = [x, y, z] in --config" in note
    assert f"({section['up_source']})" in note  # how it was guessed
    config = tmp_path / "up.toml"
    config.write_text(f"[refine]\nup = [{', '.join(str(v) for v in scene.up)}]\n")
    given = runner.invoke(
        app, ["refine", str(cloud), "--out", str(tmp_path / "b"), "--config", str(config)]
    )
    assert given.exit_code == 0, given.output
    assert "gravity:" not in given.output
    section = json.loads((tmp_path / "b" / outputs.METRICS).read_text())["refinement"]
    assert section["up_source"] != "largest plane"
