"""What Rerun logging costs a replay: time and .rrd bytes per frame, ours beside plain logging.

Frames are the real ICL-NUIM frames of ../shared/data (a procedural image where that is absent),
logged 60 times each way in the same run:
- ours: `RerunLogger` as the pipeline calls it (JPEG colour, raw and registered depth in mm, pose,
  500 keypoints with matches, tracking, three timings);
- reference: the same objects logged the plain way (raw RGB `rr.Image`, float32 `rr.DepthImage`).
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import numpy.typing as npt
import rerun as rr

from benchmarks.common import Row
from capture.recording import Intrinsics, RecordingReader, RgbdFrame
from viz import layout
from viz.rerun_log import RerunLogger

SHARED_MCAP = Path(__file__).resolve().parents[2] / "shared/data/icl_nuim/icl_nuim_5frames.mcap"
N_FRAMES = 60
N_KEYPOINTS = 500


def _frames() -> tuple[list[RgbdFrame], str]:
    """Return a few real frames, or procedural ones when the shared data is absent."""
    if SHARED_MCAP.is_file():
        with RecordingReader(SHARED_MCAP) as rec:
            return list(rec.frames()), "ICL-NUIM"
    y, x = np.mgrid[0:480, 0:640]
    color = np.stack([x % 256, y % 256, (x * y) % 256], axis=-1).astype(np.uint8)
    depth = (1.0 + x / 640.0).astype(np.float32)
    k = Intrinsics(640, 480, 525.0, 525.0, 319.5, 239.5)
    return [RgbdFrame(0, 0, color, depth, k, k, aligned=True)], "procedural"


def _ours(rrd: Path, frames: list[RgbdFrame], xy: npt.NDArray[np.float64]) -> float:
    """Log N_FRAMES frames through RerunLogger; return seconds per frame."""
    inliers = np.arange(N_KEYPOINTS) % 4 != 0
    with RerunLogger(rrd, recording_name="bench") as log:
        t0 = time.perf_counter()
        for i in range(N_FRAMES):
            frame = frames[i % len(frames)]
            log.set_frame(i, stamp_ns=i * 33_333_333)
            log.log_frame(frame)
            log.log_registered_depth(frame.depth_m)
            log.log_pose(np.eye(4), keyframe=i % 10 == 0)
            log.log_keypoints(xy, inliers=inliers, matched_xy=xy + 1.0)
            log.log_tracking(int(inliers.sum()), status="ok")
            for stage in ("depth", "odometry", "segmentation"):
                log.log_timing(stage, 0.01)
    return (time.perf_counter() - t0) / N_FRAMES  # close() flushed, as plain's flush()


def _plain(rrd: Path, frames: list[RgbdFrame], xy: npt.NDArray[np.float64]) -> float:
    """Log the same objects the plain Rerun way; return seconds per frame."""
    rec = rr.RecordingStream("bench-plain", recording_id="plain")
    rec.save(rrd)
    t0 = time.perf_counter()
    for i in range(N_FRAMES):
        frame = frames[i % len(frames)]
        rec.set_time("frame", sequence=i)
        rec.log(layout.RGB, rr.Image(frame.color))
        rec.log(layout.DEPTH, rr.DepthImage(frame.depth_m, meter=1.0))
        rec.log(layout.DEPTH_REGISTERED, rr.DepthImage(frame.depth_m, meter=1.0))
        rec.log(layout.CAMERA, rr.Transform3D(translation=[0, 0, 0], mat3x3=np.eye(3)))
        rec.log(layout.KEYPOINTS, rr.Points2D(xy))
        rec.log(layout.MATCHES, rr.LineStrips2D(np.stack([xy, xy + 1.0], axis=1)))
        rec.log(layout.PLOT_INLIERS, rr.Scalars(375.0))
        for stage in ("depth", "odometry", "segmentation"):
            rec.log(layout.timing_path(stage), rr.Scalars(0.01))
    rec.flush()
    seconds = (time.perf_counter() - t0) / N_FRAMES
    rec.disconnect()
    return seconds


def _best(fn: Callable[[Path], float], folder: Path, name: str) -> tuple[float, float]:
    """Return (best seconds per frame of 2 runs, .rrd bytes per frame)."""
    runs = [fn(folder / f"{name}{i}.rrd") for i in range(2)]
    return min(runs), (folder / f"{name}0.rrd").stat().st_size / N_FRAMES


def run() -> list[Row]:
    """Measure per-frame logging time and .rrd size, ours and plain."""
    frames, source = _frames()
    xy = np.random.default_rng(0).uniform(0, 600, (N_KEYPOINTS, 2))
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        ours_s, ours_b = _best(lambda p: _ours(p, frames, xy), folder, "ours")
        plain_s, plain_b = _best(lambda p: _plain(p, frames, xy), folder, "plain")
    ref = f"plain rr.Image + float32 rr.DepthImage, same run, {source} 640x480"
    return [
        Row(
            "viz",
            "logging time per frame",
            "ms",
            ours_s * 1e3,
            plain_s * 1e3,
            ref,
            goal="small beside the 33 ms of a 30 fps frame",
        ),
        Row("viz", ".rrd size per frame", "KiB", ours_b / 1024, plain_b / 1024, ref),
    ]
