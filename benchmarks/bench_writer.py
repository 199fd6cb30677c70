"""Recording writer throughput on one core: ours beside the mcap library's Writer, same run.

Frames are the real ICL-NUIM frames of ../shared/data (5 colour, 5 depth, cycled; resized to the
mode's resolution), so compression sees real image statistics; a procedural scene stands in where
the data is absent. Two D435 modes: 640x480 colour + depth at 30 fps (46 MB/s of images), and
1280x720 colour at 30 fps + 848x480 depth at 90 fps (156 MB/s). For each, zstd and lz4:
- throughput of the writer alone on one pinned core, in colour frames per CPU second (with their
  depth and camera_info; CPU time, so that other processes on a shared machine do not count),
  beside the mcap library's `Writer` (zstd level 3, lz4 default) writing
  the same serialised messages with the same 1 s chunks, as this project's writer did at first;
- a 3 s real-time replay at the camera's rate through the bounded queue and writer thread (the
  `record` path), counting frames written against frames offered: drops.
"""

from __future__ import annotations

import os
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt
from mcap.well_known import SchemaEncoding
from mcap.writer import CompressionType
from mcap.writer import Writer as LibraryWriter
from mcap_ros2._dynamic import serialize_dynamic

from benchmarks.common import Row
from capture.realsense.sink import StreamFrame, ThreadedWriter
from capture.recording import Intrinsics
from capture.recording import messages as m
from capture.recording.writer import RecordingWriter, camera_info

ICL = Path(__file__).resolve().parents[2] / "shared" / "data" / "icl_nuim"
AREA = "capture"


@dataclass(frozen=True, slots=True)
class Mode:
    """A D435 stream configuration."""

    name: str
    color: tuple[int, int]  # width, height
    depth: tuple[int, int]
    depth_per_color: int  # depth frames per colour frame (90 / 30)
    fps: int = 30

    @property
    def mb_per_s(self) -> float:
        """Return the raw image bytes per second the camera produces, in MB."""
        (cw, ch), (dw, dh) = self.color, self.depth
        return (cw * ch * 3 + self.depth_per_color * dw * dh * 2) * self.fps / 1e6


MODES = (
    Mode("640x480@30", (640, 480), (640, 480), 1),
    Mode("1280x720@30+848x480@90", (1280, 720), (848, 480), 3),
)
Images = tuple[list[npt.NDArray[np.uint8]], list[npt.NDArray[np.uint16]]]


