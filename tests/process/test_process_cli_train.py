"""`semreplay-process train` smoke test: a one-epoch run writes a checkpoint `run` accepts."""

from __future__ import annotations

from pathlib import Path

from helpers_seg import write_labelled_recording
from typer.testing import CliRunner

from process.cli import app
from process.segmentation.weights import load_checkpoint

runner = CliRunner()


def test_train_writes_a_checkpoint_usable_with_weights(tmp_path: Path) -> None:
    rec = write_labelled_recording(tmp_path / "train.mcap", frames=4, seed=1)
    val = write_labelled_recording(tmp_path / "val.mcap", frames=2, seed=2)
    out = tmp_path / "ckpt.safetensors"
    result = runner.invoke(
        app, ["train", str(rec), "--val", str(val), "--out", str(out), "--epochs", "1"]
    )
    assert result.exit_code == 0, result.output
    assert f"checkpoint written: {out} (use it with --weights {out})" in result.output
    assert load_checkpoint(out).info["epoch"] == 1


def test_train_refuses_a_recording_without_labels(recording: Path, tmp_path: Path) -> None:
    result = runner.invoke(app, ["train", str(recording), "--out", str(tmp_path / "c.pt")])
    assert result.exit_code == 1
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and "ground_truth/labels" in lines[0]
    assert not (tmp_path / "c.pt").exists()
