"""Bad config files, clouds, checkpoints and recording paths: a one-line error, never a hang."""

from __future__ import annotations

import json
import os
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from capture.cli import app as capture_app
from process import outputs
from process.cli import app
from process.cloud import LabelledCloud, parse_ply, ply_bytes, read_cloud
from process.config import MAX_CONFIG_BYTES, load_config
from process.errors import CloudError, ConfigError, ModelError
from process.segmentation.deeplab import ArchConfig
from process.segmentation.weights import Checkpoint, load_checkpoint, save_checkpoint

runner = CliRunner()


def test_a_config_with_a_utf8_bom_is_read(tmp_path: Path) -> None:
    path = tmp_path / "bom.toml"
    path.write_bytes(b"\xef\xbb\xbf[fusion]\nmin_views = 3\n")
    assert load_config(path).fusion.min_views == 3


@pytest.mark.parametrize(
    ("kind", "message"),
    [
        ("folder", "found a folder, pipe or device"),
        ("device", "found a folder, pipe or device"),
        ("huge", f"larger than {MAX_CONFIG_BYTES // 1024} KiB"),
        ("latin1", "not UTF-8 text"),
    ],
)
def test_a_config_that_is_no_small_text_file_is_one_line(
    tmp_path: Path, kind: str, message: str
) -> None:
    path = {"folder": tmp_path, "device": Path("/dev/zero")}.get(kind, tmp_path / "c.toml")
    if kind == "huge":
        path.write_text("# " + "x" * MAX_CONFIG_BYTES + "\n")
    elif kind == "latin1":
        path.write_bytes(b"# caf\xe9\n")
    with pytest.raises(ConfigError, match=message) as err:
        load_config(path)
    assert "\n" not in str(err.value)


def _ply(cloud: LabelledCloud) -> bytes:
    return ply_bytes(cloud)


def _cloud(points: np.ndarray) -> LabelledCloud:
    n = len(points)
    return LabelledCloud(
        points.astype(np.float32), np.zeros((n, 3), np.uint8), np.full(n, 4, np.uint8)
    )


def test_a_ply_with_a_duplicated_property_is_one_line() -> None:
    data = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float x\n"
    data += b"property float y\nproperty float z\nproperty uchar label\nend_header\n1 2 3 4 5\n"
    with pytest.raises(CloudError, match="declares property 'x' twice"):
        parse_ply(data, source="dup.ply")


def test_a_ply_with_absurd_coordinates_is_one_line() -> None:
    points = np.array([[0.0, 0.0, 0.0], [1e30, 0.0, 0.0]])
    with pytest.raises(CloudError, match="coordinates up to 1e\\+30 m"):
        parse_ply(_ply(_cloud(points)), source="far.ply")


@pytest.mark.parametrize("fill", [np.nan, np.inf, None])
def test_refine_on_a_cloud_without_finite_points_is_one_line(
    tmp_path: Path, fill: float | None
) -> None:
    n = 0 if fill is None else 20
    path = tmp_path / "c.ply"
    path.write_bytes(_ply(_cloud(np.full((n, 3), 0.0 if fill is None else fill))))
    result = runner.invoke(app, ["refine", str(path), "--out", str(tmp_path / "out")])
    assert result.exit_code == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.output
    assert ("is the cloud empty" if fill is None else "none of the cloud's 20 points") in lines[0]
    assert list((tmp_path / "out").iterdir()) == []


def test_read_cloud_still_reads_an_empty_map(tmp_path: Path) -> None:
    path = tmp_path / "empty.ply"
    path.write_bytes(_ply(_cloud(np.zeros((0, 3)))))
    assert len(read_cloud(path)) == 0
    with pytest.raises(CloudError, match="at least 1 finite point"):
        read_cloud(path, min_points=1)


def test_refine_titles_its_table_for_refine(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    points = np.concatenate([rng.normal(0, 0.05, (300, 3)), rng.normal(2, 0.05, (300, 3))])
    path = tmp_path / "two.ply"
    path.write_bytes(_ply(_cloud(points)))
    result = runner.invoke(app, ["refine", str(path), "--out", str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    assert "semreplay process refine" in result.stdout
    assert "semreplay process run" not in result.stdout
    final = json.loads((tmp_path / "out" / outputs.METRICS).read_text())["refinement"]["points"]
    assert f"{final['input']}" in result.stdout  # the table says how many points went in


def test_checkpoint_metadata_asking_for_absurd_shapes_is_refused_before_allocating(
    tmp_path: Path,
) -> None:
    arch = ArchConfig(aspp_channels=2**20)  # checked lazily: no layer is built here
    ckpt = Checkpoint(arch=arch, state_dict={"x": torch.zeros(1)}, class_to_label=tuple(range(11)))
    path = save_checkpoint(ckpt, tmp_path / "absurd.safetensors")
    assert path.stat().st_size < 10_000
    started = time.perf_counter()
    with pytest.raises(ModelError, match=r"aspp_channels.*expected channels <= 2048"):
        load_checkpoint(path)
    assert time.perf_counter() - started < 2.0


def test_info_on_a_fifo_says_so_and_does_not_hang(tmp_path: Path) -> None:
    fifo = tmp_path / "pipe.mcap"
    os.mkfifo(fifo)
    results: list[object] = []
    thread = threading.Thread(
        target=lambda: results.append(runner.invoke(capture_app, ["info", str(fifo)])), daemon=True
    )
    thread.start()
    thread.join(timeout=20)
    assert results, "info hung on a FIFO"
    result = results[0]
    assert result.exit_code == 1  # type: ignore[attr-defined]
    assert "found a folder, pipe or device" in result.stderr  # type: ignore[attr-defined]


@pytest.mark.parametrize("target", ["folder", "/dev/null"])
def test_run_on_a_folder_or_device_is_one_line(tmp_path: Path, target: str) -> None:
    rec = tmp_path if target == "folder" else Path(target)
    result = runner.invoke(app, ["run", str(rec), "--out", str(tmp_path / "out")])
    assert result.exit_code == 1
    assert result.stderr.startswith("error: expected a recording file")