def _images(mode: Mode) -> tuple[Images, str]:
    """Return 5 colour and 5 depth images at the mode's sizes, and where they came from."""
    if (ICL / "color" / "00000.jpg").is_file():
        bgr = [cv2.imread(str(ICL / "color" / f"{i:05d}.jpg")) for i in range(5)]
        mm = [
            cv2.imread(str(ICL / "depth" / f"{i:05d}.png"), cv2.IMREAD_UNCHANGED) for i in range(5)
        ]
        source = "ICL-NUIM frames"
    else:
        y, x = np.mgrid[0:480, 0:640]
        bgr = [np.stack([(x + 9 * i) % 256, y % 256, (x * y // 64) % 256], -1) for i in range(5)]
        mm = [(1000 + x + 5 * i).astype(np.uint16) for i in range(5)]
        source = "procedural frames"
    colors: list[npt.NDArray[np.uint8]] = [
        np.ascontiguousarray(cv2.resize(np.asarray(c, np.uint8), mode.color)[..., ::-1])
        for c in bgr
    ]
    nearest = cv2.INTER_NEAREST
    depths: list[npt.NDArray[np.uint16]] = [
        np.asarray(
            cv2.resize(np.asarray(d, np.uint16), mode.depth, interpolation=nearest), np.uint16
        )
        for d in mm
    ]
    return (colors, depths), source


def _intrinsics(size: tuple[int, int]) -> Intrinsics:
    w, h = size
    return Intrinsics(w, h, 0.9 * w, 0.9 * w, w / 2, h / 2)


@contextmanager
def _one_core() -> Iterator[None]:
    """Pin this process to one CPU while the block runs."""
    before = os.sched_getaffinity(0)
    os.sched_setaffinity(0, {max(before)})
    try:
        yield
    finally:
        os.sched_setaffinity(0, before)


def _ours(path: Path, mode: Mode, images: Images, compression: str, frames: int) -> float:
    """Write `frames` colour frames (and their depth) with RecordingWriter; return CPU seconds."""
    colors, depths = images
    kc, kd = _intrinsics(mode.color), _intrinsics(mode.depth)
    dt_ns = 1_000_000_000 // (mode.fps * mode.depth_per_color)
    t0 = time.process_time()
    with RecordingWriter(path, compression=compression) as w:
        for i in range(frames):
            stamp = (i * mode.depth_per_color) * dt_ns
            w.write_color(colors[i % 5], stamp_ns=stamp, intrinsics=kc)
            for j in range(mode.depth_per_color):
                d = depths[(i * mode.depth_per_color + j) % 5]
                w.write_depth(d, stamp_ns=stamp + j * dt_ns, intrinsics=kd)
    return time.process_time() - t0


def _library(path: Path, mode: Mode, images: Images, compression: str, frames: int) -> float:
    """Write the same messages with mcap.writer.Writer, a chunk per second; return CPU seconds."""
    colors, depths = images
    kc, kd = _intrinsics(mode.color), _intrinsics(mode.depth)
    dt_ns = 1_000_000_000 // (mode.fps * mode.depth_per_color)
    kind = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4}[compression]
    t0 = time.process_time()
    with path.open("wb") as f:
        w = LibraryWriter(f, chunk_size=64 << 20, compression=kind)
        w.start(profile="ros2", library="reference")
        enc, chans = {}, {}
        for name in (m.IMAGE, m.CAMERA_INFO):
            sid = w.register_schema(name, SchemaEncoding.ROS2, m.MSG_DEFS[name].encode())
            enc[name] = serialize_dynamic(name, m.MSG_DEFS[name])[name]
            for topic in ("c", "d"):
                chans[topic, name] = w.register_channel(f"/{topic}/{name}", "cdr", sid)

        def put(topic: str, img: npt.NDArray[np.generic], k: Intrinsics, stamp: int) -> None:
            h, wd = img.shape[:2]
            encoding, step = ("rgb8", 3 * wd) if img.ndim == 3 else ("16UC1", 2 * wd)
            msg = m.image(stamp, "f", width=wd, height=h, encoding=encoding, step=step,
                          data=img.tobytes())  # fmt: skip
            w.add_message(chans[topic, m.IMAGE], stamp, enc[m.IMAGE](msg), stamp)
            info = enc[m.CAMERA_INFO](camera_info(stamp, "f", k))
            w.add_message(chans[topic, m.CAMERA_INFO], stamp, info, stamp)

        for i in range(frames):
            stamp = (i * mode.depth_per_color) * dt_ns
            put("c", colors[i % 5], kc, stamp)
            for j in range(mode.depth_per_color):
                put("d", depths[(i * mode.depth_per_color + j) % 5], kd, stamp + j * dt_ns)
            if (i + 1) % mode.fps == 0:
                w.flush()  # type: ignore[no-untyped-call]  # a chunk per second, as RECORDING.md asks
        w.finish()  # type: ignore[no-untyped-call]
    return time.process_time() - t0


def _real_time(
    path: Path, mode: Mode, images: Images, compression: str, seconds: float
) -> tuple[int, int]:
    """Offer frames at the camera's rate to the record path; return (written, offered)."""
    colors, depths = images
    k = _intrinsics(mode.color)
    writer = RecordingWriter(path, compression=compression)
    sink = ThreadedWriter(writer, color_intrinsics=k, depth_intrinsics=_intrinsics(mode.depth))
    sink.start()
    period = 1.0 / (mode.fps * mode.depth_per_color)
    ticks = int(seconds / period)
    t0 = time.perf_counter()
    for n in range(ticks):
        time.sleep(max(0.0, t0 + n * period - time.perf_counter()))
        now = time.time_ns()
        if n % mode.depth_per_color == 0:
            i = n // mode.depth_per_color
            sink.submit(StreamFrame("color", i, now, now, colors[i % 5]))
        sink.submit(StreamFrame("depth", n, now, now, depths[n % 5]))
    stats = sink.stop()
    writer.finish(sink.summary(stats))
    offered = ticks + (ticks + mode.depth_per_color - 1) // mode.depth_per_color
    return sum(stats.written.values()), offered


def _rows_for(mode: Mode, tmp: Path) -> list[Row]:
    images, source = _images(mode)
    frames = 90 if mode.depth_per_color == 1 else 45
    rows = []
    for compression in ("zstd", "lz4"):
        ours = min(_ours(tmp / "o.mcap", mode, images, compression, frames) for _ in range(2))
        size_ours = (tmp / "o.mcap").stat().st_size
        ref = min(_library(tmp / "r.mcap", mode, images, compression, frames) for _ in range(2))
        size_ref = (tmp / "r.mcap").stat().st_size
        label = f"{mode.name} {compression}"
        level = "zstd level 3" if compression == "zstd" else "lz4"
        ref_name = f"mcap.writer.Writer ({level}), same messages, {source}"
        rows.append(Row(AREA, f"{label}: writer alone on one core", "frames/s", frames / ours,
                        frames / ref, ref_name, higher_is_better=True,
                        goal=f">= {3 * mode.fps} (3x camera)" if mode.depth_per_color == 1
                        else f">= {mode.fps} (camera)"))  # fmt: skip
        rows.append(Row(AREA, f"{label}: image data written on one core", "MB/s",
                        mode.mb_per_s * (frames / ours) / mode.fps,
                        mode.mb_per_s * (frames / ref) / mode.fps, ref_name,
                        higher_is_better=True, goal=f">= {mode.mb_per_s:.0f}"))  # fmt: skip
        rows.append(Row(AREA, f"{label}: file size", "MB", size_ours / 1e6, size_ref / 1e6,
                        ref_name))  # fmt: skip
    return rows


def run() -> list[Row]:
    """Measure both modes with zstd and lz4; then drops of the 156 MB/s mode in real time."""
    rows: list[Row] = []
    with tempfile.TemporaryDirectory() as d, _one_core():
        tmp = Path(d)
        for mode in MODES:
            rows += _rows_for(mode, tmp)
        fast = MODES[1]
        images, _ = _images(fast)
        for compression in ("zstd", "lz4"):
            written, offered = _real_time(tmp / "rt.mcap", fast, images, compression, 3.0)
            rows.append(Row(AREA, f"{fast.name} {compression}: frames written in 3 s real time "
                            f"(one core, queue + writer thread)", "frames", written, offered,
                            "frames offered at the camera's rate, same run", higher_is_better=True,
                            goal="all (0 dropped)"))  # fmt: skip
    return rows
