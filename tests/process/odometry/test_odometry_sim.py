"""The odometry on a simulated D435 recording: unaligned noisy depth, registered, then tracked."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from capture.recording import RecordingReader
from process.depth import DepthConfig, DepthProcessor
from process.odometry.config import OdometryConfig
from process.odometry.odometry import Odometry
from process.trajectory import Trajectory, ate_rmse, path_length, read_tum, write_tum


def test_simulated_recording_is_tracked_and_written_for_evo(
    sim_recording: Path, tmp_path: Path
) -> None:
    depth = DepthProcessor(DepthConfig())
    odometry: Odometry | None = None
    statuses, gt = [], []
    with RecordingReader(sim_recording) as rec:
        for frame in rec.frames():
            assert not frame.aligned  # the simulator records raw depth: registration runs
            odometry = odometry or Odometry(OdometryConfig(), intrinsics=frame.color_intrinsics)
            statuses.append(odometry.track(frame, depth.process(frame)).state.status)
            assert (
                frame.ground_truth is not None and frame.ground_truth.world_from_camera is not None
            )
            gt.append(frame.ground_truth.world_from_camera)
    assert odometry is not None
    assert statuses.count("ok") == len(statuses)
    trajectory = odometry.finish()
    stamps, poses = trajectory.stamps_ns, trajectory.poses
    truth = np.array(gt)
    assert path_length(truth) > 0.1
    assert ate_rmse(trajectory, Trajectory(stamps, truth)) < 0.01 * path_length(truth)

    path = tmp_path / "trajectory.tum"
    write_tum(path, trajectory)
    read = read_tum(path)
    assert np.array_equal(read.stamps_ns, stamps)
    np.testing.assert_allclose(read.poses, poses, atol=1e-8)
    if importlib.util.find_spec("evo") is None:
        pytest.skip("evo is not installed: the file was checked with our reader only")
    from evo.tools import file_interface  # type: ignore[import-untyped]

    evo_trajectory = file_interface.read_tum_trajectory_file(str(path))
    assert evo_trajectory.num_poses == len(stamps)
    np.testing.assert_allclose(evo_trajectory.positions_xyz, poses[:, :3, 3], atol=1e-8)
