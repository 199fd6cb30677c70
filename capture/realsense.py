"""A live D435, or a RealSense recording (.bag, .db3), into an MCAP recording via pyrealsense2.

The only module that imports pyrealsense2 (lazily). Both paths run the sensors with frame
callbacks that copy each frame into a `ThreadedWriter`; the device is injectable, so the tests
drive the same code with an `rs.software_device`. Sensors are used directly rather than through
`rs.pipeline`: a pipeline over a played-back file cannot pace non-real-time playback by its
consumer, and dedupes nothing; a blocking callback does both.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import asdict
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from capture.errors import CameraError, CaptureError
from capture.frames import Extrinsics, Intrinsics
from capture.mcap_session import (
    RecordConfig,
    RecordResult,
    RecordStatus,
    Streams,
    capture_record,
    finish_session,
    start_sink,
    watch,
)
from capture.mcap_threaded import StreamFrame, ThreadedWriter

__all__ = ["RecordConfig", "RecordResult", "RecordStatus", "convert", "record"]

# Colour formats a recording may hold, and how to turn them into RGB.
_TO_RGB = {"rgb8": None, "bgr8": cv2.COLOR_BGR2RGB, "rgba8": cv2.COLOR_RGBA2RGB,
           "bgra8": cv2.COLOR_BGRA2RGB, "yuyv": cv2.COLOR_YUV2RGB_YUY2}  # fmt: skip
_DEVICE_INFO = {"name": "name", "serial_number": "serial_number",
                "firmware_version": "firmware_version", "usb_type": "usb_type_descriptor",
                "product_line": "product_line"}  # fmt: skip


def rs_module() -> Any:
    """Return pyrealsense2, or raise a CameraError that names the extra to install."""
    try:
        import pyrealsense2 as rs
    except ImportError as err:
        raise CameraError(
            f"pyrealsense2 is not installed ({err}); install it: pip install '.[capture]'"
        ) from err
    return rs


def intrinsics_of(rs: Any, profile: Any) -> Intrinsics:
    """Return the Intrinsics of a video stream profile, with realsense-ros's distortion naming."""
    k = profile.as_video_stream_profile().get_intrinsics()
    fisheye = k.model == rs.distortion.kannala_brandt4
    coeffs = tuple(float(c) for c in k.coeffs)[: 4 if fisheye else 5]
    return Intrinsics(
        width=int(k.width),
        height=int(k.height),
        fx=float(k.fx),
        fy=float(k.fy),
        cx=float(k.ppx),
        cy=float(k.ppy),
        # As realsense-ros: Brown-Conrady (and its inverse, which D435 colour reports, always
        # with zero coefficients) are plumb_bob k1 k2 p1 p2 k3; Kannala-Brandt is equidistant.
        distortion_model="equidistant" if fisheye else "plumb_bob",
        coeffs=coeffs,
    )


def find_device(rs: Any, serial: str | None) -> Any:
    """Return the connected RealSense device (with the serial number, if given)."""
    devices = list(rs.context().query_devices())
    serials = [d.get_info(rs.camera_info.serial_number) for d in devices]
    if not devices:
        raise CameraError("no RealSense camera found; connect a D435 to a USB 3 port")
    if serial is None:
        return devices[0]
    if serial not in serials:
        raise CameraError(f"no RealSense camera with serial {serial}; found: {', '.join(serials)}")
    return devices[serials.index(serial)]


def _mode(p: Any) -> str:
    return f"{p.width()}x{p.height()}@{p.fps()} {p.format().name}"


def select_streams(rs: Any, device: Any, config: RecordConfig | None) -> Streams:
    """Pick the depth (z16) and colour streams; `config` None takes the first of each (files)."""
    found: dict[str, list[tuple[int, Any]]] = {"depth": [], "color": []}
    sensors = list(device.query_sensors())
    for i, sensor in enumerate(sensors):
        for p in sensor.get_stream_profiles():
            if not p.is_video_stream_profile():
                continue
            vp = p.as_video_stream_profile()
            if vp.stream_type() == rs.stream.depth and vp.format() == rs.format.z16:
                found["depth"].append((i, vp))
            elif vp.stream_type() == rs.stream.color and vp.format().name in _TO_RGB:
                found["color"].append((i, vp))
    wanted: dict[str, tuple[int, int, int, str] | None] = {"depth": None, "color": None}
    if config is not None:
        wanted = {"depth": (*config.depth_mode, "z16"),
                  "color": (config.width, config.height, config.fps, "rgb8")}  # fmt: skip
    chosen = {kind: _choose(found[kind], wanted[kind], kind) for kind in found}
    groups: dict[int, list[Any]] = {}
    for i, vp in chosen.values():
        groups.setdefault(i, []).append(vp)
    depth_sensor = sensors[chosen["depth"][0]]
    depth, color = chosen["depth"][1], chosen["color"][1]
    try:
        e = depth.get_extrinsics_to(color)
    except RuntimeError as err:
        raise CameraError(f"the device has no depth->colour extrinsics ({err})") from err
    return Streams(
        device=device,
        sensors=[(sensors[i], profiles) for i, profiles in groups.items()],
        color_format=color.format().name,
        color_intrinsics=intrinsics_of(rs, color),
        depth_intrinsics=intrinsics_of(rs, depth),
        depth_to_color=Extrinsics.from_librealsense(e.rotation, e.translation),
        depth_scale_m=_depth_scale(rs, depth_sensor),
        info=_device_info(rs, device),
    )


