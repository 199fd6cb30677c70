"""A software RealSense camera with known frames, and subprocess writers for crash/signal tests.

Run as a script (`python tests/helpers_capture.py MODE OUT`) it is the subprocess side:
`kill-writer` writes 10 frames/s through RecordingWriter and prints each frame it wrote;
`record-until-signal` runs `capture.realsense.record.record` over a software camera until SIGTERM.
"""

from __future__ import annotations

import errno
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pyrealsense2 as rs
from scipy.spatial.transform import Rotation

from capture.recording.frames import Extrinsics, Intrinsics

COLOR_W, COLOR_H = 96, 72
DEPTH_W, DEPTH_H = 80, 60
COLOR_K = (90.5, 91.25, 47.75, 35.5)  # fx fy cx cy, exact in float32
DEPTH_K = (70.0, 70.5, 40.25, 29.75)
COLOR_COEFFS = (0.125, -0.25, 0.0009765625, -0.001953125, 0.0625)  # exact in float32
# 2 degrees about a skew axis: a non-symmetric rotation, so a transposed matrix would show.
_AXIS = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
ROTATION = Rotation.from_rotvec(_AXIS * np.deg2rad(2.0)).as_matrix()
TRANSLATION = (0.015, -0.0002, 0.0004)
STAMP0_MS = 1_700_000_000_000.0  # global time (epoch ms) of frame 0
ROOT = Path(__file__).resolve().parents[1]


def color_image(i: int) -> npt.NDArray[np.uint8]:
    """Return colour frame i: seeded noise, different per frame."""
    rng = np.random.default_rng(1000 + i)
    return rng.integers(0, 256, (COLOR_H, COLOR_W, 3), dtype=np.uint8)


def depth_image(i: int) -> npt.NDArray[np.uint16]:
    """Return depth frame i in sensor units: seeded values over the whole uint16 range."""
    rng = np.random.default_rng(2000 + i)
    return rng.integers(0, 65536, (DEPTH_H, DEPTH_W), dtype=np.uint16)


def expected_extrinsics() -> Extrinsics:
    """Return the depth->colour transform the software camera registers (float32-rounded)."""
    m = np.eye(4)
    m[:3, :3] = ROTATION.astype(np.float32)
    m[:3, 3] = np.asarray(TRANSLATION, dtype=np.float32)
    return Extrinsics(m)


def expected_intrinsics(kind: str) -> Intrinsics:
    """Return the intrinsics of the software camera's colour or depth stream."""
    w, h, k, coeffs = (
        (COLOR_W, COLOR_H, COLOR_K, COLOR_COEFFS)
        if kind == "color"
        else (DEPTH_W, DEPTH_H, DEPTH_K, (0.0,) * 5)
    )
    return Intrinsics(w, h, *k, distortion_model="plumb_bob", coeffs=coeffs)


def _rs_intrinsics(w: int, h: int, k: tuple[float, ...], coeffs: tuple[float, ...]) -> Any:
    out = rs.intrinsics()
    out.width, out.height = w, h
    out.fx, out.fy, out.ppx, out.ppy = k
    out.model = rs.distortion.brown_conrady
    out.coeffs = list(coeffs)
    return out


def _stream(kind: str, fps: int) -> Any:
    vs = rs.video_stream()
    depth = kind == "depth"
    vs.type = rs.stream.depth if depth else rs.stream.color
    vs.index, vs.uid, vs.fps = 0, 0 if depth else 1, fps
    vs.width, vs.height = (DEPTH_W, DEPTH_H) if depth else (COLOR_W, COLOR_H)
    vs.bpp = 2 if depth else 3
    vs.fmt = rs.format.z16 if depth else rs.format.rgb8
    vs.intrinsics = (
        _rs_intrinsics(DEPTH_W, DEPTH_H, DEPTH_K, (0.0,) * 5)
        if depth
        else _rs_intrinsics(COLOR_W, COLOR_H, COLOR_K, COLOR_COEFFS)
    )
    return vs


