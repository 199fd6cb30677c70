"""`semreplay-process batch`: three simulated recordings and a corrupt file, local and on Ray."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from process import outputs
from process.batch import summary
from process.batch.report import HTML, bar_chart
from process.batch.runner import default_jobs, find_recordings
from process.batch.tasks import MARKER
from process.cli import app
from process.config import load_config
from process.errors import ConfigError

runner = CliRunner()
SEEDS = (1, 2, 3)
FRAMES = 12
ARGS = ("--stages", "odometry", "--no-viz")
RUN_OUTPUTS = [outputs.CONFIG, outputs.METRICS, outputs.TRAJECTORY]  # of run --stages odometry
COMPARED = ("name", "status", "frames", "keyframes", "duration_s")
METRICS = ("ate_rmse_m", "rpe_trans_m", "rpe_rot_deg")


@pytest.fixture(scope="module")
def recordings(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Return a folder of three small simulated recordings and one file that is not MCAP."""
    from capture.sim import simulate_recording

    folder = tmp_path_factory.mktemp("recs")
    for seed in SEEDS:
        simulate_recording(
            folder / f"sim{seed}.mcap", seed=seed, frames=FRAMES, width=320, height=240
        )
    (folder / "corrupt.mcap").write_bytes(b"this is not an mcap file" * 100)
    return folder


def _batch(recordings: Path, out: Path, *extra: str) -> Any:
    return runner.invoke(app, ["batch", str(recordings), "--out", str(out), *ARGS, *extra])


def _rows(out: Path) -> dict[str, dict[str, Any]]:
    return {row["name"]: row for row in summary.read_csv(out / summary.CSV)}


