"""Trajectory files and metrics, checked against evo on real data and against known answers."""

from __future__ import annotations

import copy
import importlib.util
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from process.errors import ReplayError
from process.trajectory import (
    Trajectory,
    align_umeyama,
    associate,
    associate_trajectories,
    ate_rmse,
    path_length,
    read_tum,
    rpe,
    write_tum,
)

# What evo 1.38.1 reports on shared_data/tum_trajectories (fr1_xyz ground truth vs RGBD-SLAM):
# `evo_ape tum GT EST -a`, `evo_rpe tum GT EST --delta 1 --delta_unit f [-r angle_deg]`.
EVO_MATCHED = 785
EVO_ATE_SE3_M = 0.013470088850
EVO_ATE_SIM3_M = 0.013389384904
EVO_RPE_TRANS_M = 0.005764370849
EVO_RPE_ROT_DEG = 0.353613161045
EVO_PATH_GT_MATCHED_M = 8.015045624496


def _fr1(shared_data: Path) -> tuple[Trajectory, Trajectory]:
    folder = shared_data / "tum_trajectories"
    return read_tum(folder / "freiburg1_xyz-rgbdslam.txt"), read_tum(
        folder / "freiburg1_xyz-groundtruth.txt"
    )


def test_metrics_equal_evo_known_answers(shared_data: Path) -> None:
    est, gt = _fr1(shared_data)
    e, g = associate_trajectories(est, gt)
    assert len(e) == EVO_MATCHED
    assert ate_rmse(est, gt) == pytest.approx(EVO_ATE_SE3_M, abs=1e-9)
    trans, rot = rpe(est, gt)
    assert trans == pytest.approx(EVO_RPE_TRANS_M, abs=1e-9)
    assert rot == pytest.approx(EVO_RPE_ROT_DEG, abs=1e-7)
    assert path_length(g) == pytest.approx(EVO_PATH_GT_MATCHED_M, abs=1e-9)
    transform, scale = align_umeyama(e[:, :3, 3], g[:, :3, 3], with_scale=True)
    aligned = scale * e[:, :3, 3] @ transform[:3, :3].T + transform[:3, 3]
    sim3 = np.sqrt(np.mean(np.sum((aligned - g[:, :3, 3]) ** 2, axis=1)))
    assert sim3 == pytest.approx(EVO_ATE_SIM3_M, abs=1e-9)


@pytest.mark.skipif(importlib.util.find_spec("evo") is None, reason="evo is not installed")
def test_metrics_equal_evo_computed_live(shared_data: Path) -> None:
    from evo.core import metrics, sync  # type: ignore[import-untyped]
    from evo.tools import file_interface  # type: ignore[import-untyped]

    folder = shared_data / "tum_trajectories"
    ref = file_interface.read_tum_trajectory_file(str(folder / "freiburg1_xyz-groundtruth.txt"))
    est = file_interface.read_tum_trajectory_file(str(folder / "freiburg1_xyz-rgbdslam.txt"))
    ref, est = sync.associate_trajectories(ref, est, max_diff=0.01)
    aligned = copy.deepcopy(est)
    aligned.align(ref, correct_scale=False)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, aligned))
    rpe_rot = metrics.RPE(metrics.PoseRelation.rotation_angle_deg, 1, metrics.Unit.frames)
    rpe_rot.process_data((ref, est))
    ours_est, ours_gt = _fr1(shared_data)
    assert ate_rmse(ours_est, ours_gt) == pytest.approx(
        ape.get_statistic(metrics.StatisticsType.rmse), abs=1e-9
    )
    assert rpe(ours_est, ours_gt)[1] == pytest.approx(
        rpe_rot.get_statistic(metrics.StatisticsType.rmse), abs=1e-7
    )