@dataclass
class SoftCamera:
    """A pyrealsense2 software_device shaped like a D435: a stereo module and an RGB camera."""

    fps: int = 30
    depth_units_m: float = 0.001
    device: Any = None
    sensors: dict[str, Any] = field(default_factory=dict)
    profiles: dict[str, Any] = field(default_factory=dict)
    _keep: list[Any] = field(default_factory=list)  # pixel buffers must outlive the frames

    def __post_init__(self) -> None:
        dev = rs.software_device()
        for key, value in (
            (rs.camera_info.name, "Intel RealSense D435 (software)"),
            (rs.camera_info.serial_number, "000123456789"),
            (rs.camera_info.firmware_version, "5.16.0.1"),
            (rs.camera_info.product_line, "D400"),
        ):
            dev.register_info(key, value)
        self.sensors["depth"] = dev.add_sensor("Stereo Module")
        self.sensors["color"] = dev.add_sensor("RGB Camera")
        self.sensors["depth"].add_read_only_option(rs.option.depth_units, self.depth_units_m)
        for kind in ("depth", "color"):
            profile = self.sensors[kind].add_video_stream(_stream(kind, self.fps))
            self.profiles[kind] = profile.as_video_stream_profile()
        ex = rs.extrinsics()
        ex.rotation = [float(v) for v in ROTATION.T.reshape(-1)]  # column-major
        ex.translation = list(TRANSLATION)
        self.profiles["depth"].register_extrinsics_to(self.profiles["color"], ex)
        self.device = dev

    def push(self, i: int, *, number: int | None = None) -> None:
        """Send frame i (colour and depth, same timestamp) from the started sensors."""
        stamp_ms = STAMP0_MS + i * 1000.0 / self.fps
        for kind, pixels, bpp, width in (
            ("depth", depth_image(i), 2, DEPTH_W),
            ("color", color_image(i), 3, COLOR_W),
        ):
            self._keep.append(pixels)
            f = rs.software_video_frame()
            f.pixels, f.bpp, f.stride = pixels, bpp, bpp * width
            f.timestamp, f.domain = stamp_ms, rs.timestamp_domain.global_time
            f.frame_number = i if number is None else number
            f.profile = self.profiles[kind]
            self.sensors[kind].on_video_frame(f)

    def feed(self, indices: list[int], *, after: threading.Event | None = None) -> threading.Thread:
        """Push the frames at the camera's rate on a thread (waiting for `after`, if given)."""

        def run() -> None:
            if after is not None:
                after.wait(10.0)
            for i in indices:
                self.push(i)
                time.sleep(1.0 / self.fps)

        thread = threading.Thread(target=run, daemon=True)
        thread.start()
        return thread

    def record_file(self, path: Path, count: int) -> None:
        """Record `count` frames into a RealSense .db3 with librealsense's own recorder."""
        recorder = rs.recorder(str(path), self.device, False)
        for kind in ("depth", "color"):
            self.sensors[kind].open(self.profiles[kind])
            self.sensors[kind].start(lambda _f: None)
        for i in range(count):
            self.push(i)
        for kind in ("depth", "color"):
            self.sensors[kind].stop()
            self.sensors[kind].close()
        recorder.pause()
        del recorder


class FullDisk:
    """A file stream that takes `limit` bytes and then fails as a full disk does (ENOSPC)."""

    def __init__(self, stream: Any, limit: int) -> None:
        self.stream = stream
        self.left = limit

    def write(self, data: bytes) -> int:
        """Write what fits, then raise OSError(ENOSPC)."""
        if len(data) > self.left:
            self.stream.write(bytes(data[: self.left]))
            self.stream.flush()
            self.left = 0
            raise OSError(errno.ENOSPC, "No space left on device")
        self.left -= len(data)
        return int(self.stream.write(data))

    def flush(self) -> None:
        """Flush the wrapped stream."""
        self.stream.flush()

    def close(self) -> None:
        """Close the wrapped stream."""
        self.stream.close()


def _kill_writer(out: Path) -> None:
    from capture.recording import RecordingWriter

    k = expected_intrinsics("color")
    with RecordingWriter(out, compression="zstd") as writer:
        for i in range(10_000):
            stamp = time.time_ns()
            writer.write_color(color_image(i), stamp_ns=stamp, intrinsics=k, log_ns=stamp)
            depth = np.resize(depth_image(i), (COLOR_H, COLOR_W))
            writer.write_depth(depth, stamp_ns=stamp, intrinsics=k, aligned=True, log_ns=stamp)
            print(f"wrote {i}", flush=True)
            time.sleep(0.1)


def _record_until_signal(out: Path) -> None:
    from capture.realsense.record import record
    from capture.realsense.session import RecordConfig
    from capture.realsense.sink import stop_on_signals

    cam = SoftCamera()
    started = threading.Event()
    cam.feed(list(range(100_000)), after=started)
    config = RecordConfig(width=COLOR_W, height=COLOR_H, depth_width=DEPTH_W, depth_height=DEPTH_H)

    def go() -> None:
        started.set()
        print("recording", flush=True)

    with stop_on_signals() as stop:
        threading.Timer(0.2, go).start()
        result = record(out, config, device=cam.device, stop=stop)
    print(f"{result.stop_reason} {result.frames_written['color']}", flush=True)


if __name__ == "__main__":
    mode, target = sys.argv[1], Path(sys.argv[2])
    {"kill-writer": _kill_writer, "record-until-signal": _record_until_signal}[mode](target)
