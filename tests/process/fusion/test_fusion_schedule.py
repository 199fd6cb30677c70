"""Which keyframes are segmented, and how points of skipped keyframes still get labels."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from capture.recording import Intrinsics, Label
from process.fusion.keyframes import KeyframeFusion, LabelledKeyframe
from process.fusion.schedule import SegmentationSchedule
from process.fusion.votes import FusionConfig

K = Intrinsics(width=640, height=480, fx=480.0, fy=480.0, cx=319.5, cy=239.5)  # 67 x 53 deg


def _turned(yaw_deg: float) -> np.ndarray:
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_euler("y", yaw_deg, degrees=True).as_matrix()
    return pose


def _wall_depth(yaw_deg: float) -> np.ndarray:
    """Depth of the world plane z = 2.03 m (inside one row of 8 cm cells), camera turned by yaw."""
    v, u = np.mgrid[0 : K.height, 0 : K.width].astype(np.float64)
    rays = np.stack([(u - K.cx) / K.fx, (v - K.cy) / K.fy, np.ones_like(u)], axis=-1)
    world_z = rays @ _turned(yaw_deg)[:3, :3].T[:, 2]
    return np.asarray(2.03 / world_z, np.float32)


WALL = _wall_depth(0.0)


def test_a_keyframe_is_segmented_when_it_sees_enough_new_surface() -> None:
    schedule = SegmentationSchedule(0.15)
    due = [
        schedule.due(_wall_depth(y), intrinsics=K, world_from_camera=_turned(y))
        for y in range(0, 21, 4)
    ]
    # 0 deg: all new; a 4 degree turn shows ~10 % new cells, 8 degrees ~20 %
    assert due == [True, False, True, False, True, False]
    assert not schedule.due(_wall_depth(8), intrinsics=K, world_from_camera=_turned(8.0))  # seen
    assert not schedule.due(np.zeros_like(WALL), intrinsics=K, world_from_camera=_turned(90.0))
    every = SegmentationSchedule(0.0)
    assert all(every.due(WALL, intrinsics=K, world_from_camera=_turned(0.0)) for _ in range(3))


def test_a_due_keyframe_that_was_left_out_leaves_its_view_uncovered() -> None:
    schedule = SegmentationSchedule(0.1)
    first = schedule.new_cells(WALL, intrinsics=K, world_from_camera=_turned(0.0))
    assert first is not None  # due, but (following) the segmentation had no room for it
    again = schedule.new_cells(WALL, intrinsics=K, world_from_camera=_turned(0.0))
    assert again is not None and np.array_equal(first, again)
    schedule.cover(again)
    assert schedule.new_cells(WALL, intrinsics=K, world_from_camera=_turned(0.0)) is None


def _keyframe(kf: int, yaw_deg: float, label: int, confidence: float) -> LabelledKeyframe:
    shape = (K.height, K.width)
    return LabelledKeyframe(
        kf,
        np.full((*shape, 3), 120, np.uint8),
        _wall_depth(yaw_deg),
        np.full(shape, label, np.uint8),
        np.full(shape, confidence, np.float32),
        K,
    )


def test_points_only_a_skipped_keyframe_saw_take_the_nearest_label_within_reach() -> None:
    poses = {0: _turned(0.0), 1: _turned(8.0)}  # the second sees ~40 cm more wall to the right
    for reach, expect_unlabelled in ((4.0, False), (0.0, True)):
        fusion = KeyframeFusion(FusionConfig(min_views=1, label_reach_voxels=reach))
        fusion.add(_keyframe(0, 0.0, Label.WALL, 0.9), world_from_camera=poses[0])
        fusion.add(_keyframe(1, 8.0, 0, 0.0), world_from_camera=poses[1])  # geometry only
        cloud = fusion.cloud(poses)
        fusion.close()
        x_first = 2.0 * (K.width - 1 - K.cx) / K.fx  # the first view's right edge on the wall
        beyond = cloud.points[:, 0] > x_first + 0.12  # more than the reach past it
        near = (cloud.points[:, 0] > x_first + 0.01) & (cloud.points[:, 0] < x_first + 0.06)
        assert beyond.any() and near.any()
        assert np.all(cloud.labels[beyond] == 0)  # no vote within reach: stays unlabelled
        assert np.all(cloud.labels[near] == (0 if expect_unlabelled else Label.WALL))
