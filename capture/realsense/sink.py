"""Camera frames into a RecordingWriter through a bounded queue drained by one writer thread.

The camera's callbacks only copy a frame and `submit` it, so they never wait on the disk. Drops
are counted per stream from frame-number gaps (the camera or driver lost it) and from a full queue
(the writer fell behind). In `blocking` mode (converting a file) a full queue waits instead.
"""

from __future__ import annotations

import logging
import queue
import signal
import threading
import time
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import datetime
from types import FrameType
from typing import Final

import numpy as np
import numpy.typing as npt

from capture.errors import CaptureError, RecordingError
from capture.recording.frames import Extrinsics, Intrinsics
from capture.recording.writer import RecordingWriter

logger = logging.getLogger(__name__)

STREAMS: Final = ("color", "depth")


@dataclass(frozen=True, slots=True)
class StreamFrame:
    """One camera image, copied out of the driver's buffer, on its way to the writer."""

    stream: str  # "color" or "depth"
    frame_number: int
    stamp_ns: int  # the frame's own timestamp
    log_ns: int  # host receive time
    image: npt.NDArray[np.uint8] | npt.NDArray[np.uint16]  # (H, W, 3) RGB or (H, W) depth units
    metadata: Mapping[str, object] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class CaptureStats:
    """Counters of a capture so far, per stream."""

    written: dict[str, int]
    dropped_by_camera: dict[str, int]  # frame-number gaps
    dropped_by_queue: dict[str, int]  # writer fell behind
    image_bytes: int  # raw image bytes written
    queued: int

    @property
    def dropped(self) -> dict[str, int]:
        """Return all drops per stream."""
        return {s: self.dropped_by_camera[s] + self.dropped_by_queue[s] for s in STREAMS}


