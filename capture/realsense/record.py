"""A live D435, or a RealSense recording (.bag, .db3), into an MCAP recording via pyrealsense2.

The only module that imports pyrealsense2 (lazily); capture.realsense.device and
capture.realsense.camera are handed it. Both paths run the sensors with frame callbacks that copy
each frame into a `ThreadedWriter`; the device is injectable, so the tests drive the same code with
an `rs.software_device`. Sensors are used directly rather than through `rs.pipeline`: a pipeline
over a played-back file cannot pace non-real-time playback by its consumer, and dedupes nothing; a
blocking callback does both.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import asdict
from pathlib import Path
from typing import Any

from capture.errors import CameraError
from capture.realsense.camera import Camera
from capture.realsense.device import configure, find_device, select_streams
from capture.realsense.session import (
    RecordConfig,
    RecordResult,
    RecordStatus,
    finish_session,
    start_sink,
    watch,
)
from capture.recording.writer import capture_record


def rs_module() -> Any:
    """Return pyrealsense2, or raise a CameraError that names the extra to install."""
    try:
        import pyrealsense2 as rs
    except ImportError as err:
        raise CameraError(
            f"pyrealsense2 is not installed ({err}); install it: pip install '.[capture]'"
        ) from err
    return rs


@contextlib.contextmanager
def _librealsense(doing: str) -> Iterator[None]:
    """Turn librealsense's RuntimeError into a one-line CameraError."""
    try:
        yield
    except RuntimeError as err:
        raise CameraError(
            f"{doing} failed in librealsense ({err}); check the USB 3 cable and that no other "
            "program holds the camera"
        ) from err


def record(
    path: Path,
    config: RecordConfig,
    *,
    device: Any = None,
    stop: threading.Event | None = None,
    on_status: Callable[[RecordStatus], None] | None = None,
) -> RecordResult:
    """Record a live camera (or an injected pyrealsense2 device) until duration, stop or loss."""
    rs = rs_module()
    with _librealsense("opening the camera"):
        dev = device if device is not None else find_device(rs, config.serial)
        streams = select_streams(rs, dev, config)
        configure(rs, streams, config)
    sink = start_sink(Path(path), streams, config=config, blocking=False)
    sink.writer.write_metadata(
        "capture", capture_record("semreplay-capture record", source="live", config=asdict(config))
    )
    camera = Camera(rs, streams, sink, align=config.align)
    t0 = time.monotonic()
    reason, lost = "stopped", False
    try:
        with _librealsense("starting the camera streams"):
            camera.start()
        reason, lost = watch(
            camera, sink, config, stop=stop or threading.Event(), on_status=on_status
        )
    finally:
        result = finish_session(sink, camera, path=Path(path), t0=t0, reason=reason, lost=lost)
    return result


def convert(
    src: Path, out: Path, *, compression: str = "zstd", idle_s: float = 0.5
) -> RecordResult:
    """Replay a RealSense .bag/.db3 through pyrealsense2 into an MCAP recording, bit-exact."""
    rs = rs_module()
    src = Path(src)
    dev = _load_recording(rs, src)
    playback = dev.as_playback()
    playback.set_real_time(False)  # every frame, as fast as the writer takes them
    try:
        streams = select_streams(rs, dev, None)
    except CameraError as err:
        raise CameraError(f"{err}: {src}") from err
    config = RecordConfig(compression=compression, queue_size=16)
    sink = start_sink(Path(out), streams, config=config, blocking=True)
    sink.writer.write_metadata(
        "capture",
        capture_record(
            "semreplay-capture convert", source=str(src), config={"compression": compression}
        ),
    )
    camera = Camera(rs, streams, sink, align=False)
    t0 = time.monotonic()
    try:
        playback.pause()  # start every sensor before the first frame plays
        camera.start()
        playback.resume()
        while camera.error is None and sink.error is None:
            time.sleep(0.05)
            ended = playback.current_status() == rs.playback_status.stopped
            if ended and sink.idle and time.monotonic() - sink.last_submit_mono > idle_s:
                break
    finally:
        result = finish_session(
            sink, camera, path=Path(out), t0=t0, reason="end of file", lost=False
        )
    return result


def _load_recording(rs: Any, src: Path) -> Any:
    """Return the playback device of a RealSense .bag/.db3, or raise a CameraError naming it."""
    if src.suffix not in (".bag", ".db3"):
        raise CameraError(
            f"expected a RealSense recording (.bag or .db3), found {src.suffix!r}: {src}"
        )
    if not src.is_file():
        raise CameraError(f"no such RealSense recording: {src}")
    try:
        return rs.context().load_device(str(src))
    except RuntimeError as err:
        raise CameraError(f"pyrealsense2 cannot play this recording ({err}): {src}") from err