def _choose(
    candidates: list[tuple[int, Any]], wanted: tuple[int, int, int, str] | None, kind: str
) -> tuple[int, Any]:
    for i, vp in candidates:
        if wanted is None or (vp.width(), vp.height(), vp.fps(), vp.format().name) == wanted:
            return i, vp
    offered = ", ".join(sorted({_mode(vp) for _, vp in candidates})) or "none"
    want = "any" if wanted is None else "{}x{}@{} {}".format(*wanted)
    raise CameraError(f"no {kind} stream {want}; the device offers: {offered}")


def _depth_scale(rs: Any, sensor: Any) -> float:
    if sensor.supports(rs.option.depth_units):
        return float(sensor.get_option(rs.option.depth_units))
    return 0.001


def _device_info(rs: Any, device: Any) -> dict[str, str]:
    info = {}
    for key, attr in _DEVICE_INFO.items():
        ci = getattr(rs.camera_info, attr)
        info[key] = str(device.get_info(ci)) if device.supports(ci) else ""
    return info


def configure(rs: Any, streams: Streams, config: RecordConfig) -> None:
    """Set the depth preset and emitter where asked, and global timestamps where possible."""
    for sensor, _ in streams.sensors:
        if sensor.supports(rs.option.global_time_enabled):
            sensor.set_option(rs.option.global_time_enabled, 1)
    depth_sensor = streams.sensors[0][0]
    for sensor, profiles in streams.sensors:
        if any(p.stream_type() == rs.stream.depth for p in profiles):
            depth_sensor = sensor
    if config.preset is not None:
        _set_preset(rs, depth_sensor, config.preset)
    if config.emitter is not None:
        if not depth_sensor.supports(rs.option.emitter_enabled):
            raise CameraError("this camera has no IR emitter to switch; leave --emitter out")
        depth_sensor.set_option(rs.option.emitter_enabled, 1 if config.emitter else 0)


def _set_preset(rs: Any, sensor: Any, name: str) -> None:
    option = rs.option.visual_preset
    if not sensor.supports(option):
        raise CameraError(f"this camera has no depth presets; leave --preset {name!r} out")
    r = sensor.get_option_range(option)
    names = {
        sensor.get_option_value_description(option, float(v)): float(v)
        for v in range(int(r.min), int(r.max) + 1)
    }
    key = {n.lower().replace("_", " "): v for n, v in names.items()}.get(
        name.lower().replace("_", " ")
    )
    if key is None:
        raise CameraError(f"unknown depth preset {name!r}; the camera has: {', '.join(names)}")
    sensor.set_option(option, key)


def _to_rgb(data: npt.NDArray[Any], fmt: str) -> npt.NDArray[np.uint8]:
    code = _TO_RGB[fmt]
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
    sink.writer.write_metadata("capture", capture_record("live", asdict(config)))
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
    if src.suffix not in (".bag", ".db3"):
        raise CameraError(
            f"expected a RealSense recording (.bag or .db3), found {src.suffix!r}: {src}"
        )
    if not src.is_file():
        raise CameraError(f"no such RealSense recording: {src}")
    try:
        dev = rs.context().load_device(str(src))
    except RuntimeError as err:
        raise CameraError(f"pyrealsense2 cannot play this recording ({err}): {src}") from err
    playback = dev.as_playback()
    playback.set_real_time(False)  # every frame, as fast as the writer takes them
    try:
        streams = select_streams(rs, dev, None)
    except CameraError as err:
        raise CameraError(f"{err}: {src}") from err
    config = RecordConfig(compression=compression, queue_size=16)
    sink = start_sink(Path(out), streams, config=config, blocking=True)
    sink.writer.write_metadata("capture", capture_record(str(src), {"compression": compression}))
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
