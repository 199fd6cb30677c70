"""`semreplay-process batch`, part by part: inputs, options, config, report, workers."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import pytest
from helpers_batch import runner, summary_rows

from process.batch import summary
from process.batch.report import bar_chart
from process.batch.runner import default_jobs, find_recordings
from process.cli import app
from process.config import load_config
from process.errors import ConfigError


def test_inputs_are_files_folders_and_globs(recordings: Path, tmp_path: Path) -> None:
    files = find_recordings([str(recordings / "sim2.mcap"), str(recordings / "sim[13].mcap")])
    assert [p.name for p in files] == ["sim2.mcap", "sim1.mcap", "sim3.mcap"]
    assert len(find_recordings([str(recordings), str(recordings / "sim1.mcap")])) == 4
    with pytest.raises(ConfigError, match="no recording found at"):
        find_recordings([str(tmp_path / "absent*.mcap")])
    twin = tmp_path / "sim1.mcap"
    twin.write_bytes(b"")
    with pytest.raises(ConfigError, match="share the output folder 'sim1'"):
        find_recordings([str(recordings), str(twin)])


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--executor", "dask"], "error: unknown executor 'dask'; valid: local, ray"),
        (["--jobs", "0"], "error: --jobs must be >= 1, got 0"),
        (["--stages", "slam"], "error: unknown stage(s) ['slam']"),
    ],
)
def test_bad_options_are_one_line(
    args: list[str], message: str, recordings: Path, tmp_path: Path
) -> None:
    result = runner.invoke(app, ["batch", str(recordings), "--out", str(tmp_path), *args])
    assert result.exit_code == 1
    assert result.output.strip().splitlines() == [result.output.strip()]
    assert result.output.startswith(message), result.output


def test_batch_config_section(tmp_path: Path) -> None:
    config = tmp_path / "b.toml"
    config.write_text("[batch]\ncpus_per_task = 2\ngpus_per_task = 0.5\nmax_retries = 0\n")
    cfg = load_config(config).batch
    assert (cfg.cpus_per_task, cfg.gpus_per_task, cfg.max_retries) == (2.0, 0.5, 0)
    config.write_text("[batch]\nmemory_gb_per_task = 0\n")
    with pytest.raises(ConfigError, match=r"batch.cpus_per_task and batch.memory_gb_per_task"):
        load_config(config)


def test_default_jobs_is_bounded_by_cores_and_memory() -> None:
    import os

    cores = len(os.sched_getaffinity(0))
    assert default_jobs(0.001) == cores
    assert default_jobs(1e6) == 1  # less memory than one task asks: still one


def test_bar_chart_scales_bars_to_the_largest_value() -> None:
    svg = bar_chart("ATE (m)", [("a", 1.0), ("b<", 0.5)])
    assert svg.startswith("<svg") and svg.endswith("</svg>")
    assert 'width="190.0"' in svg and 'width="95.0"' in svg  # 380 - 130 - 60 = 190 px for 1.0
    assert "b&lt;" in svg


def test_a_task_limits_its_threads() -> None:
    # As in a child of the forkserver: every library loaded, and its pools sized, before.
    code = (
        "import cv2, open3d, torch, process.pipeline;"
        "from threadpoolctl import threadpool_info;"
        "from process.batch.tasks import limit_threads; limit_threads(1);"
        "print(cv2.getNumThreads(), torch.get_num_threads(), open3d.utility.get_max_threads(),"
        " max(p['num_threads'] for p in threadpool_info()), len(threadpool_info()) > 0)"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    )
    assert result.stdout.split() == ["1", "1", "1", "1", "True"]


def test_the_report_shows_each_preview(tmp_path: Path) -> None:
    from process.batch.report import write_html

    (tmp_path / "a").mkdir()
    (tmp_path / "a" / summary.PREVIEW).write_bytes(b"\x89PNG")
    metrics = {"odometry": {"frames": 3, "keyframes": 2, "ate_rmse_m": 0.5}}
    row = summary.ok_row("a", tmp_path / "a.mcap", metrics, tmp_path / "a")
    rows = [summary.with_output_names(row, tmp_path / "a"), summary.empty_row("b", Path("b"))]
    rows[1].update(status="failed", reason="broken")
    page = write_html(tmp_path, rows).read_text()
    assert '<img src="a/preview.png" alt="a">' in page
    assert "1 of 2 recordings ok" in page and "ATE RMSE (m)" in page
    assert 'width="190.0"' in page  # the one ATE bar spans the chart


def test_a_folder_not_written_by_batch_is_left_alone(recordings: Path, tmp_path: Path) -> None:
    mine = tmp_path / "sim1" / "notes.txt"
    mine.parent.mkdir()
    mine.write_text("mine")
    result = runner.invoke(app, ["batch", str(recordings / "sim1.mcap"), "--out", str(tmp_path)])
    assert result.exit_code == 1, result.output
    reason = summary_rows(tmp_path)["sim1"]["reason"]
    assert reason.endswith(
        "was not written by batch (no batch.json); move it away or choose another --out"
    )
    assert [p.name for p in mine.parent.iterdir()] == ["notes.txt"]


def _die() -> None:
    import os

    os.kill(os.getpid(), signal.SIGKILL)


def test_a_worker_that_dies_is_a_failed_row(recordings: Path, tmp_path: Path) -> None:
    import multiprocessing

    from process.batch.local import _collect
    from process.batch.tasks import Task

    task = Task(recordings / "sim1.mcap", "sim1", tmp_path, load_config(None), ("odometry",))
    task.partial_dir.mkdir()
    ctx = multiprocessing.get_context("fork")
    receive, send = ctx.Pipe(duplex=False)
    child = ctx.Process(target=_die)
    child.start()
    send.close()
    row = _collect(receive, child, task)
    assert row["status"] == "failed" and row["name"] == "sim1"
    assert row["reason"] == "worker process died (killed by SIGKILL; out of memory?)"
    assert not task.partial_dir.exists()
