"""`semreplay-capture`: record a D435, convert RealSense files, simulate, import, inspect."""

from __future__ import annotations

import functools
import sys
from collections.abc import Callable
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, ParamSpec, TypeVar

import typer

from capture.errors import CaptureError

if TYPE_CHECKING:
    from capture.realsense.session import RecordStatus

P = ParamSpec("P")
R = TypeVar("R")

app = typer.Typer(
    name="semreplay-capture",
    help="Make RGB-D recordings (ROS 2 MCAP, RECORDING.md) from a D435, files or a simulator.",
    no_args_is_help=True,
    add_completion=False,
    rich_markup_mode="markdown",
    pretty_exceptions_enable=False,
)


class Compression(StrEnum):
    """Chunk compression of the MCAP file."""

    zstd = "zstd"
    lz4 = "lz4"
    none = "none"


class DatasetKind(StrEnum):
    """Dataset folder layouts `import` understands."""

    tum = "tum"
    sevenscenes = "7scenes"
    redwood = "redwood"


def one_line_errors(command: Callable[P, R]) -> Callable[P, R]:
    """Report a CaptureError as one `error: ...` line on stderr and exit 1."""

    @functools.wraps(command)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        try:
            return command(*args, **kwargs)
        except CaptureError as err:
            typer.echo(f"error: {err}", err=True)
            raise typer.Exit(1) from None

    return wrapper


def _status_line(status: RecordStatus) -> None:
    sys.stderr.write(
        f"\r{status.elapsed_s:7.1f} s  {status.fps:5.1f} fps  {status.mb_per_s:6.1f} MB/s  "
        f"{status.frames} frames  {status.dropped} dropped "
    )
    sys.stderr.flush()


@app.command()
@one_line_errors
def record(
    out: Annotated[Path, typer.Argument(help="The recording to write (.mcap).")],
    width: Annotated[int, typer.Option(help="Colour width.")] = 640,
    height: Annotated[int, typer.Option(help="Colour height.")] = 480,
    fps: Annotated[int, typer.Option(help="Colour frame rate.")] = 30,
    depth_width: Annotated[int | None, typer.Option(help="Depth width [as colour].")] = None,
    depth_height: Annotated[int | None, typer.Option(help="Depth height [as colour].")] = None,
    depth_fps: Annotated[int | None, typer.Option(help="Depth frame rate [as colour].")] = None,
    align: Annotated[bool, typer.Option(help="Align depth to colour while recording.")] = False,
    compression: Annotated[Compression, typer.Option(help="Chunk compression.")] = Compression.zstd,
    color_jpeg: Annotated[bool, typer.Option(help="Store colour as JPEG.")] = False,
    duration: Annotated[
        float | None, typer.Option(help="Seconds to record [until Ctrl-C].", min=0.001)
    ] = None,
    serial: Annotated[str | None, typer.Option(help="Serial number of the camera.")] = None,
    preset: Annotated[
        str | None, typer.Option(help="Depth visual preset, e.g. 'High Accuracy'.")
    ] = None,
    emitter: Annotated[
        bool | None, typer.Option("--emitter/--no-emitter", help="IR emitter [as is].")
    ] = None,
) -> None:
    r"""Record a live RealSense D435 until --duration or Ctrl-C.

    Frames go through a bounded queue to a writer thread; drops are counted per stream and
    stored in the file. Ctrl-C or SIGTERM finish the file cleanly.

    Examples:
    ```
    semreplay-capture record room.mcap --duration 30
    semreplay-capture record room.mcap --align --preset "High Accuracy"
    semreplay-capture record big.mcap --width 1280 --height 720 --depth-width 848 \
        --depth-height 480 --depth-fps 90 --compression lz4
    ```
    """
    from capture.realsense.record import record as record_camera
    from capture.realsense.session import RecordConfig
    from capture.realsense.sink import stop_on_signals

    config = RecordConfig(
        width=width, height=height, fps=fps, depth_width=depth_width,
        depth_height=depth_height, depth_fps=depth_fps, align=align,
        compression=compression.value, color_jpeg=color_jpeg, duration_s=duration,
        serial=serial, preset=preset, emitter=emitter,
    )  # fmt: skip
    with stop_on_signals() as stop:
        result = record_camera(out, config, stop=stop, on_status=_status_line)
    sys.stderr.write("\n")
    written = ", ".join(f"{k} {v}" for k, v in result.frames_written.items())
    dropped = ", ".join(f"{k} {v}" for k, v in result.frames_dropped.items())
    typer.echo(f"{out}: {written} frames, dropped {dropped}, {result.duration_s:.1f} s")
    if result.camera_lost:
        typer.echo(
            f"error: {result.stop_reason}; the recording holds what came before: {out}", err=True
        )
        raise typer.Exit(1)


