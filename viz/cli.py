"""`semreplay-view FILE.rrd [--web]`: open a recording in the Rerun viewer with our blueprint."""

from __future__ import annotations

import importlib.util
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
from collections.abc import Mapping
from pathlib import Path
from types import FrameType
from typing import Annotated, Final
from urllib.parse import quote

import typer

LOCALHOST: Final = "127.0.0.1"
DEFAULT_WEB_PORT: Final = 9090  # rerun's --web-viewer-port default
DEFAULT_GRPC_PORT: Final = 9876  # rerun's --port default
STOP_SIGNALS: Final = (signal.SIGTERM, signal.SIGHUP)  # SIGINT arrives as KeyboardInterrupt
STOP_GRACE_S: Final = 5.0  # how long the viewer has to exit on SIGTERM before it is killed

EXAMPLES: Final = (
    "Examples:\n\n"
    "  semreplay-view demo_out/recording.rrd\n\n"
    "  semreplay-view demo_out/recording.rrd --web --port 9090"
)

app = typer.Typer(add_completion=False)


class ViewError(Exception):
    """A one-line reason why the viewer cannot be opened."""


def rerun_binary() -> Path:
    """Return the viewer binary that rerun-sdk ships (package `rerun_cli`)."""
    spec = importlib.util.find_spec("rerun_cli")
    folders = [] if spec is None else list(spec.submodule_search_locations or [])
    suffix = ".exe" if sys.platform.startswith("win") else ""
    path = Path(folders[0] if folders else ".") / f"rerun{suffix}"
    if not path.is_file():
        raise ViewError(
            f"expected the rerun viewer binary of rerun-sdk, found none; reinstall: {path}"
        )
    return path


def check_display(env: Mapping[str, str], *, platform: str) -> None:
    """Raise ViewError where a native window cannot open (Linux without X11 or Wayland)."""
    if not platform.startswith("linux"):
        return  # macOS and Windows always have a window system
    if not (env.get("DISPLAY") or env.get("WAYLAND_DISPLAY")):
        raise ViewError(
            "no display: DISPLAY and WAYLAND_DISPLAY are unset; "
            "use --web to serve the web viewer on localhost instead"
        )


def check_port_free(port: int, *, host: str = LOCALHOST) -> None:
    """Raise ViewError when a TCP port cannot be bound on host."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        try:
            sock.bind((host, port))
        except OSError as err:
            raise ViewError(
                f"port {port} on {host} is not available ({err.strerror}); "
                "choose another with --port / --grpc-port"
            ) from err


def read_application_id(rrd: Path) -> str:
    """Return the application id of the first recording in an .rrd, or raise ViewError."""
    if not rrd.is_file():
        raise ViewError(f"expected a Rerun .rrd file, found none: {rrd}")
    from rerun.chunk import RrdReader

    try:
        recordings = RrdReader(rrd).recordings()
    except (RuntimeError, ValueError, OSError) as err:
        reason = str(err).splitlines()[0].rsplit(": ", 1)[-1]
        raise ViewError(f"expected a Rerun .rrd file, could not read it ({reason}): {rrd}") from err
    if not recordings:
        raise ViewError(f"expected a recording in the .rrd, found only blueprints: {rrd}")
    return recordings[0].application_id


def web_address(*, port: int, grpc_port: int) -> str:
    """Return the address of the web viewer, already pointed at the recording's server."""
    proxy = f"rerun+http://{LOCALHOST}:{grpc_port}/proxy"
    return f"http://{LOCALHOST}:{port}/?url={quote(proxy, safe='')}"


def viewer_command(
    rrd: Path, *, blueprint_rbl: Path, web: bool, port: int, grpc_port: int
) -> list[str]:
    """Return the rerun command line that shows rrd with blueprint_rbl, natively or on the web."""
    cmd = [str(rerun_binary()), str(rrd), str(blueprint_rbl)]
    if web:
        # --serve-web hosts the web viewer without opening a browser: we print the address.
        cmd += ["--serve-web", "--bind", LOCALHOST]
        cmd += ["--web-viewer-port", str(port), "--port", str(grpc_port)]
    return cmd


class _StopSignalError(Exception):
    """Raised in the main thread when a stop signal (SIGTERM, SIGHUP) arrives."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


def _raise_stopped(signum: int, _frame: FrameType | None) -> None:
    raise _StopSignalError(signum)


def _stop(child: subprocess.Popen[bytes]) -> None:
    """Terminate the viewer, killing it if it has not exited after STOP_GRACE_S."""
    child.terminate()
    try:
        child.wait(timeout=STOP_GRACE_S)
    except subprocess.TimeoutExpired:
        child.kill()
        child.wait()


def run_viewer(cmd: list[str]) -> int:
    """Run the viewer in the foreground and return its exit status.

    On SIGINT (Ctrl-C), SIGTERM or SIGHUP the viewer is stopped before this returns 128 plus
    the signal's number, so that no `rerun` process outlives us and the caller's temporary
    folder can be removed.
    """
    env = {**os.environ, "RERUN_APP_ONLY": "true"}  # as rerun's own spawn(): no first-run banner
    in_main = threading.current_thread() is threading.main_thread()
    previous = {s: signal.signal(s, _raise_stopped) for s in STOP_SIGNALS} if in_main else {}
    child: subprocess.Popen[bytes] | None = None
    try:
        child = subprocess.Popen(cmd, env=env)
        return child.wait()
    except KeyboardInterrupt:
        return 128 + signal.SIGINT
    except _StopSignalError as stopped:
        return 128 + stopped.signum
    finally:
        if child is not None and child.poll() is None:
            _stop(child)
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def _prepare(file: Path, *, web: bool, port: int, grpc_port: int) -> str:
    """Check everything that can fail before a viewer starts; return the application id."""
    application_id = read_application_id(file)
    if web:
        check_port_free(port)
        check_port_free(grpc_port)
    else:
        check_display(os.environ, platform=sys.platform)
    return application_id


@app.command(epilog=EXAMPLES)
def view(
    file: Annotated[Path, typer.Argument(help="The .rrd to open.", show_default=False)],
    web: Annotated[bool, typer.Option("--web", help="Serve the web viewer on localhost.")] = False,
    port: Annotated[
        int, typer.Option(min=1, max=65535, help="HTTP port of the web viewer (--web).")
    ] = DEFAULT_WEB_PORT,
    grpc_port: Annotated[
        int, typer.Option(min=1, max=65535, help="gRPC port that serves the data (--web).")
    ] = DEFAULT_GRPC_PORT,
) -> None:
    """Open FILE.rrd in the Rerun viewer with the semreplay blueprint."""
    try:
        application_id = _prepare(file, web=web, port=port, grpc_port=grpc_port)
        from viz.layout import blueprint

        with tempfile.TemporaryDirectory(prefix="semreplay-view-") as tmp:
            rbl = Path(tmp) / "semreplay.rbl"
            blueprint().save(application_id, rbl)
            cmd = viewer_command(file, blueprint_rbl=rbl, web=web, port=port, grpc_port=grpc_port)
            if web:
                address = web_address(port=port, grpc_port=grpc_port)
                typer.echo(f"Serving {file} at {address} (Ctrl-C stops)")
            status = run_viewer(cmd)
    except ViewError as err:
        typer.echo(f"semreplay-view: {err}", err=True)
        raise typer.Exit(1) from None
    raise typer.Exit(status)
