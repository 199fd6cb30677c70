"""semreplay-view leaves nothing behind when stopped by a signal: no `rerun` child, no temp dir."""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest
from helpers_viz import assert_rrd_verifies

from viz.rerun_log import RerunLogger


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


def _viewer_child(view: psutil.Process, *, timeout_s: float = 60.0) -> psutil.Process:
    """Return the `rerun` child of semreplay-view once it runs."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        for child in view.children(recursive=True):
            try:  # a child that is starting or ending has no command line yet or any more
                cmdline = child.cmdline()
            except (psutil.NoSuchProcess, psutil.ZombieProcess, psutil.AccessDenied):
                continue
            if len(cmdline) > 2 and Path(cmdline[0]).name == "rerun":
                return child
        time.sleep(0.1)
    raise AssertionError("semreplay-view started no rerun child")


@pytest.mark.parametrize(
    "signum", [signal.SIGTERM, signal.SIGINT, signal.SIGHUP], ids=lambda s: s.name
)
def test_a_stop_signal_ends_the_viewer_and_removes_the_temporary_folder(
    tmp_path: Path, signum: signal.Signals
) -> None:
    rrd = tmp_path / "empty.rrd"
    RerunLogger(rrd, recording_name="cleanup").close()
    assert_rrd_verifies(rrd)
    ports = ["--port", str(_free_port()), "--grpc-port", str(_free_port())]
    command = [sys.executable, "-m", "viz", str(rrd), "--web", *ports]
    view = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        rerun = _viewer_child(psutil.Process(view.pid))
        blueprint = Path(rerun.cmdline()[2])
        assert blueprint.suffix == ".rbl"
        assert blueprint.parent.name.startswith("semreplay-view-")
        assert blueprint.is_file()
        time.sleep(0.5)  # the signal handlers are in place once the child runs
        os.kill(view.pid, signum)
        status = view.wait(timeout=30)
        assert status == 128 + signum
        assert not blueprint.parent.exists()
        gone, alive = psutil.wait_procs([rerun], timeout=5)
        assert alive == [] and gone == [rerun]
    finally:  # a failed test leaves no viewer behind: children first, or they are orphaned
        if view.poll() is None:
            with contextlib.suppress(psutil.NoSuchProcess):
                for child in psutil.Process(view.pid).children(recursive=True):
                    child.kill()
            view.kill()
            view.wait()