@app.command()
@one_line_errors
def convert(
    src: Annotated[Path, typer.Argument(help="A RealSense recording (.bag or .db3).")],
    out: Annotated[Path, typer.Argument(help="The recording to write (.mcap).")],
    compression: Annotated[Compression, typer.Option(help="Chunk compression.")] = Compression.zstd,
) -> None:
    """Convert a RealSense .bag/.db3 (played back by pyrealsense2) into an MCAP recording.

    One message per frame, depth bit-exact, the recorded intrinsics and extrinsics.

    Example:
    ```
    semreplay-capture convert room.db3 room.mcap
    ```
    """
    from capture.realsense.record import convert as convert_file

    result = convert_file(src, out, compression=compression.value)
    written = ", ".join(f"{k} {v}" for k, v in result.frames_written.items())
    typer.echo(f"{out}: {written} frames from {src}")


@app.command()
@one_line_errors
def simulate(
    out: Annotated[Path, typer.Argument(help="The recording to write (.mcap).")],
    seed: Annotated[int, typer.Option(help="Scene and trajectory seed.")] = 0,
    frames: Annotated[int, typer.Option(help="Number of frames.", min=1)] = 300,
    fps: Annotated[float, typer.Option(help="Frame rate.", min=0.001)] = 30.0,
    width: Annotated[int, typer.Option(help="Image width.", min=16)] = 640,
    height: Annotated[int, typer.Option(help="Image height.", min=16)] = 480,
) -> None:
    """Simulate a D435 in a furnished room: a recording with ground truth.

    Example:
    ```
    semreplay-capture simulate sim.mcap --seed 7 --frames 90
    ```
    """
    from capture.sim import simulate_recording

    summary = simulate_recording(out, seed=seed, frames=frames, fps=fps, width=width, height=height)
    typer.echo(f"{out}: {summary.frames} simulated frames (seed {summary.seed})")


@app.command("import")
@one_line_errors
def import_(
    kind: Annotated[DatasetKind, typer.Argument(help="The dataset layout.")],
    src: Annotated[Path, typer.Argument(help="The dataset folder.")],
    out: Annotated[Path, typer.Argument(help="The recording to write (.mcap).")],
    compression: Annotated[Compression, typer.Option(help="Chunk compression.")] = Compression.zstd,
) -> None:
    """Import a TUM RGB-D, 7-Scenes or Redwood/ICL-NUIM folder as a recording.

    Example:
    ```
    semreplay-capture import tum rgbd_dataset_freiburg1_xyz fr1_xyz.mcap
    ```
    """
    from capture.importers import import_dataset

    count = import_dataset(kind.value, src, out, compression=compression.value)
    typer.echo(f"{out}: {count} frames from {src}")


@app.command()
@one_line_errors
def info(rec: Annotated[Path, typer.Argument(help="A recording (.mcap).")]) -> None:
    """Print a recording's topics, frames, duration, drops, device and whether it was finished.

    Example:
    ```
    semreplay-capture info room.mcap
    ```
    """
    from capture.recording.info import describe, format_info

    typer.echo(format_info(describe(rec)))
