"""What the pipeline logs, one method per domain object: the `Logger` protocol and `NullLogger`.

Every logger is a `Logger`: `viz.rerun_log.RerunLogger` writes an `.rrd`, `NullLogger` does
nothing (`--no-viz`), and the refinement takes the same type. Methods take numpy arrays, plain
values or capture types, never `process` objects. Each method's body is the do-nothing default
(kiss-icp's StubVisualizer pattern), so a logger implements only what it shows.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal, Protocol, Self

import numpy as np
import numpy.typing as npt

from capture.recording import Intrinsics, RgbdFrame

TrajectoryKind = Literal["estimated", "ground_truth"]
MapKind = Literal["fused", "refined"]
RefineKind = Literal["planes", "outliers", "clusters", "regrown", "seams"]
FloatArray = npt.NDArray[np.floating]
IntArray = npt.NDArray[np.integer]


@dataclass(frozen=True, slots=True)
class DbscanCurves:
    """One class's adaptive-DBSCAN curves over K (paper Figs. 4-5) and the K that was chosen."""

    ks: IntArray  # (K,)
    eps_m: FloatArray  # (K,)
    min_pts: FloatArray  # (K,)
    n_clusters: IntArray  # (K,)
    chosen_k: int


class Logger(Protocol):
    """What the pipeline and the refinement log, one method per domain object."""

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def set_frame(self, index: int, *, stamp_ns: int) -> None:
        """Set the `frame` and `capture_time` timelines for what follows."""
        return None

    def set_stage(self, step: int) -> None:
        """Set the `stage` timeline (layout.STAGE_*) for what follows."""
        return None

    def log_calibration(self, color_intrinsics: Intrinsics) -> None:
        """Log the colour camera's pinhole, once, static."""
        return None

    def log_frame(self, frame: RgbdFrame, *, keyframe: bool = False) -> None:
        """Log a frame's colour and, at the depth rate or on keyframes, its raw depth."""
        return None

    def log_registered_depth(self, depth_m: FloatArray, *, keyframe: bool = False) -> None:
        """Log depth registered to the colour camera, in metres (at the depth rate)."""
        return None

    def log_pose(self, world_from_camera: FloatArray, *, keyframe: bool) -> None:
        """Log the camera pose of the current frame and mark keyframes."""
        return None

    def log_keypoints(
        self,
        xy: FloatArray,
        *,
        inliers: npt.NDArray[np.bool_],
        matched_xy: FloatArray | None = None,
    ) -> None:
        """Log keypoints in colour pixels, inliers green; optionally their matched pixels."""
        return None

    def log_tracking(self, n_inliers: int, *, status: str, event: str | None = None) -> None:
        """Log the tracking inlier count, the status when it changes, and an event."""
        return None

    def log_trajectory(
        self, kind: TrajectoryKind, stamps_ns: IntArray, positions: FloatArray
    ) -> None:
        """Log a whole trajectory (estimated or ground truth)."""
        return None

    def log_segmentation(self, labels: IntArray, *, confidence: FloatArray | None = None) -> None:
        """Log a label image (RECORDING.md ids) and its per-pixel confidence in [0, 1]."""
        return None

    def log_timing(self, stage: str, seconds: float) -> None:
        """Log the time a stage took, in seconds."""
        return None

    def log_text(self, message: str, *, level: str = "INFO") -> None:
        """Log a line of text at a level (TRACE, DEBUG, INFO, WARN, ERROR, CRITICAL)."""
        return None

    def log_map(
        self,
        kind: MapKind,
        points: FloatArray,
        *,
        colors: npt.NDArray[np.uint8] | None = None,
        labels: IntArray | None = None,
    ) -> None:
        """Log a labelled point map (fused or refined)."""
        return None

    def log_refine(
        self,
        kind: RefineKind,
        points: FloatArray,
        *,
        labels: IntArray | None = None,
        clusters: IntArray | None = None,
    ) -> None:
        """Log the points of one refinement step, coloured by cluster where given."""
        return None

    def log_dbscan_curves(self, label_name: str, *, curves: DbscanCurves) -> None:
        """Log the adaptive-DBSCAN curves over K of one class and mark the chosen K."""
        return None

    def log_metrics(self, section: str, values: Mapping[str, float]) -> None:
        """Log named scalar metrics of one section."""
        return None

    def close(self) -> None:
        """Flush and finish the output."""
        return None


class NullLogger(Logger):
    """A `Logger` that logs nothing (`--no-viz`)."""
