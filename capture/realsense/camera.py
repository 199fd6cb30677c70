"""Camera: a device's chosen sensors feeding a ThreadedWriter from their frame callbacks."""

from __future__ import annotations

import contextlib
import threading
import time
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from capture.errors import CameraError, CaptureError
from capture.realsense.session import Streams
from capture.realsense.sink import StreamFrame, ThreadedWriter

# Colour formats a recording may hold, and how to turn them into RGB.
TO_RGB = {"rgb8": None, "bgr8": cv2.COLOR_BGR2RGB, "rgba8": cv2.COLOR_RGBA2RGB,
          "bgra8": cv2.COLOR_BGRA2RGB, "yuyv": cv2.COLOR_YUV2RGB_YUY2}  # fmt: skip


def _to_rgb(data: npt.NDArray[Any], fmt: str) -> npt.NDArray[np.uint8]:
    code = TO_RGB[fmt]
    if code is None:
        return np.array(data, dtype=np.uint8, copy=True)
    return np.asarray(cv2.cvtColor(np.ascontiguousarray(data), code), dtype=np.uint8)


def _metadata(rs: Any, frame: Any) -> dict[str, object]:
    meta: dict[str, object] = {
        "frame_number": int(frame.get_frame_number()),
        "timestamp_ms": float(frame.get_timestamp()),
        "timestamp_domain": frame.get_frame_timestamp_domain().name,
    }
    for name, key in rs.frame_metadata_value.__members__.items():
        if frame.supports_frame_metadata(key):
            meta[name] = int(frame.get_frame_metadata(key))
    return meta


class Camera:
    """The chosen sensors of a device, feeding a ThreadedWriter from their frame callbacks."""

    def __init__(self, rs: Any, streams: Streams, sink: ThreadedWriter, *, align: bool) -> None:
        self.rs = rs
        self.streams = streams
        self.sink = sink
        self.align = align
        self.playback = bool(streams.device.is_playback())
        self.error: CaptureError | None = None
        self._running: list[Any] = []
        self._pump: threading.Thread | None = None
        self._pump_stop = threading.Event()

    def start(self) -> None:
        """Open and start the sensors."""
        syncer = self.rs.syncer() if self.align else None
        for sensor, profiles in self.streams.sensors:
            sensor.open(profiles)
            sensor.start(syncer if syncer is not None else self._on_frame)
            self._running.append(sensor)
        if syncer is not None:
            self._pump_stop.clear()
            self._pump = threading.Thread(target=self._align_pump, args=(syncer,), daemon=True)
            self._pump.start()

    def stop(self) -> None:
        """Stop and close the sensors (a lost device may refuse; that is fine here)."""
        self._pump_stop.set()
        if self._pump is not None:
            self._pump.join()
            self._pump = None
        for sensor in self._running:
            for action in (sensor.stop, sensor.close):
                with contextlib.suppress(RuntimeError):  # already stopped, or the camera is gone
                    action()
        self._running = []

    def restart(self) -> None:
        """Stop and start again; a camera that cannot start stays silent and times out again."""
        self.stop()
        try:
            self.start()
        except RuntimeError:
            self.stop()

    def _on_frame(self, frame: Any) -> None:
        # Runs on a librealsense thread: never raise into it.
        try:
            self._submit(frame)
        except Exception as err:
            self.error = CameraError(f"a camera frame could not be taken: {err}")

    def _submit(self, frame: Any, *, depth_aligned: bool = False) -> None:
        rs = self.rs
        log_ns = time.time_ns()
        is_depth = frame.get_profile().stream_type() == rs.stream.depth
        data = np.asanyarray(frame.as_video_frame().get_data())
        meta = _metadata(rs, frame)
        stamp_ns = round(float(frame.get_timestamp()) * 1e6)
        if self.playback:  # the recorded host receive time, where the file kept it
            arrival = meta.get("time_of_arrival")
            log_ns = int(arrival) * 1_000_000 if isinstance(arrival, int) else stamp_ns
        image = data.copy() if is_depth else _to_rgb(data, self.streams.color_format)
        kind = "depth" if is_depth else "color"
        number = int(frame.get_frame_number())
        self.sink.submit(StreamFrame(kind, number, stamp_ns, log_ns, image, meta))

    def _align_pump(self, syncer: Any) -> None:
        align = self.rs.align(self.rs.stream.color)
        while not self._pump_stop.is_set():
            ok, frames = syncer.try_wait_for_frames(100)
            if not ok or frames.size() < 2:
                continue  # a lone frame: its partner was dropped; the gap counts it
            try:
                aligned = align.process(frames)
                self._submit(aligned.get_color_frame())
                self._submit(aligned.get_depth_frame())
            except Exception as err:
                self.error = CameraError(f"aligning depth to colour failed: {err}")
