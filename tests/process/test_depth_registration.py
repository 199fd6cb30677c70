"""Depth registration against librealsense's own rs.align, and its geometry on known scenes."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest
from helpers_odometry import rs_align
from scipy.spatial.transform import Rotation

from capture.recording import Extrinsics, Intrinsics, RgbdFrame
from process.depth import DepthConfig, DepthProcessor, register_depth
from process.errors import StageError

# D435-like: wide-angle depth and narrower colour at 640x480, 15 mm apart, a slight rotation.
DEPTH_K = Intrinsics(640, 480, 385.0, 385.0, 321.0, 239.0)
COLOR_K = Intrinsics(640, 480, 615.0, 615.0, 320.0, 240.0)
ROTATION = Rotation.from_euler("xyz", [0.05, -0.08, 0.03], degrees=True).as_matrix()
TRANSLATION = np.array([0.015, 0.0001, 0.0003])


def _color_from_depth() -> npt.NDArray[np.float64]:
    out = np.eye(4)
    out[:3, :3] = ROTATION
    out[:3, 3] = TRANSLATION
    return out


def _scene_mm() -> npt.NDArray[np.uint16]:
    """A wall at 2 m with a box at 0.6 m in front of it and a hole (no depth) on the left."""
    rng = np.random.default_rng(7)
    depth = (2000 + rng.integers(-30, 30, (480, 640))).astype(np.uint16)
    depth[150:300, 200:350] = 600
    depth[:, :40] = 0
    depth[400:, 300:] = 0
    return depth


def test_registration_matches_librealsense_align() -> None:
    depth_mm = _scene_mm()
    pytest.importorskip("pyrealsense2")
    aligned = rs_align(
        depth_mm, depth_k=DEPTH_K, color_k=COLOR_K, color_from_depth=_color_from_depth()
    )
    theirs = aligned.astype(np.float32) / 1000.0
    ours = register_depth(
        depth_mm.astype(np.float32) / 1000.0,
        depth_intrinsics=DEPTH_K,
        color_intrinsics=COLOR_K,
        color_from_depth=_color_from_depth(),
    )
    assert np.array_equal(ours > 0, theirs > 0)  # the same pixels valid
    both = (ours > 0) & (theirs > 0)
    assert both.mean() > 0.8
    assert np.mean(np.abs(ours[both] - theirs[both]) <= 0.001) >= 0.99


def test_nearer_surface_wins_and_holes_stay_holes() -> None:
    depth = np.full((480, 640), 2.0, np.float32)
    depth[200:280, 300:340] = 0.5  # a near box: its parallax shift covers wall pixels
    depth[:, 420:470] = 0.0  # a stripe without depth
    out = register_depth(
        depth,
        depth_intrinsics=DEPTH_K,
        color_intrinsics=COLOR_K,
        color_from_depth=_color_from_depth(),
    )
    values = np.unique(np.round(out[out > 0], 2))
    assert set(values.tolist()) <= {0.5, 2.0}  # nothing interpolated between surfaces
    # The box centre seen from the colour camera: x = fx * X / Z + cx with X from depth pixel 320.
    x_box = (320 - DEPTH_K.cx) / DEPTH_K.fx * 0.5 + TRANSLATION[0]
    u = round(COLOR_K.fx * x_box / 0.5 + COLOR_K.cx)
    assert out[240, u] == pytest.approx(0.5)
    # Around it only the box: the wall it hides from the colour camera does not bleed through.
    assert np.all(out[230:250, u - 5 : u + 5] == pytest.approx(0.5))
    # The stripe without depth stays empty in the colour image (3 px margin for the rotation).
    edges = [((c - 0.5 - DEPTH_K.cx) / DEPTH_K.fx * 2.0 + TRANSLATION[0]) / 2.0 for c in (420, 470)]
    u0, u1 = (round(COLOR_K.fx * x + COLOR_K.cx) for x in edges)
    assert u1 - u0 > 70
    assert np.all(out[:, u0 + 3 : u1 - 3] == 0)
    assert np.all(out[:, u0 - 8 : u0 - 3] > 0) and np.all(out[:, u1 + 3 : u1 + 8] > 0)


def test_color_z_back_projects_onto_the_true_plane() -> None:
    # A tilted plane n . p = d in the depth camera, rendered exactly into a depth image.
    normal = np.array([0.2, -0.1, 1.0])
    normal /= np.linalg.norm(normal)
    u, v = np.meshgrid(np.arange(640.0), np.arange(480.0))
    rays = np.stack(
        [(u - DEPTH_K.cx) / DEPTH_K.fx, (v - DEPTH_K.cy) / DEPTH_K.fy, np.ones_like(u)], -1
    )
    depth = (1.8 / (rays @ normal)).astype(np.float32)
    transform = _color_from_depth()
    out = register_depth(
        depth,
        depth_intrinsics=DEPTH_K,
        color_intrinsics=COLOR_K,
        color_from_depth=transform,
        z_frame="color",
    )
    vv, uu = np.nonzero(out > 0)
    z = out[vv, uu].astype(np.float64)
    pts = np.stack([(uu - COLOR_K.cx) / COLOR_K.fx * z, (vv - COLOR_K.cy) / COLOR_K.fy * z, z], 1)
    in_depth = (pts - transform[:3, 3]) @ transform[:3, :3]  # back into the depth camera
    distance = np.abs(in_depth @ normal - 1.8)
    # Each colour pixel holds its depth pixel's centre z: within a pixel footprint of the plane.
    assert np.percentile(distance, 99) < 0.004
    assert len(z) > 0.9 * 640 * 480


def _frame(
    depth_m: npt.NDArray[np.float32], *, aligned: bool, extrinsics: Extrinsics | None
) -> RgbdFrame:
    return RgbdFrame(
        index=0,
        stamp_ns=0,
        color=np.zeros((480, 640, 3), np.uint8),
        depth_m=depth_m,
        color_intrinsics=COLOR_K,
        depth_intrinsics=COLOR_K if aligned else DEPTH_K,
        aligned=aligned,
        depth_to_color=extrinsics,
    )


def test_processor_clips_range_of_aligned_depth() -> None:
    depth = np.full((480, 640), 2.0, np.float32)
    depth[:10] = 12.0
    depth[10:20] = 0.05
    out = DepthProcessor(DepthConfig(min_depth_m=0.1, max_depth_m=10.0)).process(
        _frame(depth, aligned=True, extrinsics=None)
    )
    assert np.all(out[:20] == 0) and np.all(out[20:] == 2.0)


def test_processor_needs_extrinsics_for_unaligned_depth() -> None:
    with pytest.raises(StageError, match="extrinsics"):
        DepthProcessor(DepthConfig()).process(
            _frame(np.ones((480, 640), np.float32), aligned=False, extrinsics=None)
        )


def test_hole_filling_fills_small_holes_only() -> None:
    depth = np.full((480, 640), 2.0, np.float32)
    depth[100, 100] = 0.0  # a one-pixel hole
    depth[200:260, 200:260] = 0.0  # a large hole
    cfg = DepthConfig(hole_filling=True, hole_filling_px=1)
    out = DepthProcessor(cfg).process(_frame(depth, aligned=True, extrinsics=None))
    assert out[100, 100] == 2.0
    assert np.all(out[202:258, 202:258] == 0.0)


def test_smoothing_reduces_noise_and_keeps_edges() -> None:
    rng = np.random.default_rng(0)
    depth = np.full((480, 640), 2.0, np.float32)
    depth[:, 320:] = 3.0
    noisy = (depth + rng.normal(0, 0.005, depth.shape)).astype(np.float32)
    cfg = DepthConfig(smoothing=True, smoothing_sigma_m=0.03)
    out = DepthProcessor(cfg).process(_frame(noisy, aligned=True, extrinsics=None))
    assert np.std(out[:, 100:300] - 2.0) < 0.5 * np.std(noisy[:, 100:300] - 2.0)
    assert np.all(np.abs(out[:, 319] - 2.0) < 0.03) and np.all(np.abs(out[:, 320] - 3.0) < 0.03)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"min_depth_m": 5.0, "max_depth_m": 1.0},
        {"hole_filling_px": 0},
        {"hole_filling_mode": "mean"},
    ],
)
def test_depth_config_rejects_bad_values(kwargs: dict[str, object]) -> None:
    from process.errors import ConfigError

    with pytest.raises(ConfigError):
        DepthConfig(**kwargs)  # type: ignore[arg-type]


def test_mean_z_buffer_is_not_biased_by_noise() -> None:
    rng = np.random.default_rng(1)
    depth = (2.0 + rng.normal(0.0, 0.02, (480, 640))).astype(np.float32)  # a noisy wall at 2 m
    kwargs = {
        "depth_intrinsics": DEPTH_K,
        "color_intrinsics": COLOR_K,
        "color_from_depth": np.eye(4),
    }
    nearest = register_depth(depth, z_buffer="nearest", **kwargs)  # type: ignore[arg-type]
    mean = register_depth(depth, z_buffer="mean", **kwargs)  # type: ignore[arg-type]
    assert np.array_equal(nearest > 0, mean > 0)
    assert np.median(nearest[nearest > 0]) < 1.99  # the nearest of a few noisy samples
    assert abs(float(np.median(mean[mean > 0])) - 2.0) < 0.002
    assert np.std(mean[mean > 0]) < np.std(depth)
