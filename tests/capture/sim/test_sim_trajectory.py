"""Handheld trajectories: 30 fps stamps, walking speed, a return to the start, inside the room."""

from __future__ import annotations

import numpy as np
import pytest

from capture.sim import build_scene, handheld_loop
from capture.sim.trajectory import SIM_EPOCH_NS, look_rotation


def test_stamps_are_integer_nanoseconds_at_the_frame_rate() -> None:
    traj = handheld_loop(build_scene(0), frames=31, fps=30.0, seed=0)
    assert traj.stamps_ns.dtype == np.int64 and traj.stamps_ns[0] == SIM_EPOCH_NS
    assert traj.stamps_ns[30] - traj.stamps_ns[0] == 1_000_000_000
    assert set(np.diff(traj.stamps_ns)) <= {33_333_333, 33_333_334}


@pytest.mark.parametrize("frames", [30, 90, 300, 900])
def test_the_walk_returns_to_its_start_at_walking_speed(frames: int) -> None:
    scene = build_scene(1)
    traj = handheld_loop(scene, frames=frames, fps=30.0, seed=1)
    positions = traj.world_from_camera[:, :3, 3]
    speed = np.linalg.norm(np.diff(positions, axis=0), axis=1) * 30.0
    assert speed.max() < 1.0  # metres per second, shake included
    assert np.linalg.norm(positions[-1] - positions[0]) < 0.05 + 0.5 / 30.0
    loop_start = np.linalg.norm(positions[0, :2] - positions[frames // 2, :2])
    assert loop_start > 0.1  # it went somewhere


def test_a_long_recording_walks_whole_laps_at_walking_speed() -> None:
    scene = build_scene(1)
    traj = handheld_loop(scene, frames=3 * 60 * 30, fps=30.0, seed=1)  # three minutes
    xy = traj.world_from_camera[:, :2, 3]
    step = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    path_m = float(step.sum())
    assert 0.35 * 180 < path_m <= 0.5 * 180 + 1.0  # whole laps at 0.35-0.5 m/s, not one slow lap
    centre = np.asarray(scene.path.center_m)
    angle = np.unwrap(np.arctan2(xy[:, 1] - centre[1], xy[:, 0] - centre[0]))
    laps = abs(angle[-1] - angle[0]) / (2 * np.pi)
    assert laps > 3 and abs(laps - round(laps)) < 0.02  # several laps, ending where it began
    assert np.linalg.norm(xy[-1] - xy[0]) < 0.05


def test_the_camera_stays_in_the_room_at_eye_height_looking_level() -> None:
    scene = build_scene(2)
    traj = handheld_loop(scene, frames=300, fps=30.0, seed=2)
    xyz = traj.world_from_camera[:, :3, 3]
    assert np.all(np.abs(xyz[:, :2]) < np.asarray(scene.room_m[:2]) / 2 - 1.0)
    assert np.all((xyz[:, 2] > 1.3) & (xyz[:, 2] < 1.7))
    down = traj.world_from_camera[:, :3, 1]  # optical y is image-down
    assert np.all(down[:, 2] < -0.8)
    rotations = traj.world_from_camera[:, :3, :3]
    np.testing.assert_allclose(
        rotations @ rotations.transpose(0, 2, 1),
        np.broadcast_to(np.eye(3), rotations.shape),
        atol=1e-9,
    )
    np.testing.assert_allclose(np.linalg.det(rotations), 1.0, atol=1e-9)


def test_look_rotation_is_an_optical_frame() -> None:
    r = look_rotation([1.0, 0.0, 0.0])
    np.testing.assert_allclose(r, [[0, 0, 1], [-1, 0, 0], [0, -1, 0]], atol=1e-12)
