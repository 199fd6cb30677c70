"""Undistorting a Kinect v1 frame once, and the reprojection check on dense corrections."""

from __future__ import annotations

import cv2
import numpy as np

from capture.recording import Intrinsics
from process.odometry.keyframes import FeatureCheck
from process.odometry.undistort import Undistorter

# TUM freiburg 1 (the benchmark's published calibration).
FR1 = Intrinsics(
    640, 480, 517.3, 516.5, 318.6, 255.3, coeffs=(0.2624, -0.9531, -0.0054, 0.0026, 1.1633)
)


def _pinhole_of(raw: np.ndarray) -> np.ndarray:
    """Return where OpenCV's own model puts raw (distorted) pixels in the pinhole image."""
    und = cv2.undistortPoints(
        raw.reshape(-1, 1, 2).astype(np.float64),
        FR1.matrix,
        np.asarray(FR1.coeffs),
        P=FR1.matrix,
    )
    return np.asarray(und, np.float64).reshape(-1, 2)


def test_keypoints_map_back_to_the_raw_image() -> None:
    raw = np.array([[40.0, 30.0], [600.0, 450.0], [320.0, 240.0], [100.0, 400.0]], np.float32)
    pinhole = _pinhole_of(raw).astype(np.float32)
    back = Undistorter(FR1).to_distorted(np.vstack([pinhole, [[np.nan, np.nan]]]))
    np.testing.assert_allclose(back[:4], raw, atol=0.05)
    assert np.all(np.isnan(back[4]))
    # The corners move by many pixels: undistortion is not a rounding matter here.
    assert np.linalg.norm(pinhole[0] - raw[0]) > 10


def test_a_raw_dot_lands_where_the_pinhole_camera_sees_it() -> None:
    raw = np.array([[80.0, 60.0]])
    gray = np.zeros((480, 640), np.uint8)
    depth = np.zeros((480, 640), np.float32)
    gray[58:63, 78:83] = 255
    depth[58:63, 78:83] = 1.5
    undistorter = Undistorter(FR1)
    expected = _pinhole_of(raw)[0]
    ys, xs = np.nonzero(undistorter.gray(gray) > 128)
    assert abs(xs.mean() - expected[0]) < 1.0 and abs(ys.mean() - expected[1]) < 1.0
    moved = undistorter.depth(depth)
    assert set(np.unique(moved)) <= {0.0, np.float32(1.5)}  # nearest: no blended depths
    ys, xs = np.nonzero(moved)
    assert abs(xs.mean() - expected[0]) < 1.5 and abs(ys.mean() - expected[1]) < 1.5
    assert undistorter.pinhole.coeffs == (0.0, 0.0, 0.0, 0.0, 0.0)


def test_feature_check_measures_reprojection_in_pixels() -> None:
    rng = np.random.default_rng(0)
    points = np.column_stack([rng.uniform(-1, 1, (50, 2)), np.ones(50)]).astype(np.float32)
    check = FeatureCheck(points, points[:, :2].copy(), 500.0)
    assert check.rms_px(np.eye(4)) < 1e-9
    moved = np.eye(4)
    moved[0, 3] = 0.01  # the camera 1 cm to the right: points 1 m away shift by f x 0.01
    assert abs(check.rms_px(moved) - 5.0) < 1e-4
