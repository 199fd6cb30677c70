"""Odometry alone on a TUM RGB-D folder: ATE, RPE, frames/s (wall and CPU), and a profile.

Frames are read straight from the dataset folder as the importer would write them (colour RGB,
depth rounded to millimetres), so no recording is needed; reading is not timed, depth processing
(DepthProcessor) and Odometry.track are. Run it as a script:

    python -m benchmarks.tum_odometry ../shared/data/tum_fr1_rpy [--count N] [--profile]
"""

from __future__ import annotations

import argparse
import ast
import cProfile
import pstats
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt
import open3d as o3d

from benchmarks.common import Row
from capture.importers import _read_color, _read_depth_mm
from capture.importers.tum import TUM_COLOR_READOUT_S, _load_tum
from capture.recording import GroundTruth, RgbdFrame
from process.depth import DepthConfig, DepthProcessor
from process.odometry.config import OdometryConfig
from process.odometry.odometry import Odometry
from process.trajectory import Trajectory, ate_rmse, rpe

FPS_GOAL = ">= 30 frames/s"


@dataclass
class Run:
    """One odometry run over a slice of a TUM sequence."""

    stamps: npt.NDArray[np.int64]
    poses: npt.NDArray[np.float64]  # (N, 4, 4) after finish()
    gt_stamps: npt.NDArray[np.int64]  # the frames that have ground truth
    gt: npt.NDArray[np.float64]  # (M, 4, 4)
    statuses: list[str]
    wall_s: float  # depth processing + tracking + finish
    cpu_s: float  # the same, process CPU time (user + system, all threads)
    keyframes: int
    events: list[str] = field(default_factory=list)
    inliers: list[int] = field(default_factory=list)
    is_keyframe: list[bool] = field(default_factory=list)

    @property
    def ate_m(self) -> float:
        """Return the ATE RMSE in metres."""
        return ate_rmse(Trajectory(self.stamps, self.poses), Trajectory(self.gt_stamps, self.gt))

    @property
    def rpe(self) -> tuple[float, float]:
        """Return the frame-to-frame RPE RMSE (metres, degrees)."""
        return rpe(Trajectory(self.stamps, self.poses), Trajectory(self.gt_stamps, self.gt))


def tum_frames(folder: Path, *, start: int = 0, count: int | None = None) -> Iterator[RgbdFrame]:
    """Yield the associated frames of a TUM folder with ground truth, as the importer reads them."""
    dataset = _load_tum(folder)
    chosen = dataset.frames[start : None if count is None else start + count]
    k = dataset.intrinsics
    for i, f in enumerate(chosen):
        depth_m = _read_depth_mm(f.depth, dataset).astype(np.float32) / 1000.0
        gt = None if f.world_from_camera is None else GroundTruth(f.world_from_camera)
        yield RgbdFrame(
            start + i, f.stamp_ns, _read_color(f.color, k), depth_m, k, k, True, None, gt
        )


def run_odometry(frames: Iterator[RgbdFrame], cfg: OdometryConfig | None = None) -> Run:
    """Track every frame (with its depth processing) and return the trajectory and timings."""
    processor = DepthProcessor(DepthConfig())
    odometry: Odometry | None = None
    stamps, gt_stamps, gt, statuses, events = [], [], [], [], []
    inliers: list[int] = []
    is_kf: list[bool] = []
    wall = 0.0
    cpu = time.process_time()  # once: it is slow to read with many threads
    for frame in frames:
        t0 = time.perf_counter()
        if odometry is None:
            odometry = Odometry(
                cfg or OdometryConfig(),
                intrinsics=frame.color_intrinsics,
                recording_readout_s=TUM_COLOR_READOUT_S,  # as the importer records it
            )
        result = odometry.track(frame, processor.process(frame))
        wall += time.perf_counter() - t0
        stamps.append(frame.stamp_ns)
        if frame.ground_truth is not None and frame.ground_truth.world_from_camera is not None:
            gt_stamps.append(frame.stamp_ns)
            gt.append(frame.ground_truth.world_from_camera)
        statuses.append(result.state.status)
        inliers.append(result.state.n_inliers)
        is_kf.append(result.is_keyframe)
        if result.state.event:
            events.append(f"{frame.index}: {result.state.event}")
    assert odometry is not None, "no frames"
    t0 = time.perf_counter()
    poses = odometry.finish().poses
    wall += time.perf_counter() - t0
    cpu = time.process_time() - cpu  # includes the bookkeeping here, a few percent
    return Run(
        np.array(stamps, np.int64),
        poses,
        np.array(gt_stamps, np.int64),
        np.array(gt),
        statuses,
        wall,
        cpu,
        odometry.n_keyframes,
        events,
        inliers,
        is_kf,
    )


