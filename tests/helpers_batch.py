"""Helpers for the batch tests: small simulated recordings, the command, its summary."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from typer.testing import CliRunner

from process.batch import summary
from process.cli import app

runner = CliRunner()
SEEDS = (1, 2, 3)
FRAMES = 12
ARGS = ("--stages", "odometry", "--no-viz")


def write_recordings(folder: Path) -> Path:
    """Write three small simulated recordings and one file that is not MCAP into folder."""
    from capture.sim import simulate_recording

    for seed in SEEDS:
        simulate_recording(
            folder / f"sim{seed}.mcap", seed=seed, frames=FRAMES, width=320, height=240
        )
    (folder / "corrupt.mcap").write_bytes(b"this is not an mcap file" * 100)
    return folder


def run_batch_cli(recordings: Path, out: Path, *extra: str) -> Any:
    """Run `semreplay-process batch RECORDINGS --out OUT --stages odometry --no-viz EXTRA`."""
    return runner.invoke(app, ["batch", str(recordings), "--out", str(out), *ARGS, *extra])


def summary_rows(out: Path) -> dict[str, dict[str, Any]]:
    """Return OUT/summary.csv's rows by name."""
    return {row["name"]: row for row in summary.read_csv(out / summary.CSV)}
