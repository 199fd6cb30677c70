"""Odometry and depth registration, side by side with Open3D's odometry and librealsense's align.

Reference odometry: Open3D's frame-to-frame RGB-D odometry (tensor `rgbd_odometry_multi_scale`,
hybrid, its default three-level schedule, full resolution), chained, on the same registered
depth. Both are timed per frame including the depth registration of the frame (640x480).
Recordings: a simulated handheld loop (`capture.sim`, seed 3, D435 noise) and the real frames of
../shared/data (ICL-NUIM living room, slambook2 room; 5 frames each, so mostly a sanity check;
TUM fr1_rpy, 694 frames of fast rotation, with ATE, RPE and frames/s: benchmarks.tum_odometry).
"""

from __future__ import annotations

import importlib.util
import json
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt
import open3d as o3d
from scipy.spatial.transform import Rotation

from benchmarks.common import Row
from benchmarks.tum_odometry import tum_rows
from capture.recording import Intrinsics, RecordingReader, RgbdFrame
from process.depth import DepthConfig, DepthProcessor, register_depth
from process.odometry.config import OdometryConfig
from process.odometry.odometry import Odometry
from process.trajectory import Trajectory, ate_rmse, path_length

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
TUM_RPY = "tum_fr1_rpy"  # the whole sequence: a Kinect v1 turned fast by hand (README there)
SIM_SEED = 3
SIM_FRAMES = 240
ATE_GOAL = "<= 0.5 % of path, >= 4x better"
FPS_GOAL = ">= 30 frames/s"


@dataclass
class Sequence:
    """Frames with depth already in the colour camera, their ground truth, and the depth time."""

    name: str
    frames: list[RgbdFrame]
    depth: list[npt.NDArray[np.float32]]
    gt: npt.NDArray[np.float64]  # (N, 4, 4)
    depth_s: float  # total seconds of depth processing

    @property
    def stamps(self) -> npt.NDArray[np.int64]:
        return np.array([f.stamp_ns for f in self.frames], np.int64)


def _ours(seq: Sequence) -> tuple[npt.NDArray[np.float64], float]:
    odometry = Odometry(OdometryConfig(), intrinsics=seq.frames[0].color_intrinsics)
    t0 = time.perf_counter()
    for frame, depth in zip(seq.frames, seq.depth, strict=True):
        odometry.track(frame, depth)
    trajectory = odometry.finish()
    seconds = time.perf_counter() - t0 + seq.depth_s
    return trajectory.poses, seconds


def _open3d(seq: Sequence) -> tuple[npt.NDArray[np.float64], float]:
    k = o3d.core.Tensor.from_numpy(seq.frames[0].color_intrinsics.matrix.copy())

    def image(frame: RgbdFrame, depth: npt.NDArray[np.float32]) -> o3d.t.geometry.RGBDImage:
        color = np.ascontiguousarray(frame.color.astype(np.float32) / 255.0)
        return o3d.t.geometry.RGBDImage(
            o3d.t.geometry.Image(o3d.core.Tensor.from_numpy(color)),
            o3d.t.geometry.Image(o3d.core.Tensor.from_numpy(depth)),
        )

    poses = [np.eye(4)]
    t0 = time.perf_counter()
    previous = image(seq.frames[0], seq.depth[0])
    for frame, depth in zip(seq.frames[1:], seq.depth[1:], strict=True):
        current = image(frame, depth)
        try:
            result = o3d.t.pipelines.odometry.rgbd_odometry_multi_scale(
                current, previous, k, o3d.core.Tensor.from_numpy(np.eye(4)), 1.0, 6.0
            )
            step = result.transformation.numpy()
        except RuntimeError:
            step = np.eye(4)  # too few correspondences: assume no motion
        poses.append(poses[-1] @ step)
        previous = current
    seconds = time.perf_counter() - t0 + seq.depth_s
    return np.array(poses), seconds


