"""The tracker's verdict on one frame, with the per-keypoint arrays the timeline draws."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from process.odometry.locate import Located


@dataclass(frozen=True, slots=True)
class TrackState:
    """The tracker's verdict on one frame (the Odometry turns it into a TrackResult)."""

    keyframe_id: int  # -1 before initialisation
    keyframe_from_camera: npt.NDArray[np.float64]  # (4, 4)
    is_keyframe: bool
    status: str
    n_inliers: int
    keypoints_xy: npt.NDArray[np.float32]  # (N, 2)
    inlier_mask: npt.NDArray[np.bool_]  # (N,)
    matched_keyframe_xy: npt.NDArray[np.float32]  # (N, 2), NaN where unmatched
    event: str | None = None
    trajectory_corrected: bool = False


def match_arrays(
    found: Located, xy: npt.NDArray[np.float32]
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.bool_], npt.NDArray[np.float32]]:
    """Return (keypoints, inlier mask, matched keyframe keypoint per keypoint) for the timeline."""
    inliers = np.zeros(len(xy), bool)
    inliers[found.query[found.pnp.inliers]] = True
    matched = np.full((len(xy), 2), np.nan, np.float32)
    matched[found.query] = found.keyframe.xy[found.train]
    return xy, inliers, matched