class ThreadedWriter:
    """Write submitted StreamFrames to a RecordingWriter on a thread of its own."""

    def __init__(
        self,
        writer: RecordingWriter,
        *,
        color_intrinsics: Intrinsics,
        depth_intrinsics: Intrinsics,
        depth_to_color: Extrinsics | None = None,
        aligned: bool = False,
        depth_scale_m: float = 0.001,
        queue_size: int = 64,
        blocking: bool = False,
    ) -> None:
        self.writer = writer
        self.color_intrinsics = color_intrinsics
        self.depth_intrinsics = color_intrinsics if aligned else depth_intrinsics
        self.aligned = aligned
        self._calibration = depth_to_color  # written just before the first frame
        self.depth_scale_m = depth_scale_m
        self.blocking = blocking
        self.error: CaptureError | None = None
        self.last_submit_mono = time.monotonic()
        self._queue: queue.Queue[StreamFrame | None] = queue.Queue(maxsize=queue_size)
        self._lock = threading.Lock()
        self._last_number: dict[str, int | None] = dict.fromkeys(STREAMS)
        self._written = dict.fromkeys(STREAMS, 0)
        self._gaps = dict.fromkeys(STREAMS, 0)
        self._overflow = dict.fromkeys(STREAMS, 0)
        self._image_bytes = 0
        self._thread = threading.Thread(target=self._run, name="mcap-writer", daemon=True)

    def start(self) -> None:
        """Start the writer thread."""
        self._thread.start()

    def restart_numbering(self) -> None:
        """Forget the last frame numbers (the camera restarts its counters after a restart)."""
        with self._lock:
            self._last_number = dict.fromkeys(STREAMS)
            self.last_submit_mono = time.monotonic()

    def submit(self, frame: StreamFrame) -> bool:
        """Queue a frame for writing; return False when it was a duplicate or was dropped."""
        with self._lock:
            last = self._last_number[frame.stream]
            if last is not None and frame.frame_number <= last:
                return False  # a frame seen before (framesets repeat frames)
            if last is not None:
                self._gaps[frame.stream] += frame.frame_number - last - 1
            self._last_number[frame.stream] = frame.frame_number
            self.last_submit_mono = time.monotonic()
        try:
            self._queue.put(frame, block=self.blocking)
        except queue.Full:
            with self._lock:
                self._overflow[frame.stream] += 1
            return False
        return True

    def stats(self) -> CaptureStats:
        """Return the counters so far."""
        with self._lock:
            return CaptureStats(
                written=dict(self._written),
                dropped_by_camera=dict(self._gaps),
                dropped_by_queue=dict(self._overflow),
                image_bytes=self._image_bytes,
                queued=self._queue.qsize(),
            )

    def stop(self) -> CaptureStats:
        """Write what is queued, end the thread and return the final counters."""
        if self._thread.is_alive():
            self._queue.put(None)
            self._thread.join()
        return self.stats()

    @property
    def idle(self) -> bool:
        """Return whether nothing is waiting to be written."""
        return self._queue.unfinished_tasks == 0

    def _run(self) -> None:
        while True:
            try:
                item = self._queue.get(timeout=0.2)
            except queue.Empty:
                self._guarded(self.writer.flush_if_due)
                continue
            try:
                if item is None:  # the stop marker
                    return
                if self.error is None:  # after a failure, drain so that producers never block
                    self._guarded(lambda frame=item: self._write(frame))
            finally:
                self._queue.task_done()

    def _guarded(self, work: object) -> None:
        try:
            work()  # type: ignore[operator]
        except CaptureError as err:
            logger.debug("writer thread stopped: %s", err)
            self.error = err

    def _write(self, frame: StreamFrame) -> None:
        if self._calibration is not None:
            stamp_ns = min(frame.stamp_ns, frame.log_ns) - 1
            self.writer.write_calibration(self._calibration, stamp_ns=stamp_ns)
            self._calibration = None
        if frame.stream == "color":
            self.writer.write_color(
                np.asarray(frame.image, dtype=np.uint8),
                stamp_ns=frame.stamp_ns,
                intrinsics=self.color_intrinsics,
                log_ns=frame.log_ns,
                metadata=frame.metadata or None,
            )
        else:
            self.writer.write_depth(
                self._depth_mm(frame.image),
                stamp_ns=frame.stamp_ns,
                intrinsics=self.depth_intrinsics,
                aligned=self.aligned,
                log_ns=frame.log_ns,
                metadata=frame.metadata or None,
            )
        with self._lock:
            self._written[frame.stream] += 1
            self._image_bytes += frame.image.nbytes

    def _depth_mm(
        self, raw: npt.NDArray[np.uint8] | npt.NDArray[np.uint16]
    ) -> npt.NDArray[np.uint16]:
        """Return depth in millimetres; RECORDING.md converts other units at capture."""
        units_um = round(self.depth_scale_m * 1e6)  # D400 depth units are whole micrometres
        if units_um == 1000:
            return np.asarray(raw, dtype=np.uint16)
        # Integer arithmetic, rounding half up: float products tie-break inconsistently.
        mm = (raw.astype(np.uint64) * units_um + 500) // 1000
        return np.minimum(mm, 65535).astype(np.uint16)

    def summary(self, stats: CaptureStats) -> dict[str, object]:
        """Return the end-of-capture part of the `capture` metadata record."""
        return {
            "frames_written": stats.written,
            "frames_dropped": stats.dropped,
            "dropped_by_camera": stats.dropped_by_camera,
            "dropped_by_queue": stats.dropped_by_queue,
            "finished_at": datetime.now().astimezone().isoformat(timespec="seconds"),
        }


def finish_recording(writer: RecordingWriter, summary: Mapping[str, object]) -> None:
    """Finish the file with the summary, or leave it recoverable when the disk refuses."""
    try:
        writer.finish(summary)
    except RecordingError:
        writer.close_unfinished()
        raise


@contextmanager
def stop_on_signals() -> Iterator[threading.Event]:
    """Yield an event that SIGINT or SIGTERM sets; a second signal acts as usual."""
    stop = threading.Event()
    signals = (signal.SIGINT, signal.SIGTERM)
    previous = {s: signal.getsignal(s) for s in signals}

    def handler(signum: int, frame: FrameType | None) -> None:
        stop.set()
        for s, old in previous.items():  # a second Ctrl-C interrupts a stuck finish
            signal.signal(s, old)

    for s in signals:
        signal.signal(s, handler)
    try:
        yield stop
    finally:
        for s, old in previous.items():
            signal.signal(s, old)
