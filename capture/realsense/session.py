"""A capture session into MCAP: its settings, its status line, how it ends. No camera code here."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from capture.errors import CaptureError
from capture.realsense.sink import ThreadedWriter, finish_recording
from capture.recording.frames import Extrinsics, Intrinsics
from capture.recording.writer import RecordingWriter


@dataclass(frozen=True, slots=True)
class RecordConfig:
    """How to record a live camera; None leaves a camera setting as it is."""

    width: int = 640
    height: int = 480
    fps: int = 30
    depth_width: int | None = None  # None: as colour
    depth_height: int | None = None
    depth_fps: int | None = None
    align: bool = False  # depth aligned to colour by librealsense on the host
    compression: str = "zstd"
    color_jpeg: bool = False
    duration_s: float | None = None  # None: until stopped (Ctrl-C)
    serial: str | None = None
    preset: str | None = None  # depth visual preset name, e.g. "High Accuracy"
    emitter: bool | None = None
    frame_timeout_s: float = 5.0
    retries: int = 3
    queue_size: int = 96

    def __post_init__(self) -> None:
        sizes = (self.width, self.height, self.fps, self.depth_width, self.depth_height)
        checks = {
            "sizes and rates": all(v is None or v > 0 for v in (*sizes, self.depth_fps)),
            "duration_s": self.duration_s is None or self.duration_s > 0,
            "frame_timeout_s": self.frame_timeout_s > 0,
            "retries": self.retries >= 0,
            "queue_size": self.queue_size > 0,
            "compression": self.compression in ("zstd", "lz4", "none"),
        }
        bad = [name for name, ok in checks.items() if not ok]
        if bad:
            raise CaptureError(
                f"invalid record settings ({', '.join(bad)}) in {self}; sizes, rates, times and "
                "the queue must be > 0, retries >= 0, compression zstd|lz4|none"
            )

    @property
    def depth_mode(self) -> tuple[int, int, int]:
        """Return the depth stream's (width, height, fps)."""
        return (
            self.depth_width or self.width,
            self.depth_height or self.height,
            self.depth_fps or self.fps,
        )


@dataclass(frozen=True, slots=True)
class RecordStatus:
    """What the status line shows, about once a second."""

    elapsed_s: float
    fps: float  # colour frames written per second
    mb_per_s: float  # raw image megabytes written per second
    frames: int  # colour frames written so far
    dropped: int  # frames dropped so far, all streams


@dataclass(frozen=True, slots=True)
class RecordResult:
    """How a recording ended."""

    path: Path
    frames_written: dict[str, int]
    frames_dropped: dict[str, int]
    duration_s: float
    stop_reason: str  # "duration", "stopped", "end of file" or why the camera was given up
    camera_lost: bool = False


@dataclass(slots=True)
class Streams:
    """The depth and colour streams of a device, with their calibration."""

    device: Any
    sensors: list[tuple[Any, list[Any]]]  # (sensor, the profiles to open on it)
    color_format: str
    color_intrinsics: Intrinsics
    depth_intrinsics: Intrinsics
    depth_to_color: Extrinsics
    depth_scale_m: float
    info: dict[str, str] = field(default_factory=dict)


class Restartable(Protocol):
    """A running camera that can be restarted and may have failed."""

    error: CaptureError | None

    def restart(self) -> None:
        """Stop and start the camera's sensors again."""

    def stop(self) -> None:
        """Stop the camera's sensors."""


def watch(
    camera: Restartable,
    sink: ThreadedWriter,
    config: RecordConfig,
    *,
    stop: threading.Event,
    on_status: Callable[[RecordStatus], None] | None,
) -> tuple[str, bool]:
    """Wait for the end of a recording, restarting a silent camera; return (reason, lost)."""
    t0 = time.monotonic()
    restarts = 0
    last = (t0, 0, 0)  # (time, colour frames, image bytes) at the last status
    while not stop.wait(0.05):
        now = time.monotonic()
        if sink.error is not None or camera.error is not None:
            return "failed", False
        if config.duration_s is not None and now - t0 >= config.duration_s:
            return "duration", False
        if now - sink.last_submit_mono > config.frame_timeout_s:
            if restarts >= config.retries:
                why = f"no frame for {config.frame_timeout_s:g} s after {restarts} restarts"
                return f"camera lost ({why})", True
            restarts += 1
            camera.restart()
            sink.restart_numbering()
        if on_status is not None and now - last[0] >= 1.0:
            stats = sink.stats()
            dt = now - last[0]
            on_status(
                RecordStatus(
                    elapsed_s=now - t0,
                    fps=(stats.written["color"] - last[1]) / dt,
                    mb_per_s=(stats.image_bytes - last[2]) / dt / 1e6,
                    frames=stats.written["color"],
                    dropped=sum(stats.dropped.values()),
                )
            )
            last = (now, stats.written["color"], stats.image_bytes)
    return "stopped", False


def start_sink(
    path: Path, streams: Streams, *, config: RecordConfig, blocking: bool
) -> ThreadedWriter:
    """Open the recording, write its `device` record and start its writer thread."""
    writer = RecordingWriter(path, compression=config.compression, color_jpeg=config.color_jpeg)
    info = {**streams.info, "depth_scale_m": "0.001",
            "sensor_depth_scale_m": repr(streams.depth_scale_m)}  # fmt: skip
    writer.write_metadata("device", info)  # depth is converted to mm at capture
    sink = ThreadedWriter(
        writer,
        color_intrinsics=streams.color_intrinsics,
        depth_intrinsics=streams.depth_intrinsics,
        depth_to_color=streams.depth_to_color,
        aligned=config.align,
        depth_scale_m=streams.depth_scale_m,
        queue_size=config.queue_size,
        blocking=blocking,
    )
    sink.start()
    return sink


def finish_session(
    sink: ThreadedWriter, camera: Restartable, *, path: Path, t0: float, reason: str, lost: bool
) -> RecordResult:
    """Stop the camera, write what is queued and finish the file; raise why it failed, if it did."""
    camera.stop()
    stats = sink.stop()
    finish_recording(sink.writer, sink.summary(stats))
    error = sink.error or camera.error
    if error is not None:
        raise error
    return RecordResult(path, stats.written, stats.dropped, time.monotonic() - t0, reason, lost)