@pytest.fixture(scope="module")
def local_out(recordings: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("local")
    result = _batch(recordings, out, "--jobs", "2")
    assert result.exit_code == 1, result.output  # one recording failed, the batch did not
    assert "1 of 4 recordings failed (corrupt)" in result.output
    return out


@pytest.mark.slow
def test_local_batch_writes_each_folder_and_one_row_per_recording(
    local_out: Path, recordings: Path
) -> None:
    rows = _rows(local_out)
    assert list(rows) == ["corrupt", "sim1", "sim2", "sim3"]  # a folder: its *.mcap, sorted
    bad = rows["corrupt"]
    assert bad["status"] == "failed" and bad["reason"].startswith("not an MCAP file")
    assert "\n" not in bad["reason"] and bad["out_dir"] is None
    assert not (local_out / "corrupt").exists()
    for seed in SEEDS:
        row = rows[f"sim{seed}"]
        folder = local_out / f"sim{seed}"
        metrics = json.loads((folder / outputs.METRICS).read_text())
        assert row["status"] == "ok" and row["reason"] is None and row["reused"] is False
        assert row["frames"] == FRAMES == metrics["odometry"]["frames"]
        assert row["keyframes"] == metrics["odometry"]["keyframes"] > 0
        assert row["ate_rmse_m"] == pytest.approx(metrics["odometry"]["ate_rmse_m"], rel=1e-5)
        assert 0.0 < row["ate_rmse_m"] < 0.2
        assert row["duration_s"] == pytest.approx((FRAMES - 1) / 30, abs=0.01)
        assert row["seconds_odometry"] > 0 and row["seconds_fusion"] is None
        assert 0.05 < row["peak_rss_gb"] < 4.0
        assert row["out_dir"] == str(folder)
        assert sorted(p.name for p in folder.iterdir()) == sorted([*RUN_OUTPUTS, MARKER])
        assert row["outputs"] == ";".join(sorted(RUN_OUTPUTS))
    assert not [p.name for p in local_out.iterdir() if p.name.startswith(".")]  # no partials


@pytest.mark.slow
def test_a_batch_folder_holds_what_process_run_writes(
    local_out: Path, recordings: Path, tmp_path: Path
) -> None:
    single = tmp_path / "single"
    result = runner.invoke(app, ["run", str(recordings / "sim2.mcap"), "--out", str(single), *ARGS])
    assert result.exit_code == 0, result.output
    ours = json.loads((local_out / "sim2" / outputs.METRICS).read_text())
    theirs = json.loads((single / outputs.METRICS).read_text())
    for key in ("frames", "keyframes", *METRICS):
        assert ours["odometry"][key] == pytest.approx(theirs["odometry"][key], rel=1e-6), key
    assert (local_out / "sim2" / outputs.CONFIG).read_text() == (
        single / outputs.CONFIG
    ).read_text()
    traj = (local_out / "sim2" / outputs.TRAJECTORY).read_text().splitlines()
    assert len(traj) == len((single / outputs.TRAJECTORY).read_text().splitlines())


@pytest.mark.slow
def test_parquet_and_html_hold_the_same_rows(local_out: Path) -> None:
    import pyarrow.parquet as pq

    table = pq.read_table(local_out / summary.PARQUET)
    assert table.column_names == list(summary.COLUMNS)
    from_parquet = {r["name"]: r for r in table.to_pylist()}
    for name, row in _rows(local_out).items():
        for key in (*COMPARED, *METRICS):
            expected = row[key]
            got = from_parquet[name][key]
            assert got == (
                pytest.approx(expected, rel=1e-5) if isinstance(got, float) else expected
            )
    page = (local_out / HTML).read_text()
    assert "3 of 4 recordings ok" in page
    assert page.count("<svg") >= 4 and 'class="failed"' in page
    assert '<a href="sim1/">' in page and "not an MCAP file" in page


@pytest.mark.slow
def test_rerun_keeps_complete_folders_and_retries_failed_ones(
    local_out: Path, recordings: Path
) -> None:
    before = {s: (local_out / f"sim{s}" / MARKER).stat().st_mtime_ns for s in SEEDS}
    result = _batch(recordings, local_out)
    assert result.exit_code == 1, result.output
    assert "3 of 4 recordings complete already: kept" in result.output
    rows = _rows(local_out)
    assert rows["corrupt"]["status"] == "failed"  # tried again, failed again
    for seed in SEEDS:
        assert rows[f"sim{seed}"]["reused"] is True
        assert (local_out / f"sim{seed}" / MARKER).stat().st_mtime_ns == before[seed]


@pytest.mark.slow
def test_ray_gives_the_same_summary_as_the_local_pool(
    local_out: Path, recordings: Path, tmp_path: Path
) -> None:
    ray = pytest.importorskip("ray", reason="the [ray] extra is not installed")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        result = _batch(recordings, tmp_path / "ray", "--executor", "ray")
    finally:
        ray.shutdown()
    assert result.exit_code == 1, result.output
    local, remote = _rows(local_out), _rows(tmp_path / "ray")
    assert list(remote) == list(local)
    for name, row in local.items():
        for key in COMPARED:
            assert remote[name][key] == row[key], (name, key)
        for key in METRICS:
            expected = None if row[key] is None else pytest.approx(row[key], rel=1e-6)
            assert remote[name][key] == expected, (name, key)
    assert remote["corrupt"]["reason"] == local["corrupt"]["reason"]


def _start(recordings: Path, out: Path) -> subprocess.Popen[str]:
    command = [sys.executable, "-m", "process", "batch", str(recordings), "--out", str(out)]
    return subprocess.Popen(
        [*command, *ARGS, "--jobs", "1"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )


def _wait_for(path: Path, child: subprocess.Popen[str], timeout_s: float = 120) -> None:
    deadline = time.monotonic() + timeout_s
    while not path.exists():
        assert child.poll() is None, child.communicate()
        assert time.monotonic() < deadline, f"{path} did not appear"
        time.sleep(0.05)


@pytest.mark.slow
def test_a_killed_batch_resumes_where_it_stopped(recordings: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    child = _start(recordings, out)
    _wait_for(out / "sim1" / MARKER, child)  # corrupt failed, sim1 done, sim2 running
    child.kill()
    child.communicate()
    deadline = time.monotonic() + 30  # the worker dies with the batch and removes its partial
    while [p for p in out.iterdir() if p.name.endswith(".partial")]:
        assert time.monotonic() < deadline, sorted(p.name for p in out.iterdir())
        time.sleep(0.1)
    complete = {p.name for p in out.iterdir() if p.is_dir() and not p.name.startswith(".")}
    assert "sim1" in complete and all((out / name / MARKER).is_file() for name in complete)
    result = _batch(recordings, out, "--jobs", "1")
    assert result.exit_code == 1, result.output
    rows = _rows(out)
    assert [rows[f"sim{s}"]["status"] for s in SEEDS] == ["ok"] * 3
    assert {n for n, r in rows.items() if r["reused"]} == complete


@pytest.mark.slow
def test_ctrl_c_stops_the_batch_and_leaves_no_partial_folder(
    recordings: Path, tmp_path: Path
) -> None:
    out = tmp_path / "out"
    child = _start(recordings, out)
    _wait_for(out / ".sim1.partial", child)
    child.send_signal(signal.SIGINT)
    _, err = child.communicate(timeout=60)
    assert child.returncode == 1, err
    assert "error: interrupted:" in err and "rerun the same command" in err
    assert sorted(p.name for p in out.iterdir() if p.name.startswith(".")) == []
    rows = _rows(out)
    assert rows["sim3"]["reason"] == "not finished: the batch was interrupted"
    for name, row in rows.items():
        assert (row["status"] == "ok") == (out / name / MARKER).is_file(), name


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
    code = (
        "from process.batch.tasks import limit_threads; limit_threads(1); import cv2, torch;"
        "from threadpoolctl import threadpool_info;"
        "print(cv2.getNumThreads(), torch.get_num_threads(),"
        " max(p['num_threads'] for p in threadpool_info()))"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    )
    assert result.stdout.split() == ["1", "1", "1"]


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
    reason = _rows(tmp_path)["sim1"]["reason"]
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


@pytest.mark.slow
def test_a_folder_counts_as_complete_only_for_the_same_settings(
    recordings: Path, tmp_path: Path
) -> None:
    def batch(config: str) -> dict[str, Any]:
        path = tmp_path / "c.toml"
        path.write_text(config)
        args = ["batch", str(recordings / "sim1.mcap"), "--out", str(tmp_path / "out")]
        result = runner.invoke(app, [*args, *ARGS, "--config", str(path)])
        assert result.exit_code == 0, result.output
        return _rows(tmp_path / "out")["sim1"]

    assert batch("")["reused"] is False
    assert batch("[batch]\nmax_retries = 0\n")["reused"] is True  # how to run, not what
    assert batch("[odometry]\nn_features = 1000\n")["reused"] is False  # another result
    assert "n_features = 1000" in (tmp_path / "out" / "sim1" / outputs.CONFIG).read_text()