def open3d_odometry(frames: Iterator[RgbdFrame]) -> Run:
    """Chain Open3D's frame-to-frame RGB-D odometry (tensor, hybrid, default schedule) instead.

    The same depth processing is timed; a failed step is taken as no motion, as in
    benchmarks.bench_odometry.
    """
    processor = DepthProcessor(DepthConfig())
    poses, stamps, gt_stamps, gt = [np.eye(4)], [], [], []
    previous: o3d.t.geometry.RGBDImage | None = None
    wall, cpu = 0.0, time.process_time()
    for frame in frames:
        t0 = time.perf_counter()
        color = np.ascontiguousarray(frame.color.astype(np.float32) / 255.0)
        current = o3d.t.geometry.RGBDImage(
            o3d.t.geometry.Image(o3d.core.Tensor.from_numpy(color)),
            o3d.t.geometry.Image(o3d.core.Tensor.from_numpy(processor.process(frame))),
        )
        if previous is not None:
            k = o3d.core.Tensor.from_numpy(frame.color_intrinsics.matrix.copy())
            try:
                step = o3d.t.pipelines.odometry.rgbd_odometry_multi_scale(
                    current, previous, k, o3d.core.Tensor.from_numpy(np.eye(4)), 1.0, 6.0
                ).transformation.numpy()
            except RuntimeError:
                step = np.eye(4)
            poses.append(poses[-1] @ step)
        previous = current
        wall += time.perf_counter() - t0
        stamps.append(frame.stamp_ns)
        if frame.ground_truth is not None and frame.ground_truth.world_from_camera is not None:
            gt_stamps.append(frame.stamp_ns)
            gt.append(frame.ground_truth.world_from_camera)
    cpu = time.process_time() - cpu
    n = len(stamps)
    return Run(
        np.array(stamps, np.int64),
        np.array(poses),
        np.array(gt_stamps, np.int64),
        np.array(gt),
        ["ok"] * n,
        wall,
        cpu,
        0,
    )


def tum_rows(folder: Path) -> list[Row]:
    """Rows for `make bench`: ours beside Open3D's odometry on a whole TUM sequence."""
    name = f"TUM {folder.name}"
    ours, ref = run_odometry(tum_frames(folder)), open3d_odometry(tum_frames(folder))
    (ours_m, ours_deg), (ref_m, ref_deg) = ours.rpe, ref.rpe
    n = len(ours.stamps)
    src = "Open3D frame-to-frame RGB-D odometry, same frames and depth, same run"
    return [
        Row("odometry", f"ATE, {name}", "cm", 100 * ours.ate_m, 100 * ref.ate_m, src, goal="<= 2"),
        Row("odometry", f"RPE per frame, {name}", "mm", 1000 * ours_m, 1000 * ref_m, src),
        Row("odometry", f"RPE per frame, {name}", "deg", ours_deg, ref_deg, src),
        Row(
            "odometry",
            f"depth + odometry, {name} (wall, machine shared)",
            "frames/s",
            n / ours.wall_s,
            n / ref.wall_s,
            src,
            True,
            FPS_GOAL,
        ),
        Row(
            "odometry",
            f"depth + odometry, {name} (per CPU second, all threads)",
            "frames/s",
            n / ours.cpu_s,
            n / ref.cpu_s,
            src,
            True,
            FPS_GOAL,
        ),
    ]


def main() -> None:
    """Print ATE, RPE, frames/s and optionally a cProfile of one run."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path)
    parser.add_argument("--start", type=int, default=0)
    parser.add_argument("--count", type=int, default=None)
    parser.add_argument("--profile", action="store_true")
    parser.add_argument("--events", action="store_true")
    parser.add_argument("--set", nargs="*", default=[], help="OdometryConfig overrides, k=v")
    parser.add_argument("--save", type=Path, help="write stamps, poses and ground truth (.npz)")
    args = parser.parse_args()
    frames = list(tum_frames(args.folder, start=args.start, count=args.count))
    profiler = cProfile.Profile() if args.profile else None
    if profiler:
        profiler.enable()
    overrides = {k: ast.literal_eval(v) for k, v in (o.split("=", 1) for o in args.set)}
    run = run_odometry(iter(frames), OdometryConfig(**overrides))
    if profiler:
        profiler.disable()
    n = len(run.stamps)
    rpe_m, rpe_deg = run.rpe
    lost = sum(s == "lost" for s in run.statuses)
    print(
        f"{n} frames, {run.keyframes} keyframes, {lost} lost: ATE {100 * run.ate_m:.2f} cm,"
        f" RPE {1000 * rpe_m:.1f} mm / {rpe_deg:.2f} deg per frame;"
        f" {n / run.wall_s:.1f} frames/s wall, {n / run.cpu_s:.1f} frames/s CPU"
    )
    if args.save:
        np.savez(
            args.save,
            inliers=np.array(run.inliers),
            is_keyframe=np.array(run.is_keyframe),
            stamps=run.stamps,
            poses=run.poses,
            gt_stamps=run.gt_stamps,
            gt=run.gt,
        )
    if args.events:
        print("\n".join(run.events))
    if profiler:
        pstats.Stats(profiler).sort_stats("cumulative").print_stats(35)


if __name__ == "__main__":
    main()
