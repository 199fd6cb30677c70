"""One-pass fusion: keyframes fused at their poses, fused again when the final poses moved."""

from __future__ import annotations

import numpy as np

from capture.recording import Intrinsics, Label
from process.fusion.keyframes import KeyframeFusion, LabelledKeyframe
from process.fusion.votes import FusionConfig

K = Intrinsics(width=160, height=120, fx=120.0, fy=120.0, cx=79.5, cy=59.5)


def _wall(keyframe_id: int) -> LabelledKeyframe:
    """A labelled wall 1.37 m in front of the camera."""
    shape = (K.height, K.width)
    return LabelledKeyframe(
        keyframe_id,
        np.full((*shape, 3), 200, np.uint8),
        np.full(shape, 1.37, np.float32),
        np.full(shape, Label.WALL, np.uint8),
        np.full(shape, 0.9, np.float32),
        K,
    )


def _pose(x_m: float) -> np.ndarray:
    pose = np.eye(4)
    pose[0, 3] = x_m
    return pose


def test_unmoved_keyframes_keep_the_map_fused_as_they_came() -> None:
    fusion = KeyframeFusion(FusionConfig(min_views=1))
    for kf in range(3):
        fusion.add(_wall(kf), world_from_camera=_pose(0.0))
    cloud = fusion.cloud({kf: _pose(0.005) for kf in range(3)})  # 5 mm: under half a voxel
    fusion.close()
    assert not fusion.refused
    assert len(cloud) > 0 and np.all(cloud.labels == Label.WALL)


def test_moved_keyframes_are_fused_again_at_their_final_poses() -> None:
    fusion = KeyframeFusion(FusionConfig(min_views=1))
    for kf in range(3):
        fusion.add(_wall(kf), world_from_camera=_pose(0.0))
    before = fusion.cloud({kf: _pose(0.0) for kf in range(3)}).points.mean(axis=0)
    after = fusion.cloud({kf: _pose(1.0) for kf in range(3)})  # a loop closure moved them 1 m
    fusion.close()
    assert fusion.refused
    np.testing.assert_allclose(after.points.mean(axis=0) - before, [1.0, 0.0, 0.0], atol=0.02)
    assert np.all(after.labels == Label.WALL)  # labels survive the round trip through the files
    assert np.abs(after.colors.astype(int) - 200).max() <= 2  # JPEG keeps the colour


def test_a_rebuild_gives_each_keyframe_back_its_own_depth_and_labels() -> None:
    """Keyframes of different depth and label, kept in one file, come back each to its own."""
    kinds = [(1.01, Label.WALL), (1.61, Label.CHAIR), (2.21, Label.TABLE)]
    fusion = KeyframeFusion(FusionConfig(min_views=1))
    for kf, (depth, label) in enumerate(kinds):
        wall = _wall(kf)
        fusion.add(
            LabelledKeyframe(
                kf,
                wall.color,
                np.full_like(wall.depth_m, depth),
                np.full_like(wall.labels, label),
                wall.confidence,
                K,
            ),
            world_from_camera=_pose(0.0),
        )
    moved = {kf: _pose(3.0 * kf) for kf in range(3)}  # 3 m apart: the maps do not overlap
    cloud = fusion.cloud(moved)
    fusion.close()
    assert fusion.refused
    for kf, (depth, label) in enumerate(kinds):
        near = np.abs(cloud.points[:, 0] - 3.0 * kf) < 1.4
        assert near.sum() > 100
        assert np.all(cloud.labels[near] == label)
        assert abs(float(np.median(cloud.points[near, 2])) - depth) < 0.02


def test_spilled_labels_cast_no_vote_in_the_rebuilt_map_either() -> None:
    """A chair whose label spills onto the wall behind it: the rebuild agrees with one pass."""
    from process.fusion.votes import Fusion

    shape = (K.height, K.width)
    depth = np.full(shape, 2.51, np.float32)  # the wall
    labels = np.full(shape, Label.WALL, np.uint8)
    labels[30:90, 40:120] = Label.CHAIR  # the chair's label ...
    depth[30:90, 40:100] = 1.21  # ... but the chair ends at column 100: the rest is spill
    kf = LabelledKeyframe(0, np.full((*shape, 3), 90, np.uint8), depth, labels,
                          np.full(shape, 0.9, np.float32), K)  # fmt: skip
    cfg = FusionConfig(min_views=1, pixel_stride=1)
    direct = Fusion(cfg)
    direct.integrate(
        kf.color, kf.depth_m, kf.labels, kf.confidence, intrinsics=K, world_from_camera=_pose(0.5)
    )
    expected = direct.cloud()
    fusion = KeyframeFusion(cfg)
    fusion.add(kf, world_from_camera=_pose(0.0))
    rebuilt = fusion.cloud({0: _pose(0.5)})
    fusion.close()
    assert fusion.refused
    on_wall = np.abs(expected.points[:, 2] - 2.51) < 0.03
    assert on_wall.sum() > 100 and not np.any(expected.labels[on_wall] == Label.CHAIR)
    a, b = np.lexsort(rebuilt.points.T), np.lexsort(expected.points.T)  # Open3D's order varies
    np.testing.assert_allclose(rebuilt.points[a], expected.points[b], atol=1e-5)
    np.testing.assert_array_equal(rebuilt.labels[a], expected.labels[b])
