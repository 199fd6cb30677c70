"""semreplay-view: argument handling and every refusal, without ever starting a viewer."""

from __future__ import annotations

import socket
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from helpers_viz import assert_rrd_verifies
from typer.testing import CliRunner

from viz import cli
from viz.rerun_log import RerunLogger

runner = CliRunner()


@pytest.fixture
def rrd(tmp_path: Path) -> Path:
    path = tmp_path / "recording.rrd"
    RerunLogger(path, recording_name="cli").close()
    assert_rrd_verifies(path)
    return path


@pytest.fixture
def no_viewer(monkeypatch: pytest.MonkeyPatch) -> list[list[str]]:
    """Record the commands the CLI would run instead of running them."""
    commands: list[list[str]] = []

    def fake_run(cmd: list[str]) -> int:
        assert Path(cmd[2]).is_file()  # the blueprint exists while the viewer runs
        commands.append(cmd)
        return 0

    monkeypatch.setattr(cli, "run_viewer", fake_run)
    return commands


@pytest.fixture
def bound_port() -> Iterator[int]:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        sock.listen()
        yield sock.getsockname()[1]


def _one_line(text: str) -> str:
    lines = text.strip().splitlines()
    assert len(lines) == 1, text
    return lines[0]


def test_missing_file_is_a_one_line_error(tmp_path: Path, no_viewer: list[list[str]]) -> None:
    result = runner.invoke(cli.app, [str(tmp_path / "nope.rrd")])
    assert result.exit_code == 1
    assert _one_line(result.output).endswith(str(tmp_path / "nope.rrd"))
    assert "found none" in result.output
    assert no_viewer == []


@pytest.mark.parametrize("content", [b"", b"not an rrd at all, just text"])
def test_invalid_file_is_a_one_line_error(
    tmp_path: Path, content: bytes, no_viewer: list[list[str]]
) -> None:
    path = tmp_path / "broken.rrd"
    path.write_bytes(content)
    result = runner.invoke(cli.app, [str(path)])
    assert result.exit_code == 1
    assert "could not read it" in _one_line(result.output)
    assert no_viewer == []


def test_no_display_refuses_the_native_viewer(
    rrd: Path, monkeypatch: pytest.MonkeyPatch, no_viewer: list[list[str]]
) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr(sys, "platform", "linux")
    result = runner.invoke(cli.app, [str(rrd)])
    assert result.exit_code == 1
    assert "no display" in _one_line(result.output) and "--web" in result.output
    assert no_viewer == []


@pytest.mark.parametrize(
    ("env", "platform"),
    [({"DISPLAY": ":0"}, "linux"), ({"WAYLAND_DISPLAY": "wayland-0"}, "linux"), ({}, "darwin")],
)
def test_a_window_system_is_enough_for_the_native_viewer(
    env: dict[str, str], platform: str
) -> None:
    cli.check_display(env, platform=platform)  # raises ViewError otherwise


def test_display_opens_the_native_viewer_with_our_blueprint(
    rrd: Path, monkeypatch: pytest.MonkeyPatch, no_viewer: list[list[str]]
) -> None:
    monkeypatch.setenv("DISPLAY", ":0")
    result = runner.invoke(cli.app, [str(rrd)])
    assert result.exit_code == 0, result.output
    (cmd,) = no_viewer
    assert cmd[0] == str(cli.rerun_binary())
    assert cmd[1] == str(rrd)
    assert cmd[2].endswith(".rbl")
    assert "--serve-web" not in cmd


def test_web_serves_on_localhost_and_prints_the_address(
    rrd: Path, monkeypatch: pytest.MonkeyPatch, no_viewer: list[list[str]]
) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    ports = []
    for _ in range(2):  # two free ports; released before the CLI checks them
        with socket.socket() as sock:
            sock.bind(("127.0.0.1", 0))
            ports.append(sock.getsockname()[1])
    web, grpc = ports
    result = runner.invoke(
        cli.app, [str(rrd), "--web", "--port", str(web), "--grpc-port", str(grpc)]
    )
    assert result.exit_code == 0, result.output
    (cmd,) = no_viewer
    assert cmd[cmd.index("--bind") + 1] == "127.0.0.1"
    assert cmd[cmd.index("--web-viewer-port") + 1] == str(web)
    assert cmd[cmd.index("--port") + 1] == str(grpc)
    assert "--serve-web" in cmd
    address = f"http://127.0.0.1:{web}/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A{grpc}%2Fproxy"
    assert address in result.output


@pytest.mark.parametrize("option", ["--port", "--grpc-port"])
def test_web_refuses_a_port_in_use(
    rrd: Path, bound_port: int, option: str, no_viewer: list[list[str]]
) -> None:
    other = "--grpc-port" if option == "--port" else "--port"
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        free = sock.getsockname()[1]
    args = [str(rrd), "--web", option, str(bound_port), other, str(free)]
    result = runner.invoke(cli.app, args)
    assert result.exit_code == 1
    assert f"port {bound_port} on 127.0.0.1 is not available" in _one_line(result.output)
    assert no_viewer == []


def test_viewer_exit_status_is_passed_on(rrd: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DISPLAY", ":0")
    monkeypatch.setattr(cli, "run_viewer", lambda cmd: 3)
    assert runner.invoke(cli.app, [str(rrd)]).exit_code == 3


def test_python_m_viz_shows_help_with_examples() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "viz", "--help"],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    assert "semreplay-view" in result.stdout
    assert "--web" in result.stdout and "Examples" in result.stdout
