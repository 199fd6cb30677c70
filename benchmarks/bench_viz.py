"""What Rerun logging costs a replay: .rrd KB per frame and ms per frame, compact and full fidelity.

The frames are logged straight through `RerunLogger` as the pipeline calls it, not through the
whole pipeline (which would take minutes per recording on 2 cores): colour, depth (and registered
depth when the recording's depth is not aligned), pose, 500 keypoints, tracking, three timings,
and on keyframes a label image and its confidence.
- real: TUM RGB-D fr1_rpy (640x480 Kinect, depth already registered), N_FRAMES frames spread
  over the whole sequence, read from ../shared/data; every KEYFRAME_EVERY-th frame a keyframe
  (our odometry made 167 keyframes of 694 frames on it, 24 %). Labels: depth bands standing in
  for the network's (blobby regions like its output), confidence a smooth field.
- simulated: the simulated D435 (seed 1, 640x480, depth in the depth camera, registered here),
  with its ground-truth labels.
Each is logged by default ([viz] compress = true, depth_every_n = 30) and at full fidelity
(compress = false, depth_every_n = 1); full fidelity is also compared with plain Rerun logging
(raw rr.Image, float32 rr.DepthImage).
The whole `process run` on TUM fr1_rpy (694 frames, 167 keyframes, ~800 real keypoints a frame,
the network's confidence, maps and plots) wrote 98.5 KB a frame by default (319 KB before).
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt
import rerun as rr

from benchmarks.common import Row
from capture.recording import Intrinsics, RecordingReader, RgbdFrame
from viz import layout
from viz.rerun_log import RerunLogger

SHARED = Path(__file__).resolve().parents[2] / "shared/data"
TUM = SHARED / "tum_fr1_rpy"
TUM_K = Intrinsics(640, 480, 517.3, 516.5, 318.6, 255.3)
N_FRAMES = 90
KEYFRAME_EVERY = 4
N_KEYPOINTS = 500
DEFAULT: dict[str, Any] = {"compress": True, "jpeg_quality": 70, "depth_every_n": 30}
FULL: dict[str, Any] = {"compress": False, "depth_every_n": 1}
GOAL_KB = 100.0

Frame = tuple[RgbdFrame, npt.NDArray[np.float32] | None, npt.NDArray[np.uint8]]


def _tum_frames() -> Iterator[Frame]:
    """Yield N_FRAMES TUM fr1_rpy frames spread over the sequence, with stand-in labels."""
    colours = sorted((TUM / "rgb").iterdir())
    depths = sorted((TUM / "depth").iterdir())
    n = min(len(colours), len(depths))
    for i, j in enumerate(np.linspace(0, n - 1, N_FRAMES).astype(int)):
        colour = np.asarray(cv2.imread(str(colours[j])), np.uint8)[..., ::-1].copy()
        depth = np.asarray(cv2.imread(str(depths[j]), cv2.IMREAD_UNCHANGED), np.float32) / 5e3
        depth = depth.astype(np.float32)
        labels = np.clip(depth * 2.0, 0, 10).astype(np.uint8)  # half-metre bands
        yield RgbdFrame(i, i * 33_333_333, colour, depth, TUM_K, TUM_K, aligned=True), None, labels


def _sim_frames(folder: Path) -> Iterator[Frame]:
    """Yield N_FRAMES simulated frames with depth registered to colour and ground-truth labels."""
    from capture.sim import simulate_recording
    from process.depth import DepthConfig, DepthProcessor

    path = folder / "sim.mcap"
    simulate_recording(path, seed=1, frames=N_FRAMES, fps=30.0, width=640, height=480)
    depth = DepthProcessor(DepthConfig())
    with RecordingReader(path) as rec:
        for frame in rec.frames():
            truth = frame.ground_truth
            labels = truth.labels if truth is not None and truth.labels is not None else None
            registered = depth.process(frame)
            yield (
                frame,
                registered,
                np.zeros(registered.shape, np.uint8) if labels is None else labels,
            )


def _log(rrd: Path, frames: list[Frame], options: dict[str, Any]) -> float:
    """Log the frames through RerunLogger with options; return seconds per frame."""
    rng = np.random.default_rng(0)
    xy = rng.uniform(0, 600, (N_KEYPOINTS, 2))
    inliers = np.arange(N_KEYPOINTS) % 4 != 0
    with RerunLogger(rrd, recording_name="bench", **options) as log:
        t0 = time.perf_counter()
        for i, (frame, registered, labels) in enumerate(frames):
            keyframe = i % KEYFRAME_EVERY == 0
            log.set_frame(i, stamp_ns=i * 33_333_333)
            log.log_frame(frame, keyframe=keyframe)
            if registered is not None:
                log.log_registered_depth(registered, keyframe=keyframe)
            pose = np.eye(4)
            pose[:3, 3] = [0.01 * i, 0.0, 0.0]
            log.log_pose(pose, keyframe=keyframe)
            log.log_keypoints(xy + i % 7, inliers=inliers)
            log.log_tracking(int(inliers.sum()), status="ok")
            if keyframe:
                h, w = labels.shape
                confidence = np.repeat(np.linspace(0.3, 1.0, h)[:, None], w, axis=1)
                log.log_segmentation(labels, confidence=confidence)
            for stage in ("depth", "odometry", "segmentation"):
                log.log_timing(stage, 0.01)
    return (time.perf_counter() - t0) / len(frames)  # close() flushed


def _plain(rrd: Path, frames: list[Frame]) -> None:
    """Log the images the plain Rerun way: raw rr.Image and float32 rr.DepthImage every frame."""
    rec = rr.RecordingStream("bench-plain", recording_id="plain")
    rec.save(rrd)
    for i, (frame, registered, _) in enumerate(frames):
        rec.set_time("frame", sequence=i)
        rec.log(layout.RGB, rr.Image(frame.color))
        rec.log(layout.DEPTH, rr.DepthImage(frame.depth_m, meter=1.0))
        if registered is not None:
            rec.log(layout.DEPTH_REGISTERED, rr.DepthImage(registered, meter=1.0))
    rec.flush()
    rec.disconnect()


def _rows(name: str, frames: list[Frame], folder: Path) -> list[Row]:
    """Measure one recording's frames default, full fidelity and plain."""
    kb: dict[str, float] = {}
    ms: dict[str, float] = {}
    for fidelity, options in (("default", DEFAULT), ("full", FULL)):
        rrd = folder / f"{name}_{fidelity}.rrd"
        ms[fidelity] = _log(rrd, frames, options) * 1e3
        kb[fidelity] = rrd.stat().st_size / 1000 / len(frames)
    _plain(folder / f"{name}_plain.rrd", frames)
    kb["plain"] = (folder / f"{name}_plain.rrd").stat().st_size / 1000 / len(frames)
    size = f".rrd per frame, {name}"
    goal = f"<= {GOAL_KB:g} KB" if name.startswith("real") else ""
    full = "full fidelity (viz.compress = false, viz.depth_every_n = 1), same frames"
    return [
        Row("viz", f"{size}, default", "KB", kb["default"], kb["full"], full, goal=goal),
        Row("viz", f"{size}, full fidelity", "KB", kb["full"], kb["plain"], "plain rr.Image"),
        Row(
            "viz",
            f"logging time per frame, {name}, default",
            "ms",
            ms["default"],
            ms["full"],
            full,
            goal="small beside the 33 ms of a 30 fps frame",
        ),
    ]


def run() -> list[Row]:
    """Measure .rrd KB per frame and logging ms per frame on real and simulated frames."""
    rows: list[Row] = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        if TUM.is_dir():
            rows += _rows("real TUM fr1_rpy 640x480", list(_tum_frames()), folder)
        else:
            print(f"bench_viz: {TUM} not found: no real-recording rows")
        rows += _rows("simulated D435 640x480", list(_sim_frames(folder)), folder)
    return rows
