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
from helpers_batch import ARGS, FRAMES, SEEDS, run_batch_cli, runner, summary_rows

from process import outputs
from process.batch import summary
from process.batch.report import HTML
from process.batch.tasks import MARKER
from process.cli import app

RUN_OUTPUTS = [outputs.CONFIG, outputs.METRICS, outputs.TRAJECTORY]  # of run --stages odometry
COMPARED = ("name", "status", "frames", "keyframes", "duration_s")
METRICS = ("ate_rmse_m", "rpe_trans_m", "rpe_rot_deg")
# Another number of threads sums in another order: ATE moved by 6e-5 relative between 1 and 2
# Open3D threads; runs with the same threads agree to 1e-8.
REL = 1e-3


@pytest.fixture(scope="module")
def local_out(recordings: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("local")
    result = run_batch_cli(recordings, out, "--jobs", "2")
    assert result.exit_code == 1, result.output  # one recording failed, the batch did not
    assert "1 of 4 recordings failed (corrupt)" in result.output
    return out


@pytest.mark.slow
def test_local_batch_writes_each_folder_and_one_row_per_recording(
    local_out: Path, recordings: Path
) -> None:
    rows = summary_rows(local_out)
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
        assert ours["odometry"][key] == pytest.approx(theirs["odometry"][key], rel=REL), key
    assert (local_out / "sim2" / outputs.CONFIG).read_text() == (
        single / outputs.CONFIG
    ).read_text()
    traj = (local_out / "sim2" / outputs.TRAJECTORY).read_text().splitlines()
    assert len(traj) == len((single / outputs.TRAJECTORY).read_text().splitlines())


@pytest.mark.slow
def test_parquet_and_html_hold_the_samesummary_rows(local_out: Path) -> None:
    import pyarrow.parquet as pq

    table = pq.read_table(local_out / summary.PARQUET)
    assert table.column_names == list(summary.COLUMNS)
    from_parquet = {r["name"]: r for r in table.to_pylist()}
    for name, row in summary_rows(local_out).items():
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
    result = run_batch_cli(recordings, local_out)
    assert result.exit_code == 1, result.output
    assert "3 of 4 recordings complete already: kept" in result.output
    rows = summary_rows(local_out)
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
        result = run_batch_cli(recordings, tmp_path / "ray", "--executor", "ray")
    finally:
        ray.shutdown()
    assert result.exit_code == 1, result.output
    local, remote = summary_rows(local_out), summary_rows(tmp_path / "ray")
    assert list(remote) == list(local)
    for name, row in local.items():
        for key in COMPARED:
            assert remote[name][key] == row[key], (name, key)
        for key in METRICS:
            expected = None if row[key] is None else pytest.approx(row[key], rel=REL)
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
    result = run_batch_cli(recordings, out, "--jobs", "1")
    assert result.exit_code == 1, result.output
    rows = summary_rows(out)
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
    rows = summary_rows(out)
    assert rows["sim3"]["reason"] == "not finished: the batch was interrupted"
    for name, row in rows.items():
        assert (row["status"] == "ok") == (out / name / MARKER).is_file(), name


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
        return summary_rows(tmp_path / "out")["sim1"]

    assert batch("")["reused"] is False
    assert batch("[batch]\nmax_retries = 0\n")["reused"] is True  # how to run, not what
    assert batch("[odometry]\nn_features = 1000\n")["reused"] is False  # another result
    assert "n_features = 1000" in (tmp_path / "out" / "sim1" / outputs.CONFIG).read_text()
