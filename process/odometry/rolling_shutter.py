"""Rolling shutter: each image row is read at its own time; the camera moves in between.

A rolling-shutter sensor reads its rows one after another over the readout time; a camera that
turns at 180 deg/s (TUM fr1_rpy) turns about 1.8 deg while a Kinect v1 reads half its rows, which
shears the image by ~16 px. The odometry keeps one pose per frame, the pose at the middle row's
time, and models the others with the camera's velocity (the constant-velocity model of the
tracker): the camera at time tau after the middle row is world_from_mid @ exp(tau * twist), twist
= (angular rate, velocity) in the camera's frame. Row v is read at tau = readout * (v - (h - 1) / 2)
/ h. Observations are moved to where a global-shutter camera at the middle row's time would see
them (first order in the pose error, exact in the readout up to the third order of the small
rotation), so PnP, the depth refinement and the pose graph stay global-shutter.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

from capture.recording import Intrinsics
from process.errors import ConfigError
from process.geometry import project

NO_MOTION: npt.NDArray[np.float64] = np.zeros(6)
READOUT_KEY = "rolling_shutter_readout_s"  # in the recording's `device` metadata record


def recorded_readout_s(metadata: Mapping[str, Mapping[str, str]]) -> float | None:
    """Return the colour camera's readout time from a recording's metadata, None if unsaid."""
    text = metadata.get("device", {}).get(READOUT_KEY)
    if text is None:
        return None
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not 0.0 <= value <= 0.1:
        raise ConfigError(
            f"the recording's device metadata {READOUT_KEY} must be seconds in [0, 0.1],"
            f" found {text!r}; set odometry.rolling_shutter_readout_s in the config to override"
        )
    return value


@dataclass(frozen=True, slots=True)
class RollingShutter:
    """A pinhole camera whose rows are read over `readout_s` seconds, top to bottom."""

    intrinsics: Intrinsics
    readout_s: float

    def row_time(self, v: npt.NDArray[np.floating[Any]]) -> npt.NDArray[np.float64]:
        """Return the time (s) at which image row v is read, relative to the middle row."""
        h = self.intrinsics.height
        return self.readout_s * (np.asarray(v, np.float64) - 0.5 * (h - 1)) / h

    def observe(
        self, points: npt.NDArray[np.float64], twist: npt.NDArray[np.float64]
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """Return where the rolling shutter sees points given in the middle row's camera frame.

        Args:
            points: (N, 3) in the camera frame at the middle row's time, z > 0.
            twist: (6,) angular rate (rad/s) and velocity (m/s) in the camera frame.

        Returns:
            (N, 2) pixels and (N,) depths at the times their rows are read.
        """
        p = np.asarray(points, np.float64)
        seen = p
        for _ in range(3):  # the row depends on the time, weakly: each step gains ~10x
            tau = self.row_time(project(seen, self.intrinsics)[:, 1])
            seen = _move(p, -tau[:, None] * twist[None, :])
        return project(seen, self.intrinsics), seen[:, 2]

    def to_middle(
        self,
        points: npt.NDArray[np.float32],
        rows: npt.NDArray[np.float32],
        twist: npt.NDArray[np.float64],
    ) -> npt.NDArray[np.float32]:
        """Return points measured at their rows' times in the middle row's camera frame.

        Args:
            points: (N, 3) camera-frame points, each measured when its row (N,) was read.
            rows: (N,) the image row each point was seen in.
            twist: (6,) the camera's twist, as in `observe`.
        """
        tau = self.row_time(rows)
        moved = _move(np.asarray(points, np.float64), tau[:, None] * twist[None, :])
        return moved.astype(np.float32)


def twist_of(
    previous_from_current: npt.NDArray[np.float64], dt_s: float
) -> npt.NDArray[np.float64]:
    """Return the constant twist (rad/s, m/s; camera frame) that makes a motion in dt_s seconds."""
    if dt_s <= 0:
        return NO_MOTION.copy()
    rotvec = Rotation.from_matrix(previous_from_current[:3, :3]).as_rotvec()
    return np.concatenate([rotvec, previous_from_current[:3, 3]]) / dt_s


def _move(p: npt.NDArray[np.float64], a: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Return exp(a_i) p_i for small twists a (N, 6): rotation to second order, then translation."""
    w = a[:, :3]
    wp = np.cross(w, p)
    return p + wp + 0.5 * np.cross(w, wp) + a[:, 3:]
