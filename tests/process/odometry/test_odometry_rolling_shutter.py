"""Known answers for the rolling-shutter model: a synthetic shutter, and the readout's origin."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest
from scipy.spatial.transform import Rotation

from capture.recording import Intrinsics
from process.errors import ConfigError
from process.odometry.config import OdometryConfig
from process.odometry.features import FeatureExtractor, Keyframe
from process.odometry.locate import Locator
from process.odometry.odometry import Odometry
from process.odometry.rolling_shutter import RollingShutter, recorded_readout_s, twist_of

K = Intrinsics(640, 480, 525.0, 525.0, 319.5, 239.5)
READOUT_S = 0.028
# A fast pan and tilt (TUM fr1_rpy turns up to ~3 rad/s) with a slow drift.
TWIST = np.array([0.8, 3.0, 0.4, 0.05, -0.02, 0.03])


def _pose(
    rotvec: tuple[float, float, float], t: tuple[float, float, float]
) -> npt.NDArray[np.float64]:
    out = np.eye(4)
    out[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    out[:3, 3] = t
    return out


def _exact_rolling_shutter(
    points: npt.NDArray[np.float64], camera_from_points: npt.NDArray[np.float64]
) -> npt.NDArray[np.float32]:
    """Render pixels the exact way: each point seen at its own row's time (exact exponential)."""
    q = points @ camera_from_points[:3, :3].T + camera_from_points[:3, 3]
    v = K.fy * q[:, 1] / q[:, 2] + K.cy
    for _ in range(20):  # fixed point of row -> time -> row
        tau = READOUT_S * (v - 0.5 * (K.height - 1)) / K.height
        rot = Rotation.from_rotvec(-tau[:, None] * TWIST[None, :3]).as_matrix()
        seen = np.einsum("nij,nj->ni", rot, q) - tau[:, None] * TWIST[None, 3:]
        v = K.fy * seen[:, 1] / seen[:, 2] + K.cy
    return np.stack([K.fx * seen[:, 0] / seen[:, 2] + K.cx, v], axis=1).astype(np.float32)


def _scene(rng: np.random.Generator) -> tuple[Keyframe, npt.NDArray[np.uint8]]:
    """Return a keyframe at the origin seeing 600 points 1.5-4 m away, and their descriptors."""
    n = 600
    xy = rng.uniform([20, 20], [620, 460], size=(n, 2))
    z = rng.uniform(1.5, 4.0, n)
    points = np.stack([(xy[:, 0] - K.cx) / K.fx * z, (xy[:, 1] - K.cy) / K.fy * z, z], 1)
    descriptors = rng.integers(0, 256, size=(n, 32), dtype=np.uint8)
    kf = Keyframe(
        0,
        0,
        0,
        0,
        xy.astype(np.float32),
        descriptors,
        points.astype(np.float32),
        np.zeros(768, np.float32),
    )
    return kf, descriptors


def _pose_error(a: npt.NDArray[np.float64], b: npt.NDArray[np.float64]) -> tuple[float, float]:
    delta = np.linalg.inv(a) @ b
    return float(np.linalg.norm(delta[:3, 3])), float(
        np.degrees(Rotation.from_matrix(delta[:3, :3]).magnitude())
    )


def test_the_corrected_solver_recovers_the_pose_the_global_shutter_one_misses() -> None:
    kf, descriptors = _scene(np.random.default_rng(3))
    truth = _pose((0.01, 0.08, -0.02), (0.04, -0.01, 0.02))  # camera_from_keyframe, middle row
    xy = _exact_rolling_shutter(kf.points.astype(np.float64), truth)
    prior = _pose((0.012, 0.075, -0.02), (0.035, -0.01, 0.02))  # ~0.3 deg off
    extractor = FeatureExtractor(
        K,
        n_features=1000,
        scale_factor=1.2,
        levels=8,
        fast_threshold=20,
        min_depth_m=0.2,
        max_depth_m=6.0,
    )
    no_depth = np.zeros((K.height, K.width), np.float32)
    errors = {}
    for name, shutter in (("rolling", RollingShutter(K, READOUT_S)), ("global", None)):
        locator = Locator(OdometryConfig(), extractor=extractor, shutter=shutter)
        found = locator.locate(kf, xy, descriptors, no_depth, prior=prior, twist=TWIST)
        assert not isinstance(found, str), found
        errors[name] = _pose_error(found.pnp.camera_from_reference, truth)
    moved_m, turned_deg = errors["rolling"]
    assert moved_m < 0.001 and turned_deg < 0.02  # exact up to the model's small-angle terms
    off_m, _ = errors["global"]
    assert off_m > 10 * moved_m and off_m > 0.005  # the shear biases a global-shutter pose


def test_observe_and_to_middle_are_inverse_and_match_the_exact_rendering() -> None:
    kf, _ = _scene(np.random.default_rng(5))
    shutter = RollingShutter(K, READOUT_S)
    points = kf.points.astype(np.float64)
    seen, depth = shutter.observe(points, TWIST)
    exact = _exact_rolling_shutter(points, np.eye(4))
    assert np.max(np.abs(seen - exact)) < 0.05  # px, at up to ~25 px of shear
    at_row_time = np.stack([(seen[:, 0] - K.cx) / K.fx, (seen[:, 1] - K.cy) / K.fy], 1)
    lifted = np.concatenate([at_row_time * depth[:, None], depth[:, None]], 1)
    back = shutter.to_middle(lifted.astype(np.float32), seen[:, 1].astype(np.float32), TWIST)
    assert np.max(np.abs(back - points)) < 2e-4  # m


def test_twist_of_a_motion_is_its_rate() -> None:
    motion = _pose((0.0, 0.1, 0.0), (0.01, 0.0, 0.0))
    np.testing.assert_allclose(twist_of(motion, 0.05), [0, 2.0, 0, 0.2, 0, 0], atol=1e-12)
    assert not np.any(twist_of(motion, 0.0))


def test_the_readout_comes_from_the_config_else_the_recording_else_zero() -> None:
    assert recorded_readout_s({"device": {"rolling_shutter_readout_s": "0.028"}}) == 0.028
    assert recorded_readout_s({"device": {"name": "x"}}) is None
    assert recorded_readout_s({}) is None
    for bad in ("fast", "0.5", "-0.01"):
        with pytest.raises(ConfigError, match=r"rolling_shutter_readout_s.*found"):
            recorded_readout_s({"device": {"rolling_shutter_readout_s": bad}})
    assert Odometry(OdometryConfig(), intrinsics=K, recording_readout_s=0.02).readout_s == 0.02
    assert Odometry(OdometryConfig(), intrinsics=K).readout_s == 0.0
    cfg = OdometryConfig(rolling_shutter_readout_s=0.0)
    assert Odometry(cfg, intrinsics=K, recording_readout_s=0.02).readout_s == 0.0
    with pytest.raises(ConfigError, match="rolling_shutter_readout_s"):
        OdometryConfig(rolling_shutter_readout_s=0.5)
