"""ReplayPipeline: a recording through odometry, segmentation, fusion and refinement, streamed."""

from __future__ import annotations

import logging
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from tqdm import tqdm

from capture.recording import (
    GT_CLOUD_ATTACHMENT,
    LABEL_NAMES,
    RecordingReader,
    RgbdFrame,
)
from process import outputs
from process.config import ReplayConfig, to_toml
from process.depth import DepthProcessor
from process.evaluate import class_counts, confusion_matrix, ratios
from process.odometry.odometry import Odometry
from process.trajectory import ate_rmse, path_length, rpe, write_tum
from viz.layout import STAGE_FUSED
from viz.logger import Logger

logger = logging.getLogger(__name__)


@dataclass
class RunResult:
    """What a run produced: the files written and the metrics."""

    out_dir: Path
    written: list[Path] = field(default_factory=list)
    metrics: dict[str, Any] = field(default_factory=dict)


class ReplayPipeline:
    """Replay one recording through the configured stages, logging every step."""

    def __init__(
        self,
        recording: Path,
        *,
        out_dir: Path,
        cfg: ReplayConfig,
        stages: tuple[str, ...],
        viz: Logger,
        weights: Path | None = None,
        device: str = "auto",
        progress: bool = True,
    ) -> None:
        self.recording = recording
        self.out_dir = out_dir
        self.cfg = cfg
        self.stages = stages
        self.viz = viz
        self.weights = weights
        self.device = device
        self.progress = progress
        self.result = RunResult(out_dir)
        self._seconds: dict[str, float] = {}
        self._anchor: npt.NDArray[np.float64] | None = None  # map world from the first camera
        self._keyframe_stamps: set[int] = set()
        self._segmenter: Any = None

    def run(self) -> RunResult:
        """Run the stages and write the outputs; return what was written and measured."""
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self._write_config()
        with RecordingReader(self.recording) as rec:
            if not rec.has_ground_truth:
                self.viz.log_text(
                    "recording has no ground truth: metrics against it are skipped", level="INFO"
                )
                logger.info("no ground truth in %s: metrics against it are skipped", self.recording)
            trajectory, gt_poses = self._replay_frames(rec)
            self._finish_odometry(trajectory, gt_poses)
            if "fusion" in self.stages:
                cloud = self._fuse(rec, trajectory)
            gt_cloud = rec.attachment(GT_CLOUD_ATTACHMENT)
        if "fusion" in self.stages:
            self._write_cloud(outputs.MAP_FUSED, cloud)
            self.viz.set_stage(STAGE_FUSED)
            self.viz.log_map("fused", cloud.points, colors=cloud.colors, labels=cloud.labels)
            if "refinement" in self.stages and len(cloud) == 0:
                note = (
                    "the fused map is empty: no keyframe pixel had depth within fusion's"
                    f" {self.cfg.fusion.min_depth_m:g}..{self.cfg.fusion.max_depth_m:g} m;"
                    " refinement is skipped (check [fusion] and the recording's depth)"
                )
                self.viz.log_text(note, level="WARN")
                logger.warning(note)
            elif "refinement" in self.stages:
                self._refine(cloud, gt_cloud)
        self.result.metrics["seconds"] = {k: round(v, 3) for k, v in self._seconds.items()}
        path = self.out_dir / outputs.METRICS
        outputs.write_metrics(path, self.result.metrics)
        self.result.written.append(path)
        return self.result

    # -- per frame ---------------------------------------------------------------------------
    def _replay_frames(
        self, rec: RecordingReader
    ) -> tuple[list[tuple[int, Any]], list[tuple[int, Any]]]:
        depth = DepthProcessor(self.cfg.depth)
        odometry: Odometry | None = None
        segmenter = self._make_segmenter() if "segmentation" in self.stages else None
        self._segmenter = segmenter
        gt_poses: list[tuple[int, Any]] = []
        self._seg_stats = _SegStats()
        frames = tqdm(
            rec.frames(),
            total=len(rec),
            unit="frame",
            dynamic_ncols=True,
            disable=not self.progress,
        )
        self._frames = 0  # counted here: a disabled tqdm (progress=False) does not count
        for frame in frames:
            self._frames += 1
            if odometry is None:
                odometry = Odometry(self.cfg.odometry, intrinsics=frame.color_intrinsics)
                self.viz.log_calibration(frame.color_intrinsics)
            self.viz.set_frame(frame.index, stamp_ns=frame.stamp_ns)
            with self._timer("depth"):
                depth_m = depth.process(frame)
            gt_pose = frame.ground_truth.world_from_camera if frame.ground_truth else None
            if self._anchor is None:
                # The map's world is the recording's world where it has a first pose (so the map
                # meets the ground-truth cloud), else the first camera.
                self._anchor = np.eye(4) if gt_pose is None else gt_pose
            with self._timer("odometry"):
                track = odometry.track(frame, depth_m)
            world_from_camera = self._anchor @ track.world_from_camera
            images = track.is_keyframe or frame.index % self.cfg.viz.images_every_n == 0
            if images:
                self.viz.log_frame(frame)
                if not frame.aligned:
                    self.viz.log_registered_depth(depth_m)
            self._log_track(track, world_from_camera, keypoints=images)
            if gt_pose is not None:
                gt_poses.append((frame.stamp_ns, gt_pose))
            if segmenter is not None and track.is_keyframe:
                self._keyframe(frame, segmenter)
        self._odometry = odometry
        trajectory = odometry.finish() if odometry is not None else []
        anchor = np.eye(4) if self._anchor is None else self._anchor
        return [(stamp, anchor @ pose) for stamp, pose in trajectory], gt_poses

    @contextmanager
    def _timer(self, stage: str) -> Iterator[None]:
        """Add the block's wall time to the stage's total and log it on the timeline."""
        t0 = time.perf_counter()
        yield
        dt = time.perf_counter() - t0
        self._seconds[stage] = self._seconds.get(stage, 0.0) + dt
        self.viz.log_timing(stage, dt)

    def _log_track(
        self, track: Any, world_from_camera: npt.NDArray[np.float64], *, keypoints: bool
    ) -> None:
        self.viz.log_pose(world_from_camera, keyframe=track.is_keyframe)
        if keypoints:  # only over the image they belong to
            self.viz.log_keypoints(track.keypoints_xy, inliers=track.inlier_mask)
        self.viz.log_tracking(track.n_inliers, status=track.status, event=track.event)

    def _make_segmenter(self) -> Any:
        from process.segmentation import Segmenter

        return Segmenter(self.cfg.segmentation, weights=self.weights, device=self.device)

    def _keyframe(self, frame: RgbdFrame, segmenter: Any) -> None:
        with self._timer("segmentation"):
            seg = segmenter.segment(frame.color)
        self.viz.log_segmentation(seg.labels, confidence=seg.confidence)
        gt = frame.ground_truth
        if gt is not None and gt.labels is not None:
            self._seg_stats.add(seg.labels, gt.labels)
        self._seg_stats.keyframes += 1
        self._keyframe_stamps.add(frame.stamp_ns)

    def _fuse(self, rec: RecordingReader, trajectory: list[tuple[int, Any]]) -> Any:
        """Fuse the keyframes at their final poses: a second pass over the recording.

        The final poses include the loop closures found after a keyframe was tracked; keeping
        the keyframes' images until then would make memory grow with the recording, reading
        them again does not. Segmenting a keyframe again costs ~20 ms.
        """
        from process.fusion.votes import Fusion

        fusion = Fusion(self.cfg.fusion)
        depth = DepthProcessor(self.cfg.depth)
        world_from_camera = dict(trajectory)
        with self._timer("fusion"):
            for frame in rec.frames():
                if frame.stamp_ns not in self._keyframe_stamps:
                    continue
                seg = self._segmenter.segment(frame.color)
                fusion.integrate(
                    frame.color,
                    depth.process(frame),
                    seg.labels,
                    seg.confidence,
                    intrinsics=frame.color_intrinsics,
                    world_from_camera=world_from_camera[frame.stamp_ns],
                )
        return fusion.cloud()

    # -- after the frames ----------------------------------------------------------------
    def _finish_odometry(
        self, trajectory: list[tuple[int, Any]], gt_poses: list[tuple[int, Any]]
    ) -> None:
        stamps = [s for s, _ in trajectory]
        poses = [p for _, p in trajectory]
        path = self.out_dir / outputs.TRAJECTORY
        write_tum(path, stamps, poses)
        self.result.written.append(path)
        self.viz.log_trajectory(
            "estimated", np.array(stamps, np.int64), np.array([p[:3, 3] for p in poses])
        )
        seconds = self._seconds.get("odometry", 0.0) + self._seconds.get("depth", 0.0)
        odo: dict[str, Any] = {
            "frames": self._frames,
            "keyframes": int(getattr(self._odometry, "n_keyframes", 0)),
            "fps": round(self._frames / seconds, 2) if seconds > 0 else None,
        }
        if gt_poses:
            gt_stamps = np.array([s for s, _ in gt_poses], np.int64)
            self.viz.log_trajectory(
                "ground_truth", gt_stamps, np.array([p[:3, 3] for _, p in gt_poses])
            )
            est = (np.array(stamps, np.int64), np.array(poses))
            ref = (gt_stamps, np.array([p for _, p in gt_poses]))
            odo["ate_rmse_m"] = ate_rmse(est, ref)
            odo["rpe_trans_m"], odo["rpe_rot_deg"] = rpe(est, ref)
            odo["path_length_m"] = path_length(ref[1])
            self.viz.log_metrics("odometry", {k: v for k, v in odo.items() if isinstance(v, float)})
        self.result.metrics["odometry"] = odo
        if "segmentation" in self.stages:
            self.result.metrics["segmentation"] = self._seg_stats.summary(
                self._seconds.get("segmentation", 0.0)
            )

    def _write_cloud(self, name: str, cloud: Any) -> None:
        from process.cloud import write_ply

        path = self.out_dir / name
        write_ply(path, cloud)
        self.result.written.append(path)

    def _refine(self, cloud: Any, gt_cloud_ply: bytes | None) -> None:
        from process.refine.job import refine_and_log

        t0 = time.perf_counter()
        refined, section = refine_and_log(
            cloud, self.cfg.refine, viz=self.viz, up=self._up_vector(), gt_cloud_ply=gt_cloud_ply
        )
        self._seconds["refinement"] = time.perf_counter() - t0
        self._write_cloud(outputs.MAP_REFINED, refined)
        self.result.metrics["refinement"] = section

    def _up_vector(self) -> npt.NDArray[np.float64] | None:
        """Return a hint of world up: the first camera's -y axis (optical y points down).

        Refinement replaces it by the normal of the largest plane within 30 degrees of it, so a
        camera held a little tilted at the start still gives a level floor.
        """
        if self._anchor is None:
            return None
        up: npt.NDArray[np.float64] = self._anchor[:3, :3] @ np.array([0.0, -1.0, 0.0])
        return up

    def _write_config(self) -> None:
        path = self.out_dir / outputs.CONFIG
        outputs.write_text_atomic(path, to_toml(self.cfg))
        self.result.written.append(path)


class _SegStats:
    """Accumulates a confusion matrix of keyframe labels against ground truth."""

    def __init__(self) -> None:
        self.keyframes = 0
        self.confusion = np.zeros((len(LABEL_NAMES), len(LABEL_NAMES)), np.int64)

    def add(self, pred: npt.NDArray[np.uint8], gt: npt.NDArray[np.uint8]) -> None:
        self.confusion += confusion_matrix(pred, gt)

    def summary(self, seconds: float) -> dict[str, Any]:
        out: dict[str, Any] = {
            "keyframes": self.keyframes,
            "ms_per_keyframe": round(1000 * seconds / self.keyframes, 2)
            if self.keyframes
            else None,
        }
        if self.confusion.sum() == 0:
            return out
        present = [c for c in range(1, len(LABEL_NAMES)) if self.confusion[c].sum() > 0]
        iou = {LABEL_NAMES[c]: ratios(*class_counts(self.confusion, c))["iou"] for c in present}
        out["iou_2d"] = iou
        out["miou_2d"] = float(np.mean(list(iou.values()))) if iou else None
        return out
