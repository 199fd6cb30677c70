"""Visual odometry: ORB + PnP against the last keyframe, dense refinement, loop closure.

Per frame (`Odometry.track`): ORB features are matched to the reference keyframe's features that
have depth, by projection around the pose a constant-velocity model predicts (all against all when
there is no prediction); PnP RANSAC, with the prediction as a second hypothesis, gives the pose;
Gauss-Newton refines it on the inliers' reprojection and the current depth
(process.odometry.locate). Open3D's RGB-D odometry on half-size images then refines it densely
(process.odometry.dense). A frame becomes a keyframe when it has moved or turned enough, sees too
little of the reference, or keeps too few inliers; it enters a pose graph. New keyframes are
compared with old ones (thumbnail similarity and pose proximity, verified by PnP); a loop closure
adds an edge and the graph is optimised (GTSAM, sparse: process.odometry.loop_closure).
When tracking fails
the odometry tries the recent keyframes and, after a while, starts a new segment; each of these is
an event on the timeline. Every pose is stored relative to its keyframe, so `finish()` returns all
frames after the last optimisation. Memory grows with keyframes (features, a thumbnail: <= 80 kB
each, ~2,400 keyframes in a 10-minute walk), plus one small pose per frame; only the reference
keyframe keeps images.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from capture.recording import Intrinsics, RgbdFrame
from process.odometry.config import OdometryConfig
from process.odometry.dense import DenseAligner
from process.odometry.features import FeatureExtractor, Keyframe
from process.odometry.pose_graph import PoseGraph
from process.odometry.state import TrackState
from process.odometry.tracker import Tracker

__all__ = ["Odometry", "OdometryConfig", "TrackResult"]


@dataclass(frozen=True, slots=True)
class TrackResult:
    """What the odometry made of one frame; enough to draw it on the timeline."""

    index: int
    stamp_ns: int
    world_from_camera: npt.NDArray[
        np.float64
    ]  # (4, 4) colour optical frame; first keyframe = identity
    is_keyframe: bool
    keyframe_id: int  # the keyframe this frame was tracked against (-1 before initialisation)
    status: str  # "ok" | "lost" | "relocalised" | "new_segment" | "frozen"
    n_inliers: int
    keypoints_xy: npt.NDArray[np.float32]  # (N, 2) this frame's ORB keypoints, pixels
    inlier_mask: npt.NDArray[np.bool_]  # (N,) PnP inliers among keypoints_xy
    matched_keyframe_xy: npt.NDArray[np.float32]  # (N, 2) matched keyframe keypoint, NaN if none
    event: str | None  # a one-line note for the timeline (loss, relocalisation, loop closure ...)
    seconds: float  # time spent in track()
    trajectory_corrected: bool = False  # a loop closure moved earlier poses: redraw the trajectory


class Odometry:
    """Track an RGB-D stream, one frame at a time; `finish()` returns every optimised pose."""

    def __init__(self, cfg: OdometryConfig, *, intrinsics: Intrinsics) -> None:
        self.cfg = cfg
        self.intrinsics = intrinsics
        extractor = FeatureExtractor(
            intrinsics,
            n_features=cfg.n_features,
            scale_factor=cfg.orb_scale_factor,
            levels=cfg.orb_levels,
            fast_threshold=cfg.fast_threshold,
            min_depth_m=cfg.min_depth_m,
            max_depth_m=cfg.max_depth_m,
        )
        dense = DenseAligner(
            intrinsics,
            scale=cfg.dense_scale,
            max_depth_m=cfg.max_depth_m,
            iterations=cfg.dense_iterations,
            quick_iterations=cfg.dense_frame_iterations,
            method=cfg.dense_method,
        )
        self.graph = PoseGraph()
        self.keyframes: list[Keyframe] = []
        self._tracker = Tracker(
            cfg, extractor=extractor, dense=dense, graph=self.graph, keyframes=self.keyframes
        )
        self._frames: list[
            tuple[int, int, npt.NDArray[np.float64]]
        ] = []  # stamp, keyframe, kf_from_camera

    @property
    def n_keyframes(self) -> int:
        """Return how many keyframes the odometry has made."""
        return len(self.keyframes)

    def track(self, frame: RgbdFrame, depth_m: npt.NDArray[np.float32]) -> TrackResult:
        """Estimate the pose of one frame from its colour and its depth in the colour camera."""
        t0 = time.perf_counter()
        gray = np.asarray(cv2.cvtColor(frame.color, cv2.COLOR_RGB2GRAY), np.uint8)
        state: TrackState = self._tracker.step(gray, np.asarray(depth_m, np.float32), frame)
        self._frames.append((frame.stamp_ns, state.keyframe_id, state.keyframe_from_camera))
        world = (
            self.graph.poses[state.keyframe_id] @ state.keyframe_from_camera
            if state.keyframe_id >= 0
            else np.eye(4)
        )
        return TrackResult(
            index=frame.index,
            stamp_ns=frame.stamp_ns,
            world_from_camera=world,
            is_keyframe=state.is_keyframe,
            keyframe_id=state.keyframe_id,
            status=state.status,
            n_inliers=state.n_inliers,
            keypoints_xy=state.keypoints_xy,
            inlier_mask=state.inlier_mask,
            matched_keyframe_xy=state.matched_keyframe_xy,
            event=state.event,
            seconds=time.perf_counter() - t0,
            trajectory_corrected=state.trajectory_corrected,
        )

    def finish(self) -> list[tuple[int, npt.NDArray[np.float64]]]:
        """Optimise the graph a last time; return (stamp_ns, world_from_camera) of every frame."""
        if self.cfg.loop_closure and self.graph.n_loops > 0:
            self.graph.optimise(
                max_correspondence_m=self.cfg.loop_max_correspondence_m,
                prune_threshold=self.cfg.loop_prune_threshold,
            )
        out = []
        for stamp_ns, kf, kf_from_camera in self._frames:
            world = self.graph.poses[kf] @ kf_from_camera if kf >= 0 else np.eye(4)
            out.append((stamp_ns, world))
        return out
