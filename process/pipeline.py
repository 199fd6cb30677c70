"""ReplayPipeline: a recording through odometry, segmentation, fusion and refinement, in one pass.

The odometry runs on the calling thread, frame after frame. Keyframes go to a worker thread that
segments and fuses them, and every logging call goes to a thread that encodes and writes the
`.rrd` (process.streaming, viz.background); bounded queues keep memory flat. Keyframes are fused
at their pose when tracked; if loop closures later move them, the map is fused again at the
final poses from the keyframes the fusion kept on disk (process.fusion.keyframes).

Two runs of one recording with one config write the same maps, trajectory and metrics (but
timings), bit for bit: keyframes are chosen on the frame loop's thread and fused in their order,
whatever the threads' timing; the dense odometry sums on one thread (process.odometry.dense) and
the TSDF's points come out sorted (process.fusion.tsdf). Following a live capture is the
exception: which frames and keyframes are left out to keep up depends on the clock.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import logging
import os
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np
import numpy.typing as npt
from tqdm import tqdm

from capture.recording import GT_CLOUD_ATTACHMENT, LABEL_NAMES, RecordingReader, RgbdFrame
from process import outputs
from process.cloud import LabelledCloud, write_ply
from process.config import ReplayConfig, to_toml
from process.depth import DepthProcessor
from process.evaluate import confusion_iou, confusion_matrix, confusion_miou
from process.fusion.keyframes import KeyframeFusion, LabelledKeyframe
from process.fusion.schedule import SegmentationSchedule
from process.odometry.odometry import Odometry, TrackResult
from process.odometry.rolling_shutter import recorded_readout_s
from process.preview import write_preview
from process.streaming import Worker, prefetch
from process.trajectory import Trajectory, ate_rmse, path_length, rpe, write_tum
from viz.background import BackgroundLogger
from viz.layout import STAGE_FUSED
from viz.logger import Logger

if TYPE_CHECKING:
    from process.segmentation.segmenter import Segmenter

logger = logging.getLogger(__name__)


@dataclass
class RunResult:
    """What a run produced: the files written and the metrics."""

    out_dir: Path
    written: list[Path] = field(default_factory=list)
    metrics: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class _Keyframe:
    """A tracked keyframe on its way to segmentation and fusion."""

    frame: RgbdFrame
    depth_m: npt.NDArray[np.float32]  # (H, W) registered to colour
    keyframe_id: int
    world_from_camera: npt.NDArray[np.float64]  # (4, 4) when tracked
    segment: bool  # False: geometry only (SegmentationSchedule)


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
        follow_idle_s: float | None = None,
        stop: threading.Event | None = None,
    ) -> None:
        self.recording = recording
        self.follow_idle_s = follow_idle_s  # follow a recording still being written
        self.stop = stop or threading.Event()  # set: stop following and finish with what came
        self.out_dir = out_dir
        self.cfg = cfg
        self.stages = stages
        self.viz = BackgroundLogger(viz)
        self.weights = weights
        self.device = device
        self.progress = progress
        self.result = RunResult(out_dir)
        self.clock = _StageClock()
        self._frames = 0
        self._odometry: Odometry | None = None
        self._readout_s: float | None = None  # the colour camera's, from the recording
        self._segmenter: Segmenter | None = None
        self._schedule = SegmentationSchedule(cfg.segmentation.min_new_share)
        self._seg_stats = _SegStats()
        self._seg_model: dict[str, Any] = {}  # which model, why, its load time
        self._fusion = KeyframeFusion(cfg.fusion) if "fusion" in stages else None
        # 12 keyframes (~4 MB each) absorb a burst of keyframes in fast motion without holding
        # the odometry back (4: the frame loop waited 1 s of 22 on TUM fr1_rpy, 12: 0.3 s)
        self._keyframes: Worker[_Keyframe] = Worker("keyframes", self._on_keyframe, max_pending=12)
        self._keyframe_stamps: dict[int, int] = {}  # keyframe id -> stamp_ns
        self._lag_s: list[float] = []  # following: wall clock minus frame stamp, per frame
        self._keyframes_skipped = 0  # following: keyframes the segmentation had no room for
        self._frames_dropped = 0  # following: frames too late to be tracked (FollowConfig)
        self._read_waited_s = 0.0  # the frame loop waited for the next frame (or the camera)
        self._frames_done_at: float | None = None  # perf_counter when the last frame was tracked

    def run(self) -> RunResult:
        """Run the stages and write the outputs; return what was written and measured."""
        wall0, cpu0 = time.perf_counter(), time.process_time()
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self._write_config()
        if "segmentation" in self.stages:
            # Import the networks' runtimes (torch: ~1 s) before the recording is opened: when
            # following a capture this happens while waiting for its first frames, not after.
            import process.segmentation.segmenter  # noqa: F401
        try:
            reader = RecordingReader(
                self.recording, follow_idle_s=self.follow_idle_s, stop=self.stop
            )
            with reader as rec:
                self._note_ground_truth(rec)
                ground_truth = self._replay(rec)
                for text in rec.warnings:  # already in the log
                    self._warn(text, logged=True)
                gt_cloud = rec.attachment(GT_CLOUD_ATTACHMENT)
            trajectory = self._finish_odometry(ground_truth)
            if self._frames_dropped:
                self._warn(
                    f"following: {self._frames_dropped} frames were read more than"
                    f" {self.cfg.follow.max_lag_s:g} s after the camera took them and were not"
                    " tracked, to keep up with the capture ([follow] max_lag_s)"
                )
            if self._keyframes_skipped:
                self._warn(
                    f"following: {self._keyframes_skipped} keyframes were left out of the map"
                    " because segmentation could not keep up with the camera"
                )
            self._keyframes.join()
            if self._segmenter is not None:
                self.result.metrics["segmentation"] = {
                    **self._seg_model,
                    **self._seg_stats.summary(self.clock.wall.get("segmentation", 0.0)),
                }
            if self._fusion is not None and self._odometry is not None:
                self._map(trajectory, gt_cloud, up=self._odometry.world_from_first[:3, 1] * -1.0)
        except BaseException:
            self._stop_threads(failed=True)
            raise
        self._stop_threads(failed=False)
        end = time.perf_counter()
        after = end - self._frames_done_at if self._frames_done_at is not None else 0.0
        self._record_times(end - wall0, time.process_time() - cpu0, after_frames_s=after)
        path = self.out_dir / outputs.METRICS
        outputs.write_metrics(path, self.result.metrics)
        self.result.written.append(path)
        return self.result

    def _stop_threads(self, *, failed: bool) -> None:
        """Stop the keyframe and logging threads; after a failure, keep the first error."""
        close_viz = functools.partial(outputs.close_logger, self.viz, quiet=False)  # OutputError
        for stop in (self._keyframes.join, close_viz):
            try:
                stop()
            except Exception:
                if not failed:
                    raise
                logger.debug("a background thread failed too", exc_info=True)
        if self._fusion is not None:
            self._fusion.close()

    # -- the pass over the frames ------------------------------------------------------------
    def _replay(self, rec: RecordingReader) -> Trajectory:
        """Track every frame; hand keyframes to the worker; return the ground-truth poses."""
        self._readout_s = recorded_readout_s(rec.metadata)
        if "segmentation" in self.stages:
            self._segmenter = self._make_segmenter(rec)
        _limit_threads()
        gt_stamps: list[int] = []
        gt_poses: list[npt.NDArray[np.float64]] = []
        total = None if rec.following else len(rec)
        bar = tqdm(total=total, unit="frame", dynamic_ncols=True, disable=not self.progress)
        with bar:  # closed on errors too, so that an error line starts a line of its own
            for frame, depth_m in self._timed_frames(rec):
                self._frames += 1
                gt_pose = frame.ground_truth.world_from_camera if frame.ground_truth else None
                if gt_pose is not None:
                    gt_stamps.append(frame.stamp_ns)
                    gt_poses.append(gt_pose)
                self._track(frame, depth_m, gt_pose)
                bar.update()
                if rec.following:
                    self._lag_s.append((time.time_ns() - frame.stamp_ns) / 1e9)
        self._frames_done_at = time.perf_counter()
        return Trajectory.of(gt_stamps, gt_poses)

    def _timed_frames(
        self, rec: RecordingReader
    ) -> Iterator[tuple[RgbdFrame, npt.NDArray[np.float32]]]:
        """Yield the frames with their depth in the colour camera, prepared ahead on a thread.

        Reading, decoding (stage "read") and registering depth (stage "depth") run on that
        thread, so that the frame loop's thread does only the odometry.
        """
        ahead = 2 if rec.following else 4  # following: frames wait less in the queue
        frames = prefetch(self._read(rec), name="read", ahead=ahead, stop=self.stop)
        with contextlib.closing(frames) as items:
            while True:
                t0 = time.perf_counter()
                item = next(items, None)
                self._read_waited_s += time.perf_counter() - t0  # reading was the bottleneck
                if item is None:
                    return
                yield item

    def _read(self, rec: RecordingReader) -> Iterator[tuple[RgbdFrame, npt.NDArray[np.float32]]]:
        depth = DepthProcessor(self.cfg.depth)
        frames = rec.frames()
        follow = self.cfg.follow
        max_lag_ns = int(follow.max_lag_s * 1e9) if rec.following else 0
        max_gap_ns = int(1e9 / follow.min_tracked_hz)
        kept_ns: int | None = None  # stamp of the last frame passed on to be tracked
        while True:
            with self.clock("read"):
                frame = next(frames, None)
            if frame is None:
                return
            # following a capture: a frame already too old when it is read is dropped before
            # any work on it, so that a job slower than the camera keeps up; but the frames
            # tracked stay at most 1 / min_tracked_hz apart in camera time, so tracking holds
            late = max_lag_ns > 0 and time.time_ns() - frame.stamp_ns > max_lag_ns
            if late and kept_ns is not None and frame.stamp_ns - kept_ns < max_gap_ns:
                self._frames_dropped += 1
                continue
            kept_ns = frame.stamp_ns
            with self.clock("depth"):
                depth_m = depth.process(frame)
            yield frame, depth_m

    def _track(
        self,
        frame: RgbdFrame,
        depth_m: npt.NDArray[np.float32],
        gt_pose: npt.NDArray[np.float64] | None,
    ) -> None:
        if self._odometry is None:
            # The map's world is the recording's world where it has a first pose (so the map
            # meets the ground-truth cloud), else the first camera.
            self._odometry = Odometry(
                self.cfg.odometry,
                intrinsics=frame.color_intrinsics,
                world_from_first=gt_pose,
                recording_readout_s=self._readout_s,
            )
            self.viz.log_calibration(frame.color_intrinsics)
        self.viz.set_frame(frame.index, stamp_ns=frame.stamp_ns)
        with self.clock("odometry"):
            track = self._odometry.track(frame, depth_m)
        self._log_frame(frame, depth_m, track)
        if track.is_keyframe and self._segmenter is not None:
            cells = self._schedule.new_cells(
                depth_m,
                intrinsics=frame.color_intrinsics,
                world_from_camera=track.world_from_camera,
            )
            kf = _Keyframe(
                frame,
                depth_m,
                track.state.keyframe_id,
                track.world_from_camera,
                segment=cells is not None,
            )
            # Following a live capture, a keyframe the segmentation has no room for is left out
            # of the map rather than letting the whole job fall behind the camera; offline,
            # every keyframe is segmented (the frame loop waits).
            if self.follow_idle_s is None:
                self._keyframes.submit(kf)
            elif not self._keyframes.offer(kf):
                self._keyframes_skipped += 1
                return
            if cells is not None:  # what it sees is labelled now: later keyframes need not be
                self._schedule.cover(cells)
            self._keyframe_stamps[kf.keyframe_id] = frame.stamp_ns

    def _log_frame(
        self, frame: RgbdFrame, depth_m: npt.NDArray[np.float32], track: TrackResult
    ) -> None:
        images = track.is_keyframe or frame.index % self.cfg.viz.images_every_n == 0
        if images:
            self.viz.log_frame(frame, keyframe=track.is_keyframe)
            if not frame.aligned:
                self.viz.log_registered_depth(depth_m, keyframe=track.is_keyframe)
        self.viz.log_pose(track.world_from_camera, keyframe=track.is_keyframe)
        if images:  # keypoints only over the image they belong to
            self.viz.log_keypoints(track.state.keypoints_xy, inliers=track.state.inlier_mask)
        state = track.state
        self.viz.log_tracking(state.n_inliers, status=state.status, event=state.event)

    # -- the keyframe worker (its own thread) ------------------------------------------------
    def _make_segmenter(self, rec: RecordingReader) -> Segmenter:
        from process.segmentation import Segmenter
        from process.segmentation.config import beside_odometry_threads
        from process.segmentation.models import choose_model

        t0 = time.perf_counter()
        cfg = self.cfg.segmentation
        if cfg.threads == 0:  # leave a core to the odometry
            cfg = dataclasses.replace(cfg, threads=beside_odometry_threads())
        device = rec.metadata.get("device", {}).get("name")
        choice = choose_model(cfg, weights=self.weights, device_name=device)
        segmenter = Segmenter(cfg, choice=choice, device=self.device)
        segmenter.warm_up()  # one-off setup is load time, not a keyframe's
        self._seg_model = {
            "model": choice.name,
            "model_reason": choice.reason,
            "threads": cfg.threads,  # the runtime's; compare ms_per_keyframe at the same count
            "load_s": round(time.perf_counter() - t0, 3),
        }
        note = f"segmentation model: {choice.name} ({choice.backend}), because {choice.reason}"
        self.viz.log_text(note, level="INFO")
        logger.info(note)
        return segmenter

    def _on_keyframe(self, kf: _Keyframe) -> None:
        assert self._segmenter is not None  # keyframes are queued only with a segmenter
        frame = kf.frame
        self.viz.set_frame(frame.index, stamp_ns=frame.stamp_ns)
        if kf.segment:
            with self.clock("segmentation"):
                seg = self._segmenter.segment(frame.color)
            self.viz.log_segmentation(seg.labels, confidence=seg.confidence)
            gt = frame.ground_truth
            if gt is not None and gt.labels is not None:
                self._seg_stats.add(seg.labels, gt.labels)
            self._seg_stats.keyframes += 1
            labels, confidence = seg.labels, seg.confidence
        else:  # geometry only: no label votes
            self._seg_stats.geometry_only += 1
            labels = np.zeros(frame.color.shape[:2], np.uint8)
            confidence = np.zeros(frame.color.shape[:2], np.float32)
        if self._fusion is not None:
            labelled = LabelledKeyframe(
                kf.keyframe_id, frame.color, kf.depth_m, labels, confidence, frame.color_intrinsics
            )
            with self.clock("fusion"):
                self._fusion.add(labelled, world_from_camera=kf.world_from_camera)

    # -- after the frames ----------------------------------------------------------------
    def _note_ground_truth(self, rec: RecordingReader) -> None:
        if not rec.has_ground_truth:
            self.viz.log_text(
                "recording has no ground truth: metrics against it are skipped", level="INFO"
            )
            logger.info("no ground truth in %s: metrics against it are skipped", self.recording)

    def _finish_odometry(self, ground_truth: Trajectory) -> Trajectory:
        with self.clock("odometry"):
            trajectory = (
                self._odometry.finish() if self._odometry is not None else Trajectory.of([], [])
            )
        path = self.out_dir / outputs.TRAJECTORY
        write_tum(path, trajectory)
        self.result.written.append(path)
        self.viz.log_trajectory("estimated", trajectory.stamps_ns, trajectory.positions)
        odo: dict[str, Any] = {
            "frames": self._frames,
            "keyframes": 0 if self._odometry is None else self._odometry.n_keyframes,
        }
        if self._odometry is not None:  # the rolling-shutter model it ran with (0: global)
            odo["rolling_shutter_readout_s"] = self._odometry.readout_s
        if len(ground_truth):
            self.viz.log_trajectory("ground_truth", ground_truth.stamps_ns, ground_truth.positions)
            odo["ate_rmse_m"] = ate_rmse(trajectory, ground_truth)
            odo["rpe_trans_m"], odo["rpe_rot_deg"] = rpe(trajectory, ground_truth)
            odo["path_length_m"] = path_length(ground_truth.poses)
            self.viz.log_metrics("odometry", {k: v for k, v in odo.items() if isinstance(v, float)})
        self.result.metrics["odometry"] = odo
        return trajectory

    def _map(
        self, trajectory: Trajectory, gt_cloud: bytes | None, *, up: npt.NDArray[np.float64]
    ) -> None:
        """Fuse at the final keyframe poses, write the map and refine it.

        `up` hints world up: the first camera's -y (optical y points down). Refinement replaces
        it by the normal of the largest plane within 30 degrees of it, so a camera held a little
        tilted at the start still gives a level floor.
        """
        assert self._fusion is not None
        pose_at = dict(zip(trajectory.stamps_ns.tolist(), trajectory.poses, strict=True))
        poses = {kf: pose_at[stamp] for kf, stamp in self._keyframe_stamps.items()}
        wall0, cpu0 = time.perf_counter(), time.thread_time()
        cloud = self._fusion.cloud(poses)
        # a map fused again at the final poses is a stage of its own: it runs after the frames
        stage = "refusion" if self._fusion.refused else "fusion"
        self.clock.add(stage, time.perf_counter() - wall0, time.thread_time() - cpu0)
        if self._fusion.refused:
            self.viz.log_text("loop closures moved keyframes: the map was fused again")
        refine = "refinement" in self.stages and len(cloud) > 0
        self._write_cloud(outputs.MAP_FUSED, cloud, preview=not refine)  # else the refined one
        self.viz.set_stage(STAGE_FUSED)
        self.viz.log_map("fused", cloud.points, colors=cloud.colors, labels=cloud.labels)
        if "refinement" not in self.stages:
            return
        if len(cloud) == 0:
            note = (
                "the fused map is empty: no keyframe pixel had depth within fusion's"
                f" {self.cfg.fusion.min_depth_m:g}..{self.cfg.fusion.max_depth_m:g} m;"
                " refinement is skipped (check [fusion] and the recording's depth)"
            )
            self._warn(note)
            return
        self._refine(cloud, gt_cloud, up=up)

    def _write_cloud(self, name: str, cloud: LabelledCloud, *, preview: bool = True) -> None:
        path = self.out_dir / name
        write_ply(path, cloud)
        self.result.written.append(path)
        if not preview:
            return
        up = None if self._odometry is None else -self._odometry.world_from_first[:3, 1]
        picture = write_preview(
            self.out_dir / outputs.PREVIEW, cloud.points, cloud.labels, up_hint=up
        )
        self.result.written += [] if picture in self.result.written else [picture]
        self.result.metrics["preview"] = picture.name

    def _refine(
        self, cloud: LabelledCloud, gt_cloud_ply: bytes | None, *, up: npt.NDArray[np.float64]
    ) -> None:
        """Refine the map and write it."""
        from process.refine.job import refine_and_log

        with self.clock("refinement"):
            refined, section = refine_and_log(
                cloud, self.cfg.refine, viz=self.viz, up=up, gt_cloud_ply=gt_cloud_ply
            )
        self._write_cloud(outputs.MAP_REFINED, refined)
        self.result.metrics["refinement"] = section

    def _record_times(self, wall_s: float, cpu_s: float, *, after_frames_s: float) -> None:
        """Put wall time, CPU time and frames/s per stage and for the job into the metrics."""
        self.clock.add("logging", self.viz.seconds, self.viz.cpu_seconds)
        n = self._frames
        per_stage = {
            stage: {
                "wall_s": round(wall, 3),
                "cpu_s": round(self.clock.cpu[stage], 3),
                "fps": round(n / wall, 2) if wall > 0 and stage not in _ONCE else None,
            }
            for stage, wall in self.clock.wall.items()
        }
        self.result.metrics["seconds"] = {k: v["wall_s"] for k, v in per_stage.items()}
        self.result.metrics["stages"] = per_stage
        keyframes_behind = self._keyframes.blocked_seconds / wall_s if wall_s > 0 else 0.0
        logging_behind = self.viz.blocked_seconds / wall_s if wall_s > 0 else 0.0
        read_behind = self._read_waited_s / wall_s if wall_s > 0 else 0.0
        after_behind = after_frames_s / wall_s if wall_s > 0 else 0.0
        reading = "the camera" if self.follow_idle_s is not None else "reading"
        self.result.metrics["job"] = {
            "frames": n,
            "wall_s": round(wall_s, 3),
            "cpu_s": round(cpu_s, 3),
            "fps": round(n / wall_s, 2) if wall_s > 0 else None,
            "cores_used": round(cpu_s / wall_s, 2) if wall_s > 0 else None,
            # the share of the run the frame loop waited for the frames (reading them, or the
            # camera when following) or for a later stage (that stage was the bottleneck), and
            # the share after the last frame (the rebuilt map, refinement, the outputs); the
            # rest of the time the frame loop itself (the odometry) was
            "bottleneck_share": {
                reading: round(read_behind, 3),
                "keyframes": round(keyframes_behind, 3),
                "logging": round(logging_behind, 3),
                "after the frames": round(after_behind, 3),
                "frame loop": round(
                    max(0.0, 1.0 - read_behind - keyframes_behind - logging_behind - after_behind),
                    3,
                ),
            },
        }
        if self._lag_s:
            lag = np.array(self._lag_s)
            self.result.metrics[
                "follow"
            ] = {  # seconds behind the camera, when each frame was tracked
                "lag_s_median": round(float(np.median(lag)), 3),
                "lag_s_p95": round(float(np.percentile(lag, 95)), 3),
                "lag_s_max": round(float(lag.max()), 3),
                "keyframes_skipped": self._keyframes_skipped,
                "frames_dropped": self._frames_dropped,
            }

        odo = self.result.metrics.get("odometry")
        seconds = self.clock.wall.get("odometry", 0.0) + self.clock.wall.get("depth", 0.0)
        if odo is not None:
            odo["fps"] = round(n / seconds, 2) if seconds > 0 else None

    def _warn(self, text: str, *, logged: bool = False) -> None:
        """Say a warning in the .rrd and metrics.json "warnings" (and the log unless it was)."""
        self.viz.log_text(text, level="WARN")
        if not logged:
            logger.warning("%s", text)
        self.result.metrics.setdefault("warnings", []).append(text)

    def _write_config(self) -> None:
        path = self.out_dir / outputs.CONFIG
        outputs.write_text_atomic(path, to_toml(self.cfg))
        self.result.written.append(path)


_ONCE = frozenset({"refinement", "refusion"})  # stages that run once per job: no frames/s


def _limit_threads() -> None:
    """Leave the second core to the keyframe and logging threads: OpenCV's pool would take it.

    BLAS gets one thread: the pipeline's matrix products are small (points times a 3x3
    rotation), and a second OpenBLAS thread spins after each one (5.5 of 41 CPU seconds on
    TUM fr1_rpy).
    """
    from threadpoolctl import threadpool_limits

    cv2.setNumThreads(max(1, (os.cpu_count() or 2) - 1))
    threadpool_limits(limits=1, user_api="blas")


class _StageClock:
    """Wall and CPU time per stage, added from any thread (each stage from one thread)."""

    def __init__(self) -> None:
        self.wall: dict[str, float] = {}
        self.cpu: dict[str, float] = {}

    @contextmanager
    def __call__(self, stage: str) -> Iterator[None]:
        t0, c0 = time.perf_counter(), time.thread_time()
        try:
            yield
        finally:
            self.add(stage, time.perf_counter() - t0, time.thread_time() - c0)

    def add(self, stage: str, wall_s: float, cpu_s: float) -> None:
        self.wall[stage] = self.wall.get(stage, 0.0) + wall_s
        self.cpu[stage] = self.cpu.get(stage, 0.0) + cpu_s


class _SegStats:
    """Accumulates a confusion matrix of keyframe labels against ground truth."""

    def __init__(self) -> None:
        self.keyframes = 0
        self.geometry_only = 0  # keyframes the schedule left unsegmented
        self.confusion = np.zeros((len(LABEL_NAMES), len(LABEL_NAMES)), np.int64)

    def add(self, pred: npt.NDArray[np.uint8], gt: npt.NDArray[np.uint8]) -> None:
        self.confusion += confusion_matrix(pred, gt)

    def summary(self, seconds: float) -> dict[str, Any]:
        out: dict[str, Any] = {
            "keyframes": self.keyframes,
            "keyframes_geometry_only": self.geometry_only,
            "ms_per_keyframe": round(1000 * seconds / self.keyframes, 2)
            if self.keyframes
            else None,
        }
        if self.confusion.sum() == 0:
            return out
        iou = confusion_iou(self.confusion)  # the one mIoU definition (labels 1-10)
        out["iou_2d"] = {LABEL_NAMES[c]: v for c, v in iou.items()}
        out["miou_2d"] = confusion_miou(self.confusion) if iou else None
        return out
