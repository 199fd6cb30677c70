"""Frozen frames, missing depth, textureless stretches: tracking loss is reported, never a crash."""

from __future__ import annotations

import dataclasses
from functools import cache

import numpy as np
import pytest
from helpers_odometry import K_QVGA, RenderedFrame, pose, render, to_frame, track_all

from capture.recording import RgbdFrame
from process.errors import ConfigError
from process.odometry.config import OdometryConfig
from process.odometry.odometry import Odometry, TrackResult


@cache
def _view(i: int) -> RenderedFrame:
    """Views 0-5 walk sideways 3 cm a step; view 9 looks the other way."""
    if i == 9:
        return render(pose((0.2, 0.0, 0.4), yaw_deg=200.0), K_QVGA)
    return render(pose((0.03 * i, 0.0, 0.0), yaw_deg=10.0 + 2.0 * i), K_QVGA)


def _frames(views: list[int | str]) -> list[RgbdFrame]:
    """Frames of views; "grey" is a textureless frame, "nodepth:i" view i without depth."""
    out = []
    for index, view in enumerate(views):
        if view == "grey":
            rendered = _view(0)
            frame = to_frame(rendered, index=index, intr=K_QVGA)
            frame = dataclasses.replace(frame, color=np.full_like(rendered.color, 100 + index))
        elif isinstance(view, str):
            rendered = _view(int(view.split(":")[1]))
            frame = to_frame(rendered, index=index, intr=K_QVGA)
            frame = dataclasses.replace(frame, depth_m=np.zeros_like(rendered.depth_m))
        else:
            frame = to_frame(_view(view), index=index, intr=K_QVGA)
        out.append(frame)
    return out


def _run(views: list[int | str], **cfg: object) -> tuple[Odometry, list[TrackResult]]:
    # At 320x240 the dense alignment runs at full size (at half size it would be 160x120).
    settings = {"min_inliers": 15, "dense_scale": 1, **cfg}
    odometry = Odometry(OdometryConfig(**settings), intrinsics=K_QVGA)  # type: ignore[arg-type]
    return odometry, track_all(odometry, _frames(views))


def _position_error(result: TrackResult, view: int) -> float:
    truth = np.linalg.inv(_view(0).world_from_camera) @ _view(view).world_from_camera
    return float(np.linalg.norm(result.world_from_camera[:3, 3] - truth[:3, 3]))


def test_frozen_frames_hold_the_pose_and_say_so() -> None:
    odometry, results = _run([0, 1, 1, 1, 2])
    assert [r.state.status for r in results] == ["ok", "ok", "frozen", "frozen", "ok"]
    assert results[2].state.event is not None and "frozen" in results[2].state.event
    assert results[3].state.event is None  # one event per frozen stretch
    np.testing.assert_array_equal(results[2].world_from_camera, results[1].world_from_camera)
    assert _position_error(results[4], 2) < 0.01
    assert len(odometry.finish()) == 5


def test_no_depth_at_the_start_delays_initialisation() -> None:
    _, results = _run(["nodepth:0", 1, 2])
    assert results[0].state.status == "lost"
    assert results[0].state.event is not None and "cannot initialise" in results[0].state.event
    assert results[1].state.status == "ok" and results[1].is_keyframe
    assert results[1].state.event is not None and "initialised at frame 1" in results[1].state.event


def test_a_frame_without_depth_is_still_tracked() -> None:
    _, results = _run([0, "nodepth:2", 3], keyframe_translation_m=0.02)
    assert [r.state.status for r in results] == ["ok", "ok", "ok"]
    assert not results[1].is_keyframe  # no depth: it cannot be a keyframe
    assert _position_error(results[1], 2) < 0.01
    assert _position_error(results[2], 3) < 0.01


def test_textureless_stretch_is_lost_then_relocalised() -> None:
    _, results = _run([0, 1, "grey", "grey", "grey", 2, 3])
    statuses = [r.state.status for r in results]
    assert statuses == ["ok", "ok", "lost", "lost", "lost", "relocalised", "ok"]
    assert (
        results[2].state.event is not None and "tracking lost at frame 2" in results[2].state.event
    )
    assert results[3].state.event is None
    assert results[5].state.event is not None and "after 3 lost frame(s)" in results[5].state.event
    assert _position_error(results[5], 2) < 0.01
    assert len(results[2].state.keypoints_xy) == 0 or results[2].state.n_inliers == 0


def test_long_loss_starts_a_new_segment() -> None:
    odometry, results = _run([0, 1, "grey", "grey", 9, 9, 1], lost_frames_new_segment=3)
    statuses = [r.state.status for r in results]
    assert statuses[:5] == ["ok", "ok", "lost", "lost", "new_segment"]
    assert (
        results[4].is_keyframe
        and results[4].state.event is not None
        and "new segment 1" in results[4].state.event
    )
    # The new segment starts where the camera was last seen.
    np.testing.assert_allclose(
        results[4].world_from_camera, results[1].world_from_camera, atol=1e-9
    )
    assert statuses[6] == "relocalised"  # back to a view of the first segment
    trajectory = odometry.finish()
    assert trajectory.stamps_ns.tolist() == [r.stamp_ns for r in results]


def test_only_the_reference_keyframe_keeps_images() -> None:
    odometry, results = _run([0, 1, 2, 3, 4, 5], keyframe_translation_m=0.02)
    assert odometry.n_keyframes >= 3
    assert sum(k.dense is not None for k in odometry.keyframes) == 1
    assert sum(r.is_keyframe for r in results) == odometry.n_keyframes


@pytest.mark.parametrize(
    "kwargs",
    [
        {"n_features": 10},
        {"min_depth_m": 3.0, "max_depth_m": 1.0},
        {"dense_method": "magic"},
        {"keyframe_min_overlap": 1.5},
        {"dense_iterations": ()},
        {"loop_min_inliers": 5},
    ],
)
def test_config_rejects_bad_values(kwargs: dict[str, object]) -> None:
    with pytest.raises(ConfigError, match="odometry"):
        OdometryConfig(**kwargs)  # type: ignore[arg-type]
