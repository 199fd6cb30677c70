"""Known answers: relative poses between rendered views, and the real ICL-NUIM frames."""

from __future__ import annotations

import json
from functools import cache
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt
import pytest
from helpers_odometry import K_VGA, pose, render, rotation_deg, to_frame

from capture.recording import Intrinsics, RgbdFrame
from process.odometry.config import OdometryConfig
from process.odometry.odometry import Odometry
from process.trajectory import Trajectory, ate_rmse

START = pose((0.3, 0.1, -0.2), yaw_deg=20.0, pitch_deg=-5.0)
_start = cache(lambda: render(START))


def _translation(x: float, y: float, z: float) -> npt.NDArray[np.float64]:
    out = np.eye(4)
    out[:3, 3] = [x, y, z]
    return out


def _relative_estimate(
    motion: npt.NDArray[np.float64], cfg: OdometryConfig
) -> npt.NDArray[np.float64]:
    first, second = _start(), render(START @ motion)
    odometry = Odometry(cfg, intrinsics=K_VGA)
    odometry.track(to_frame(first, index=0), first.depth_m)
    result = odometry.track(to_frame(second, index=1), second.depth_m)
    assert result.state.status == "ok"
    assert result.state.n_inliers > 200
    assert result.state.inlier_mask.sum() == result.state.n_inliers
    return result.world_from_camera  # the first frame is the identity


MOTIONS = {
    "translation 5 cm sideways": _translation(0.05, 0.0, 0.0),
    "translation 8 cm forward": _translation(0.0, 0.0, 0.08),
    "rotation 3 deg yaw": pose((0.0, 0.0, 0.0), yaw_deg=3.0),
    "rotation 2 deg pitch": pose((0.0, 0.0, 0.0), pitch_deg=-2.0),
}


@pytest.mark.parametrize("name", list(MOTIONS))
def test_relative_motion_is_recovered_within_1mm_and_0_1deg(name: str) -> None:
    motion = MOTIONS[name]
    # Every frame refined densely (the default refines keyframes; this pair is not one).
    estimate = _relative_estimate(motion, OdometryConfig(dense_refine_all_frames=True))
    assert np.linalg.norm(estimate[:3, 3] - motion[:3, 3]) < 0.001
    assert rotation_deg(estimate, motion) < 0.1


def test_keyframe_path_recovers_motion_within_1mm() -> None:
    motion = _translation(0.0, 0.0, 0.08)
    cfg = OdometryConfig(keyframe_translation_m=0.05)  # the second frame becomes a keyframe
    estimate = _relative_estimate(motion, cfg)
    assert np.linalg.norm(estimate[:3, 3] - motion[:3, 3]) < 0.001
    assert rotation_deg(estimate, motion) < 0.1


def test_sparse_pnp_alone_is_within_a_few_mm() -> None:
    motion = MOTIONS["rotation 3 deg yaw"]
    estimate = _relative_estimate(motion, OdometryConfig(dense_refine=False))
    assert np.linalg.norm(estimate[:3, 3] - motion[:3, 3]) < 0.006
    assert rotation_deg(estimate, motion) < 0.1


def _icl_frames(folder: Path) -> tuple[list[RgbdFrame], npt.NDArray[np.float64]]:
    k = json.loads((folder / "camera_primesense.json").read_text())["intrinsic_matrix"]
    intr = Intrinsics(640, 480, k[0], k[4], k[6], k[7])
    frames = []
    for i in range(5):
        bgr = np.asarray(cv2.imread(str(folder / "color" / f"{i:05d}.jpg")), np.uint8)
        color = np.asarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), np.uint8)
        depth_mm = np.asarray(
            cv2.imread(str(folder / "depth" / f"{i:05d}.png"), cv2.IMREAD_UNCHANGED)
        )
        depth = depth_mm.astype(np.float32) / 1000.0
        frames.append(RgbdFrame(i, i * 33_333_333, color, depth, intr, intr, True))
    lines = (folder / "trajectory.log").read_text().split("\n")
    gt = np.array(
        [[[float(v) for v in lines[5 * i + 1 + r].split()] for r in range(4)] for i in range(5)]
    )
    return frames, gt


def test_icl_nuim_frames_track_within_3mm_ate(shared_data: Path) -> None:
    frames, gt = _icl_frames(shared_data / "icl_nuim")
    odometry = Odometry(OdometryConfig(), intrinsics=frames[0].color_intrinsics)
    results = [odometry.track(f, f.depth_m) for f in frames]
    assert [r.state.status for r in results] == ["ok"] * 5
    out = odometry.finish()
    # 9.8 cm of motion over 5 frames: the error stays at the millimetre level (a few % of it).
    assert ate_rmse(out, Trajectory(out.stamps_ns, np.asarray(gt))) < 0.003
