"""Visual odometry: ORB + PnP against the last keyframe, dense refinement, loop closure.

Per frame (`Odometry.track`): ORB features are matched to the reference keyframe's features that
have depth, by projection around the pose a constant-velocity model predicts (all against all when
there is no prediction); PnP RANSAC, with the prediction as a second hypothesis, gives the pose;
Gauss-Newton refines it on the inliers' reprojection and the current depth
(process.odometry.locate). Open3D's RGB-D odometry on half-size images then refines it densely
(process.odometry.dense). A frame becomes a keyframe when it has moved or turned enough, sees too
little of the reference, or keeps too few inliers; it enters a pose graph, its edge weighted by
the refinement's information (Gauss-Newton Hessian). A keyframe whose pose the dense step could
not correct is also located against the keyframe(s) before its parent, and that stretch of the
graph is optimised with older keyframes held (process.odometry.covisibility). New keyframes are
compared with old ones (thumbnail similarity and pose proximity, verified by PnP on features
matched around the graph's prediction first); a loop closure adds an edge and the loop is
optimised (GTSAM, sparse: process.odometry.loop_closure).
When tracking fails
the odometry tries the recent keyframes and, after a while, starts a new segment; each of these is
an event on the timeline. Every pose is stored relative to its keyframe, so `finish()` returns all
frames after the last optimisation. Memory grows with keyframes (features, a thumbnail: <= 80 kB
each, ~2,400 keyframes in a 10-minute walk), plus one small pose per frame; only the reference
keyframe keeps images.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import cv2
import numpy as np
import numpy.typing as npt

from capture.recording import Intrinsics, RgbdFrame
from process.odometry.config import OdometryConfig
from process.odometry.dense import DenseAligner
from process.odometry.features import FeatureExtractor, Keyframe
from process.odometry.pose_graph import PoseGraph
from process.odometry.rolling_shutter import RollingShutter
from process.odometry.state import TrackState
from process.odometry.tracker import Tracker
from process.odometry.undistort import Undistorter
from process.trajectory import Trajectory


@dataclass(frozen=True, slots=True)
class TrackResult:
    """What the odometry made of one frame: its world pose and the tracker's verdict."""

    index: int
    stamp_ns: int
    world_from_camera: npt.NDArray[np.float64]  # (4, 4) colour optical frame, in the map's world
    state: TrackState  # keyframe, status, inliers, keypoints, event

    @property
    def is_keyframe(self) -> bool:
        """Return whether this frame became a keyframe."""
        return self.state.is_keyframe


class Odometry:
    """Track an RGB-D stream, one frame at a time; `finish()` returns every optimised pose.

    Poses are in the map's world: `world_from_first` places the first camera (the recording's
    ground-truth pose where it has one, so the map meets the ground-truth cloud; else identity).
    """

    def __init__(
        self,
        cfg: OdometryConfig,
        *,
        intrinsics: Intrinsics,
        world_from_first: npt.NDArray[np.float64] | None = None,
        recording_readout_s: float | None = None,
    ) -> None:
        """Set up the odometry of one camera.

        Args:
            cfg: the [odometry] settings.
            intrinsics: the colour camera's.
            world_from_first: where the first camera is in the map's world (None: identity).
            recording_readout_s: the colour camera's rolling-shutter readout time from the
                recording's metadata, used unless cfg.rolling_shutter_readout_s is set.
        """
        self.cfg = cfg
        self.intrinsics = intrinsics
        self.world_from_first = np.eye(4) if world_from_first is None else world_from_first
        self._undistort = Undistorter(intrinsics) if intrinsics.is_distorted else None
        pinhole = self._undistort.pinhole if self._undistort else intrinsics
        extractor = FeatureExtractor(
            pinhole,
            n_features=cfg.n_features,
            scale_factor=cfg.orb_scale_factor,
            levels=cfg.orb_levels,
            fast_threshold=cfg.fast_threshold,
            min_depth_m=cfg.min_depth_m,
            max_depth_m=cfg.max_depth_m,
        )
        dense = DenseAligner(
            pinhole,
            scale=cfg.dense_scale,
            max_depth_m=cfg.max_depth_m,
            iterations=cfg.dense_iterations,
            quick_iterations=cfg.dense_frame_iterations,
            method=cfg.dense_method,
            reproducible=cfg.reproducible,
        )
        readout = cfg.rolling_shutter_readout_s
        self.readout_s = float((recording_readout_s or 0.0) if readout is None else readout)
        shutter = RollingShutter(pinhole, self.readout_s) if self.readout_s > 0 else None
        self._tracker = Tracker(cfg, extractor=extractor, dense=dense, shutter=shutter)
        self._frames: list[tuple[int, int, npt.NDArray[np.float64]]] = []  # stamp, kf, kf_from_cam

    @property
    def graph(self) -> PoseGraph:
        """Return the keyframe pose graph (poses relative to the first camera)."""
        return self._tracker.graph

    @property
    def keyframes(self) -> Sequence[Keyframe]:
        """Return the keyframes, read-only (the tracker owns and extends them)."""
        return self._tracker.keyframes

    @property
    def n_keyframes(self) -> int:
        """Return how many keyframes the odometry has made."""
        return len(self._tracker.keyframes)

    def keyframe_pose(self, keyframe_id: int) -> npt.NDArray[np.float64]:
        """Return the latest world_from_camera of a keyframe (it moves when a loop closes)."""
        return self.world_from_first @ self.graph.poses[keyframe_id]

    def track(self, frame: RgbdFrame, depth_m: npt.NDArray[np.float32]) -> TrackResult:
        """Estimate the pose of one frame from its colour and its depth in the colour camera."""
        gray = np.asarray(cv2.cvtColor(frame.color, cv2.COLOR_RGB2GRAY), np.uint8)
        depth = np.asarray(depth_m, np.float32)
        if self._undistort is not None:
            gray, depth = self._undistort.gray(gray), self._undistort.depth(depth)
        state = self._tracker.step(gray, depth, frame)
        self._frames.append((frame.stamp_ns, state.keyframe_id, state.keyframe_from_camera))
        if self._undistort is not None:  # the timeline draws on the raw image
            state = replace(
                state,
                keypoints_xy=self._undistort.to_distorted(state.keypoints_xy),
                matched_keyframe_xy=self._undistort.to_distorted(state.matched_keyframe_xy),
            )
        return TrackResult(
            frame.index,
            frame.stamp_ns,
            self._world(state.keyframe_id, state.keyframe_from_camera),
            state,
        )

    def finish(self) -> Trajectory:
        """Optimise the graph a last time; return the world pose of every frame."""
        if self.cfg.loop_closure and self.graph.n_loops > 0:
            self.graph.optimise(
                max_correspondence_m=self.cfg.loop_max_correspondence_m,
                prune_threshold=self.cfg.loop_prune_threshold,
            )
        return Trajectory.of(
            [stamp for stamp, _, _ in self._frames],
            [self._world(kf, kf_from_camera) for _, kf, kf_from_camera in self._frames],
        )

    def _world(
        self, keyframe_id: int, kf_from_camera: npt.NDArray[np.float64]
    ) -> npt.NDArray[np.float64]:
        if keyframe_id < 0:  # before initialisation
            return self.world_from_first.copy()
        return self.keyframe_pose(keyframe_id) @ kf_from_camera