def _simulated() -> Sequence:
    from capture.sim import simulate_recording

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "sim.mcap"
        simulate_recording(path, seed=SIM_SEED, frames=SIM_FRAMES)
        processor = DepthProcessor(DepthConfig())
        frames, depth, gt, depth_s = [], [], [], 0.0
        with RecordingReader(path) as rec:
            for frame in rec.frames():
                t0 = time.perf_counter()
                depth.append(processor.process(frame))
                depth_s += time.perf_counter() - t0
                assert (
                    frame.ground_truth is not None
                    and frame.ground_truth.world_from_camera is not None
                )
                gt.append(frame.ground_truth.world_from_camera)
                frames.append(frame)
    return Sequence(
        f"sim seed {SIM_SEED}, {SIM_FRAMES} frames", frames, depth, np.array(gt), depth_s
    )


def _image_frames(
    colors: list[Path], depths: list[Path], intr: Intrinsics
) -> tuple[list[RgbdFrame], list[npt.NDArray[np.float32]]]:
    frames, depth = [], []
    for i, (c, d) in enumerate(zip(colors, depths, strict=True)):
        color = np.asarray(
            cv2.cvtColor(np.asarray(cv2.imread(str(c))), cv2.COLOR_BGR2RGB), np.uint8
        )
        dm = np.asarray(cv2.imread(str(d), cv2.IMREAD_UNCHANGED)).astype(np.float32) / 1000.0
        frames.append(RgbdFrame(i, 1_000_000_000 + i * 33_333_333, color, dm, intr, intr, True))
        depth.append(DepthProcessor(DepthConfig()).process(frames[-1]))
    return frames, depth


def _icl_nuim() -> Sequence:
    folder = DATA / "icl_nuim"
    k = json.loads((folder / "camera_primesense.json").read_text())["intrinsic_matrix"]
    intr = Intrinsics(640, 480, k[0], k[4], k[6], k[7])
    colors = sorted((folder / "color").glob("*.jpg"))
    frames, depth = _image_frames(colors, sorted((folder / "depth").glob("*.png")), intr)
    lines = (folder / "trajectory.log").read_text().split("\n")
    gt = np.array(
        [
            [[float(v) for v in lines[5 * i + 1 + r].split()] for r in range(4)]
            for i in range(len(frames))
        ]
    )
    return Sequence("ICL-NUIM, 5 frames", frames, depth, gt, 0.0)


def _slambook() -> Sequence:
    folder = DATA / "slambook2_rgbd"
    intr = Intrinsics(640, 480, 518.0, 519.0, 325.5, 253.5)
    colors = [folder / "color" / f"{i}.png" for i in range(1, 6)]
    frames, depth = _image_frames(
        colors, [folder / "depth" / f"{i}.pgm" for i in range(1, 6)], intr
    )
    rows = np.loadtxt(folder / "pose.txt")
    gt = np.tile(np.eye(4), (len(rows), 1, 1))
    gt[:, :3, :3] = Rotation.from_quat(rows[:, 3:]).as_matrix()
    gt[:, :3, 3] = rows[:, :3]
    return Sequence("slambook2 room, 5 frames (0.2-0.7 m apart)", frames, depth, gt, 0.0)


def _odometry_rows(seq: Sequence, *, with_fps: bool) -> list[Row]:
    length = path_length(seq.gt)
    ours, ours_s = _ours(seq)
    ref, ref_s = _open3d(seq)
    truth = Trajectory(seq.stamps, seq.gt)
    ate_ours = ate_rmse(Trajectory(seq.stamps, ours), truth)
    ate_ref = ate_rmse(Trajectory(seq.stamps, ref), truth)
    source = "Open3D frame-to-frame RGB-D odometry, same run"
    rows = [
        Row(
            "odometry",
            f"ATE / path, {seq.name}",
            "%",
            100 * ate_ours / length,
            100 * ate_ref / length,
            source,
            goal=ATE_GOAL,
        ),
        Row("odometry", f"ATE, {seq.name}", "mm", 1000 * ate_ours, 1000 * ate_ref, source),
    ]
    if with_fps:
        n = len(seq.frames)
        rows.append(
            Row(
                "odometry",
                f"depth + odometry, {seq.name}, 640x480",
                "frames/s",
                n / ours_s,
                n / ref_s,
                source,
                True,
                FPS_GOAL,
            )
        )
    return rows