def test_tum_round_trip_keeps_nanoseconds_and_poses(tmp_path: Path) -> None:
    stamps = [1_305_031_098_665_900_001, 1_305_031_098_699_233_334]
    poses = [np.eye(4), np.eye(4)]
    poses[1][:3, :3] = Rotation.from_euler("xyz", [10, -20, 30], degrees=True).as_matrix()
    poses[1][:3, 3] = [1.5, -2.25, 0.125]
    path = tmp_path / "trajectory.tum"
    write_tum(path, Trajectory.of(stamps, poses))
    read = read_tum(path)
    assert read.stamps_ns.tolist() == stamps
    np.testing.assert_allclose(read.poses, np.array(poses), atol=1e-8)
    assert [p.name for p in tmp_path.iterdir()] == ["trajectory.tum"]  # no temporary left behind
    line = path.read_text().splitlines()[1].split()
    assert line[0] == "1305031098.665900001" and len(line) == 8


def test_read_tum_rejects_other_files(tmp_path: Path) -> None:
    path = tmp_path / "bad.txt"
    path.write_text("0 1 2 3\n")
    with pytest.raises(ReplayError, match="8 fields"):
        read_tum(path)


def test_associate_takes_the_nearest_stamp_within_tolerance() -> None:
    a = np.array([100, 200, 300, 400])
    b = np.array([195, 108, 290, 520])
    ia, ib = associate(a, b, max_dt_ns=10)
    assert ia.tolist() == [0, 1, 2]
    assert ib.tolist() == [1, 0, 2]


def _circle(n: int, radius: float) -> np.ndarray:
    poses = np.tile(np.eye(4), (n, 1, 1))
    angles = np.linspace(0, 2 * np.pi, n, endpoint=False)
    poses[:, 0, 3] = radius * np.cos(angles)
    poses[:, 2, 3] = radius * np.sin(angles)
    return poses


def test_ate_of_a_known_perturbation() -> None:
    stamps = np.arange(16, dtype=np.int64) * 33_000_000
    gt = _circle(16, 1.0)
    est = _circle(16, 1.02)  # every position 2 cm off, radially: no rigid motion can fix that
    moved = np.eye(4)
    moved[:3, :3] = Rotation.from_euler("zyx", [40, -10, 25], degrees=True).as_matrix()
    moved[:3, 3] = [3.0, -1.0, 0.5]
    est = moved @ est  # the estimate lives in its own world frame
    truth = Trajectory(stamps, gt)
    assert ate_rmse(Trajectory(stamps, est), truth) == pytest.approx(0.02, abs=1e-9)
    assert ate_rmse(Trajectory(stamps, moved @ gt), truth) == pytest.approx(0.0, abs=1e-9)


def test_rpe_of_a_known_scale_drift() -> None:
    stamps = np.arange(10, dtype=np.int64) * 33_000_000
    gt = np.tile(np.eye(4), (10, 1, 1))
    gt[:, 0, 3] = 0.05 * np.arange(10)  # 5 cm per frame along x
    est = gt.copy()
    est[:, 0, 3] *= 1.1  # 10 % too long steps
    trans, rot = rpe(Trajectory(stamps, est), Trajectory(stamps, gt))
    assert trans == pytest.approx(0.005, abs=1e-12)
    assert rot == pytest.approx(0.0, abs=1e-9)
    assert path_length(gt) == pytest.approx(0.45)


def test_umeyama_recovers_a_similarity() -> None:
    rng = np.random.default_rng(3)
    src = rng.normal(size=(50, 3))
    rot = Rotation.from_rotvec([0.3, -0.2, 0.9]).as_matrix()
    dst = 2.5 * src @ rot.T + [1.0, 2.0, -3.0]
    transform, scale = align_umeyama(src, dst, with_scale=True)
    assert scale == pytest.approx(2.5)
    np.testing.assert_allclose(transform[:3, :3], rot, atol=1e-12)
    np.testing.assert_allclose(transform[:3, 3], [1.0, 2.0, -3.0], atol=1e-12)
