"""OdometryConfig: the [odometry] section of the config, with its ranges."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

from process.errors import ConfigError
from process.odometry.dense import DENSE_METHODS

# Inclusive ranges of the numeric settings.
_RANGES: Final[dict[str, tuple[float, float]]] = {
    "n_features": (50, 10_000),
    "orb_scale_factor": (1.05, 2.0),
    "orb_levels": (1, 16),
    "fast_threshold": (1, 100),
    "match_ratio": (0.1, 1.0),
    "guided_radius_px": (0.0, 500.0),
    "min_depth_m": (0.0, 100.0),
    "max_depth_m": (0.1, 100.0),
    "ransac_reprojection_px": (0.1, 20.0),
    "ransac_iterations": (10, 10_000),
    "ransac_confidence": (0.5, 0.999999),
    "min_inliers": (6, 1000),
    "max_step_m": (0.001, 100.0),
    "keyframe_translation_m": (0.001, 100.0),
    "keyframe_rotation_deg": (0.1, 90.0),
    "keyframe_min_overlap": (0.0, 0.99),
    "keyframe_min_inliers": (6, 10_000),
    "keyframe_min_inlier_ratio": (0.0, 0.99),
    "dense_min_fitness": (0.0, 1.0),
    "dense_max_correction_m": (0.0001, 10.0),
    "dense_max_correction_deg": (0.01, 90.0),
    "dense_max_reprojection_px": (0.0, 100.0),
    "relocalise_keyframes": (0, 50),
    "lost_frames_new_segment": (1, 100_000),
    "covisible_keyframes": (0, 10),
    "loop_min_gap": (2, 100_000),
    "loop_candidates": (1, 20),
    "loop_min_similarity": (-1.0, 1.0),
    "loop_search_radius_m": (0.0, 100.0),
    "loop_min_inliers": (6, 10_000),
    "loop_edges": (1, 20),
    "loop_cooldown": (0, 100_000),
    "loop_guided_radius_px": (0.0, 500.0),
    "loop_max_correspondence_m": (0.001, 10.0),
    "loop_prune_threshold": (0.0, 0.99),
}


@dataclass(frozen=True, slots=True)
class OdometryConfig:
    """Settings of the visual odometry; defaults suit a D435 at 640x480, 30 frames/s."""

    n_features: int = 1500  # ORB features per frame
    orb_scale_factor: float = 1.2
    orb_levels: int = 8
    fast_threshold: int = 20
    match_ratio: float = 0.8  # Lowe's ratio test on Hamming distances
    guided_radius_px: float = 20.0  # match by projection within this radius (0: all against all)
    min_depth_m: float = 0.2  # features outside this depth range get no 3-D point
    max_depth_m: float = 6.0
    ransac_reprojection_px: float = 2.0
    ransac_iterations: int = 200
    ransac_confidence: float = 0.999
    min_inliers: int = 20  # fewer PnP inliers: tracking is lost
    depth_refine: bool = True  # refine each PnP pose with the current frame's depth too
    max_step_m: float = 0.3  # a larger jump between consecutive frames is rejected as wrong
    keyframe_translation_m: float = 0.15
    keyframe_rotation_deg: float = 10.0
    keyframe_min_overlap: float = 0.7  # share of the keyframe's points still in view
    keyframe_min_inliers: int = 50  # fewer inliers: a new keyframe
    keyframe_min_inlier_ratio: float = 0.5  # ... or fewer than this share of the keyframe's first
    dense_refine: bool = True  # refine keyframe poses by dense RGB-D alignment
    dense_refine_all_frames: bool = True  # ... and every other frame, with the short schedule
    dense_method: str = "auto"  # "auto" | "point_to_plane" | "hybrid" | "intensity"
    dense_scale: int = 2  # dense alignment on images downsampled by this factor
    dense_iterations: tuple[int, ...] = (10, 5, 3)  # keyframes: per pyramid level, coarsest first
    dense_frame_iterations: tuple[int, ...] = (3,)  # other frames: start from PnP, finest only
    # sum the dense alignment on one thread, so that a recording gives the same trajectory and
    # map every run (dense.one_thread; TUM fr1_rpy whole job 3-5 % slower); false: all threads
    reproducible: bool = True
    dense_min_fitness: float = 0.3
    dense_max_correction_m: float = 0.05  # larger corrections of the PnP pose are rejected
    dense_max_correction_deg: float = 3.0
    dense_max_reprojection_px: float = 0.5  # ... and those that worsen the PnP inliers' RMS more
    relocalise_keyframes: int = 5  # recent keyframes tried when tracking fails
    lost_frames_new_segment: int = 15  # lost this long: start a new segment
    # a new keyframe is also located against this many before (2 -> 1: TUM fr1_rpy 0.7 CPU-s
    # less of ~14.6, ATE 1.32 -> 1.24 cm; the simulated loop unchanged)
    covisible_keyframes: int = 1
    loop_closure: bool = True
    loop_min_gap: int = 5  # keyframes between a loop's ends
    loop_candidates: int = 5
    loop_min_similarity: float = 0.6  # thumbnail correlation for an appearance candidate
    loop_search_radius_m: float = 1.0  # pose-proximity candidates
    loop_min_inliers: int = 60  # PnP inliers that verify a loop
    loop_edges: int = 1  # verified candidates kept as edges, most inliers first
    # keyframes after a loop closure before the next is searched (1: TUM fr1_rpy, which closes a
    # loop at nearly every keyframe, 1.5 CPU-s less of ~16, ATE 1.35 -> 1.45 cm; sim loop
    # 0.077 -> 0.082 % of path)
    loop_cooldown: int = 1
    loop_guided_radius_px: float = 60.0  # match around the graph's prediction first (0: never)
    loop_max_correspondence_m: float = 0.05  # line-process scale (Open3D's meaning)
    loop_prune_threshold: float = 0.25
    # Seconds the colour camera takes to read its rows (rolling shutter; 0: global shutter).
    # None: the recording's `device` metadata says (rolling_shutter_readout_s), else 0.
    rolling_shutter_readout_s: float | None = None

    def __post_init__(self) -> None:
        for name, (lo, hi) in _RANGES.items():
            value = getattr(self, name)
            _check(lo <= value <= hi, name, f"in [{lo:g}, {hi:g}]", value)
        _check(
            self.min_depth_m < self.max_depth_m, "min_depth_m", "< max_depth_m", self.min_depth_m
        )
        _check(
            self.dense_method in DENSE_METHODS,
            "dense_method",
            f"one of {DENSE_METHODS}",
            self.dense_method,
        )
        readout = self.rolling_shutter_readout_s
        _check(
            readout is None or 0.0 <= readout <= 0.1,
            "rolling_shutter_readout_s",
            "None or in [0, 0.1] s",
            readout,
        )
        _check(self.dense_scale in (1, 2, 4, 8), "dense_scale", "1, 2, 4 or 8", self.dense_scale)
        for name in ("dense_iterations", "dense_frame_iterations"):
            levels = getattr(self, name)
            _check(
                0 < len(levels) <= 5 and all(0 < i <= 100 for i in levels),
                name,
                "1 to 5 pyramid levels of 1..100 iterations",
                levels,
            )
        for name in ("keyframe_min_inliers", "loop_min_inliers"):
            _check(
                getattr(self, name) >= self.min_inliers, name, ">= min_inliers", getattr(self, name)
            )


def _check(ok: bool, name: str, expected: str, found: object) -> None:
    if not ok:
        raise ConfigError(
            f"odometry.{name} must be {expected}, found {found!r}; fix [odometry] in the config"
        )
