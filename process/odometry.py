"""Visual odometry: ORB + PnP RANSAC against the last keyframe, dense refinement, loop closure.

Per frame (`Odometry.track`): ORB features are matched to the reference keyframe's features that
have depth, PnP RANSAC on the 3-D/2-D matches gives the pose, Levenberg-Marquardt refines it on
the inliers. A frame becomes a keyframe when it has moved or turned enough, or sees too little of
the reference; its pose relative to the reference is then refined densely (Open3D's hybrid
photometric + geometric RGB-D odometry on half-size images) and enters a pose graph. New keyframes
are compared with old ones (thumbnail similarity and pose proximity, verified by PnP); a loop
closure adds an edge and the graph is optimised. When tracking fails the odometry tries the recent
keyframes and, after a while, starts a new segment; each of these is an event on the timeline.
Every pose is stored relative to its keyframe, so `finish()` returns all frames after the last
optimisation. Memory grows with keyframes (features, a thumbnail), plus one small pose per frame.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from capture.recording import Intrinsics, RgbdFrame
from process.errors import ConfigError
from process.loop_closure import PoseGraph
from process.odometry_dense import DENSE_METHODS, DenseAligner
from process.odometry_features import FeatureExtractor, Keyframe
from process.odometry_tracker import Tracker, TrackState

__all__ = ["Odometry", "OdometryConfig", "TrackResult"]


@dataclass(frozen=True, slots=True)
class OdometryConfig:
    """Settings of the visual odometry; defaults suit a D435 at 640x480, 30 frames/s."""

    n_features: int = 1000  # ORB features per frame
    orb_scale_factor: float = 1.2
    orb_levels: int = 8
    fast_threshold: int = 20
    match_ratio: float = 0.8  # Lowe's ratio test on Hamming distances
    min_depth_m: float = 0.2  # features outside this depth range get no 3-D point
    max_depth_m: float = 6.0
    ransac_reprojection_px: float = 2.0
    ransac_iterations: int = 200
    ransac_confidence: float = 0.999
    min_inliers: int = 20  # fewer PnP inliers: tracking is lost
    max_step_m: float = 0.3  # a larger jump between consecutive frames is rejected as wrong
    keyframe_translation_m: float = 0.15
    keyframe_rotation_deg: float = 10.0
    keyframe_min_overlap: float = 0.7  # share of the keyframe's points still in view
    keyframe_min_inliers: int = 100
    dense_refine: bool = True  # refine keyframe poses by dense RGB-D alignment
    dense_refine_all_frames: bool = False  # ... and every other frame too (slower)
    dense_method: str = (
        "auto"  # "auto" | "point_to_plane" | "hybrid" | "intensity" (odometry_dense)
    )
    dense_scale: int = 2  # dense alignment on images downsampled by this factor
    dense_iterations: tuple[int, ...] = (10, 5, 3)  # per pyramid level, finest first
    dense_min_fitness: float = 0.3
    dense_max_correction_m: float = 0.05  # larger corrections of the PnP pose are rejected
    dense_max_correction_deg: float = 3.0
    relocalise_keyframes: int = 5  # recent keyframes tried when tracking fails
    lost_frames_new_segment: int = 15  # lost this long: start a new segment
    loop_closure: bool = True
    loop_min_gap: int = 10  # keyframes between a loop's ends
    loop_candidates: int = 3
    loop_min_similarity: float = 0.6  # thumbnail correlation for an appearance candidate
    loop_search_radius_m: float = 1.0  # pose-proximity candidates
    loop_min_inliers: int = 100  # PnP inliers that verify a loop (the best candidate is kept)
    loop_cooldown: int = 3  # keyframes after a loop closure before the next is searched
    loop_max_correspondence_m: float = 0.05  # Open3D line-process scale
    loop_prune_threshold: float = 0.25

    def __post_init__(self) -> None:
        _check(50 <= self.n_features <= 10000, "n_features", "50..10000", self.n_features)
        _check(
            1.0 < self.orb_scale_factor <= 2.0, "orb_scale_factor", "(1, 2]", self.orb_scale_factor
        )
        _check(1 <= self.orb_levels <= 16, "orb_levels", "1..16", self.orb_levels)
        _check(1 <= self.fast_threshold <= 100, "fast_threshold", "1..100", self.fast_threshold)
        _check(0.0 < self.match_ratio <= 1.0, "match_ratio", "(0, 1]", self.match_ratio)
        _check(
            0.0 <= self.min_depth_m < self.max_depth_m,
            "min_depth_m/max_depth_m",
            "0 <= min < max",
            (self.min_depth_m, self.max_depth_m),
        )
        _check(
            0.0 < self.ransac_reprojection_px <= 20.0,
            "ransac_reprojection_px",
            "(0, 20]",
            self.ransac_reprojection_px,
        )
        _check(
            10 <= self.ransac_iterations <= 10000,
            "ransac_iterations",
            "10..10000",
            self.ransac_iterations,
        )
        _check(
            0.5 <= self.ransac_confidence < 1.0,
            "ransac_confidence",
            "[0.5, 1)",
            self.ransac_confidence,
        )
        _check(6 <= self.min_inliers <= 1000, "min_inliers", "6..1000", self.min_inliers)
        _check(self.max_step_m > 0, "max_step_m", "> 0", self.max_step_m)
        _check(
            self.keyframe_translation_m > 0,
            "keyframe_translation_m",
            "> 0",
            self.keyframe_translation_m,
        )
        _check(
            0 < self.keyframe_rotation_deg <= 90,
            "keyframe_rotation_deg",
            "(0, 90]",
            self.keyframe_rotation_deg,
        )
        _check(
            0.0 <= self.keyframe_min_overlap < 1.0,
            "keyframe_min_overlap",
            "[0, 1)",
            self.keyframe_min_overlap,
        )
        _check(
            self.keyframe_min_inliers >= self.min_inliers,
            "keyframe_min_inliers",
            ">= min_inliers",
            self.keyframe_min_inliers,
        )
        _check(
            self.dense_method in DENSE_METHODS,
            "dense_method",
            f"one of {DENSE_METHODS}",
            self.dense_method,
        )
        _check(self.dense_scale in (1, 2, 4, 8), "dense_scale", "1, 2, 4 or 8", self.dense_scale)
        _check(
            0 < len(self.dense_iterations) <= 5
            and all(0 < i <= 100 for i in self.dense_iterations),
            "dense_iterations",
            "1 to 5 levels of 1..100 iterations",
            self.dense_iterations,
        )
        _check(
            0.0 <= self.dense_min_fitness <= 1.0,
            "dense_min_fitness",
            "[0, 1]",
            self.dense_min_fitness,
        )
        _check(
            self.dense_max_correction_m > 0,
            "dense_max_correction_m",
            "> 0",
            self.dense_max_correction_m,
        )
        _check(
            self.dense_max_correction_deg > 0,
            "dense_max_correction_deg",
            "> 0",
            self.dense_max_correction_deg,
        )
        _check(
            0 <= self.relocalise_keyframes <= 50,
            "relocalise_keyframes",
            "0..50",
            self.relocalise_keyframes,
        )
        _check(
            self.lost_frames_new_segment >= 1,
            "lost_frames_new_segment",
            ">= 1",
            self.lost_frames_new_segment,
        )
        _check(self.loop_min_gap >= 2, "loop_min_gap", ">= 2", self.loop_min_gap)
        _check(1 <= self.loop_candidates <= 20, "loop_candidates", "1..20", self.loop_candidates)
        _check(
            -1.0 <= self.loop_min_similarity <= 1.0,
            "loop_min_similarity",
            "[-1, 1]",
            self.loop_min_similarity,
        )
        _check(
            self.loop_search_radius_m >= 0,
            "loop_search_radius_m",
            ">= 0",
            self.loop_search_radius_m,
        )
        _check(
            self.loop_min_inliers >= self.min_inliers,
            "loop_min_inliers",
            ">= min_inliers",
            self.loop_min_inliers,
        )
        _check(self.loop_cooldown >= 0, "loop_cooldown", ">= 0", self.loop_cooldown)
        _check(
            self.loop_max_correspondence_m > 0,
            "loop_max_correspondence_m",
            "> 0",
            self.loop_max_correspondence_m,
        )
        _check(
            0.0 <= self.loop_prune_threshold < 1.0,
            "loop_prune_threshold",
            "[0, 1)",
            self.loop_prune_threshold,
        )


def _check(ok: bool, name: str, expected: str, found: object) -> None:
    if not ok:
        raise ConfigError(
            f"odometry.{name} must be {expected}, found {found!r}; fix [odometry] in the config"
        )


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
