"""No output is lost or half-written: staging, --force, dead runs' temporaries, full disks."""

from __future__ import annotations

import errno
import os
import subprocess
import sys
from pathlib import Path

import pytest
from helpers_robust import Case, write_case
from typer.testing import CliRunner

from process import outputs
from process.cli import app
from process.errors import OutputError

runner = CliRunner()


@pytest.fixture
def small(tmp_path: Path) -> Path:
    """Return a small valid recording (8 frames of 64x48)."""
    return write_case(tmp_path / "small.mcap", Case())


def _run(rec: Path, out: Path, *extra: str) -> tuple[int, list[str]]:
    args = ["run", str(rec), "--out", str(out), "--stages", "odometry", *extra]
    result = runner.invoke(app, args)
    assert result.exception is None or isinstance(result.exception, SystemExit), result.output
    return result.exit_code, [ln for ln in result.stderr.splitlines() if ln.startswith("error:")]


def _dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def test_a_non_empty_out_is_refused_without_force_and_replaced_whole_with_it(
    small: Path, tmp_path: Path
) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / outputs.MAP_FUSED).write_bytes(b"old map of another recording")
    (out / outputs.CONFIG).write_text("# old\n")
    code, errors = _run(small, out, "--no-viz")
    assert code == 1 and len(errors) == 1 and "pass --force" in errors[0]
    assert (out / outputs.CONFIG).read_text() == "# old\n"
    code, errors = _run(small, out, "--no-viz", "--force")
    assert code == 0, errors
    names = sorted(p.name for p in out.iterdir())
    assert names == sorted([outputs.CONFIG, outputs.METRICS, outputs.TRAJECTORY])  # no old map


def test_a_failing_run_leaves_the_old_folder_as_it_was(
    small: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    out = tmp_path / "out"
    assert _run(small, out, "--no-viz")[0] == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}

    write_text = Path.write_text

    def full(self: Path, *args: object, **kwargs: object) -> int:
        if outputs.TRAJECTORY in self.name:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return write_text(self, *args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(Path, "write_text", full)
    code, errors = _run(small, out, "--no-viz", "--force")
    assert code == 1 and len(errors) == 1
    assert "cannot write trajectory.tum (No space left on device)" in errors[0]
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def test_a_full_disk_in_the_toml_writer_is_one_line(
    small: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def full(*_: object, **__: object) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(Path, "write_text", full)
    code, errors = _run(small, tmp_path / "out", "--no-viz")
    assert code == 1 and "cannot write config.toml (No space left on device)" in errors[0]
    assert list((tmp_path / "out").iterdir()) == []


def test_a_failing_rrd_close_is_one_line_and_leaves_no_part_file(
    small: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from viz.rerun_log import RerunLogger

    close = RerunLogger.close

    def failing_close(self: RerunLogger) -> None:
        close(self)
        raise RuntimeError("No space left on device")

    monkeypatch.setattr(RerunLogger, "close", failing_close)
    out = tmp_path / "out"
    code, errors = _run(small, out)
    assert code == 1 and len(errors) == 1 and "cannot finish recording.rrd" in errors[0]
    assert list(out.iterdir()) == []


def test_dead_runs_temporaries_are_removed_and_live_ones_kept(small: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    out.mkdir()
    dead = _dead_pid()
    (out / f".recording.rrd.part{dead}").write_bytes(b"x" * 1000)
    (out / f"{outputs.STAGING_PREFIX}{dead}").mkdir()
    (out / f"{outputs.STAGING_PREFIX}{dead}" / outputs.RRD).write_bytes(b"partial")
    (out / f".map_fused.ply.{dead}.tmp").write_bytes(b"partial")
    live = f".trajectory.tum.part{os.getppid()}"  # a run still going: not ours to remove
    (out / live).write_bytes(b"")
    code, errors = _run(small, out, "--no-viz")
    assert code == 0, errors
    left = sorted(p.name for p in out.iterdir() if p.name.startswith("."))
    assert left == [live]


@pytest.mark.parametrize("kind", ["file", "nested-in-file"])
def test_out_that_is_a_file_is_one_line(small: Path, tmp_path: Path, kind: str) -> None:
    target = tmp_path / "taken"
    target.write_text("not a folder")
    out = target if kind == "file" else target / "sub"
    code, errors = _run(small, out, "--no-viz")
    assert code == 1 and len(errors) == 1 and "--out" in errors[0]
    assert target.read_text() == "not a folder"


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_a_read_only_out_is_one_line(small: Path, tmp_path: Path) -> None:
    out = tmp_path / "ro"
    out.mkdir()
    out.chmod(0o500)
    try:
        code, errors = _run(small, out)
    finally:
        out.chmod(0o700)
    assert code == 1 and len(errors) == 1 and "cannot write into --out" in errors[0]


def test_prepare_out_refuses_a_folder_it_cannot_write(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def denied(*_: object, **__: object) -> None:
        raise PermissionError(errno.EACCES, os.strerror(errno.EACCES))

    monkeypatch.setattr(Path, "write_bytes", denied)
    with pytest.raises(OutputError, match=r"cannot write into --out \(Permission denied"):
        outputs.prepare_out(tmp_path / "out", force=False)
    assert list((tmp_path / "out").iterdir()) == []


def test_a_sigkilled_runs_staging_folder_is_removed_by_the_next_run(
    small: Path, tmp_path: Path
) -> None:
    import signal
    import time

    from helpers_robust import Case, write_case

    longer = write_case(tmp_path / "longer.mcap", Case(size=(320, 240)))
    out = tmp_path / "out"
    child = subprocess.Popen(
        [sys.executable, "-m", "process", "run", str(longer), "--out", str(out)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    staging = out / f"{outputs.STAGING_PREFIX}{child.pid}"
    deadline = time.monotonic() + 60
    while not (staging / outputs.CONFIG).exists() and time.monotonic() < deadline:
        time.sleep(0.02)
    child.send_signal(signal.SIGKILL)
    child.wait(timeout=60)
    if not staging.exists():
        pytest.skip("the run finished before it could be killed")
    assert (staging / outputs.CONFIG).exists()  # what a killed run leaves...
    code, errors = _run(small, out, "--no-viz")
    assert code == 0, errors  # ...is not "a non-empty --out"
    assert not staging.exists()  # ...and the next run removes it
    assert not [p for p in out.iterdir() if p.name.startswith(".")]