def _rs_align_helper() -> Any:
    """Load tests/helpers_odometry.py (the rs.align software-device driver) by its path."""
    path = Path(__file__).resolve().parents[1] / "tests" / "helpers_odometry.py"
    spec = importlib.util.spec_from_file_location("helpers_odometry", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.rs_align


def _registration_rows() -> list[Row]:
    """Agreement with rs.align and time per frame, on a D435-like scene with an occluding box."""
    rs_align = _rs_align_helper()
    depth_k = Intrinsics(640, 480, 385.0, 385.0, 321.0, 239.0)
    color_k = Intrinsics(640, 480, 615.0, 615.0, 320.0, 240.0)
    color_from_depth = np.eye(4)
    color_from_depth[:3, :3] = Rotation.from_euler(
        "xyz", [0.05, -0.08, 0.03], degrees=True
    ).as_matrix()
    color_from_depth[:3, 3] = [0.015, 0.0001, 0.0003]
    rng = np.random.default_rng(7)
    depth_mm = (2000 + rng.integers(-30, 30, (480, 640))).astype(np.uint16)
    depth_mm[150:300, 200:350] = 600
    depth_mm[:, :40] = 0
    t0 = time.perf_counter()
    theirs = rs_align(depth_mm, depth_k=depth_k, color_k=color_k, color_from_depth=color_from_depth)
    rs_s = time.perf_counter() - t0
    theirs = theirs.astype(np.float32) / 1000.0
    kwargs: dict[str, Any] = {
        "depth_intrinsics": depth_k,
        "color_intrinsics": color_k,
        "color_from_depth": color_from_depth,
    }
    depth_m = depth_mm.astype(np.float32) / 1000.0
    ours = register_depth(depth_m, z_buffer="nearest", **kwargs)
    t0 = time.perf_counter()
    for _ in range(5):
        register_depth(depth_m, z_buffer="mean", **kwargs)
    ours_s = (time.perf_counter() - t0) / 5
    both = (ours > 0) & (theirs > 0)
    same = float(np.mean((ours > 0) == (theirs > 0)))
    within = float(np.mean(np.abs(ours[both] - theirs[both]) <= 0.001))
    src = "pyrealsense2 rs.align on the same software_device frames"
    return [
        Row(
            "depth",
            "pixels with the same validity as rs.align",
            "%",
            100 * same,
            100.0,
            src,
            True,
            "100 %",
        ),
        Row(
            "depth", "depth within 1 mm of rs.align", "%", 100 * within, 100.0, src, True, ">= 99 %"
        ),
        Row(
            "depth",
            "registration 640x480 (ours: mean z-buffer; rs: incl. device round trip)",
            "ms",
            1000 * ours_s,
            1000 * rs_s,
            src,
        ),
    ]


def run() -> list[Row]:
    """Measure odometry on the simulated loop and the real frames, and depth registration."""
    rows = _odometry_rows(_simulated(), with_fps=True)
    if DATA.is_dir():
        rows += _odometry_rows(_icl_nuim(), with_fps=False)
        rows += _odometry_rows(_slambook(), with_fps=False)
    if (DATA / TUM_RPY).is_dir():
        rows += tum_rows(DATA / TUM_RPY)
    else:
        print(f"bench_odometry: no {DATA / TUM_RPY}: TUM fr1_rpy rows skipped", file=sys.stderr)
    if importlib.util.find_spec("pyrealsense2") is not None:
        rows += _registration_rows()
    return rows
