"""The dense alignment's photometric methods: Open3D's answer, whatever the images' addresses."""

from __future__ import annotations

from functools import cache

import cv2
import numpy as np
import numpy.typing as npt
import open3d as o3d
import pytest
from helpers_odometry import K_VGA, RenderedFrame, pose, render

from process.odometry.dense import DenseAligner, DenseImage, gaussian_pyrdown, pyrdown_depth

_OPEN3D = {
    "hybrid": o3d.t.pipelines.odometry.Method.Hybrid,
    "intensity": o3d.t.pipelines.odometry.Method.Intensity,
}
START = pose((0.3, 0.1, -0.2), yaw_deg=20.0, pitch_deg=-5.0)
MOTION = np.eye(4)
MOTION[:3, 3] = [0.02, 0.0, 0.01]


@cache
def _views() -> tuple[RenderedFrame, RenderedFrame]:
    return render(START), render(START @ MOTION)


def _prepared(aligner: DenseAligner) -> tuple[DenseImage, DenseImage]:
    """Return (second view, first view) prepared, the first with a hole in its depth."""
    first, second = _views()
    depth = first.depth_m.copy()
    depth[100:180, 200:300] = 0.0  # a hole: Open3D's multi-scale varied only with holes
    gray = [
        np.asarray(cv2.cvtColor(v.color, cv2.COLOR_RGB2GRAY), np.uint8) for v in (second, first)
    ]
    return aligner.prepare(gray[0], second.depth_m), aligner.prepare(gray[1], depth)


def _at_offset(a: npt.NDArray[np.float32], offset: int) -> npt.NDArray[np.float32]:
    """Return a copy of a whose buffer starts offset bytes past a 64-byte boundary."""
    buffer = np.empty(a.nbytes + 128, np.uint8)
    start = (-buffer.ctypes.data) % 64 + offset
    out = buffer[start : start + a.nbytes].view(np.float32).reshape(a.shape)
    out[...] = a
    return out


@pytest.mark.parametrize("method", list(_OPEN3D))
def test_photometric_alignment_is_open3ds_and_recovers_the_motion(method: str) -> None:
    aligner = DenseAligner(K_VGA, scale=2, max_depth_m=6.0, iterations=(10, 5, 3), method=method)
    source, target = _prepared(aligner)
    result = aligner.align(source, target, init_target_from_source=np.eye(4))
    assert result is not None and result.method == method
    reference = o3d.t.pipelines.odometry.rgbd_odometry_multi_scale(
        source.rgbd,
        target.rgbd,
        aligner.camera_matrix,
        o3d.core.Tensor.from_numpy(np.eye(4)),
        1.0,
        6.0,
        aligner.criteria,
        _OPEN3D[method],
    )
    # Open3D's own multi-scale, to the last bits of its Gaussian (measured: 7e-6)
    assert np.abs(result.target_from_source - reference.transformation.numpy()).max() < 1e-4
    assert abs(result.fitness - reference.fitness) < 1e-3
    # the photometric term's known bias on exact renders is a few mm (measured: 4-5 mm)
    assert np.linalg.norm(result.target_from_source[:3, 3] - MOTION[:3, 3]) < 0.008


@pytest.mark.parametrize("method", list(_OPEN3D))
def test_photometric_alignment_gives_one_pose_for_the_same_images(method: str) -> None:
    # Open3D's multi-scale gave 2-4 different poses in 8 such calls (its Gaussian's result
    # depends on where its buffers happen to lie, and they lie elsewhere after each prepare)
    aligner = DenseAligner(K_VGA, scale=2, max_depth_m=6.0, iterations=(10, 5, 3), method=method)
    poses = set()
    for _ in range(8):
        source, target = _prepared(aligner)
        result = aligner.align(source, target, init_target_from_source=np.eye(4))
        assert result is not None
        poses.add(result.target_from_source.tobytes())
    assert len(poses) == 1


def test_the_intensity_pyramid_does_not_depend_on_the_images_address() -> None:
    gray = np.random.default_rng(0).random((120, 160)).astype(np.float32)
    levels = {gaussian_pyrdown(_at_offset(gray, offset)).tobytes() for offset in range(0, 64, 4)}
    assert len(levels) == 1  # Open3D's filter_gaussian gives two, by address mod 8
    # a 5x5 Gaussian of sigma 1: a constant stays, a single bright pixel spreads to 5x5
    assert np.allclose(gaussian_pyrdown(np.full((8, 8), 0.5, np.float32)), 0.5)
    spike = np.zeros((16, 16), np.float32)
    spike[8, 8] = 1.0
    down = gaussian_pyrdown(spike)
    assert down.shape == (8, 8)
    assert down[4, 4] == down.max() and np.isclose(down.sum() * 4, 1.0, atol=0.3)
    assert np.count_nonzero(down > 1e-6) == 9  # the 5x5 footprint sampled every other pixel


def test_depth_pyramid_averages_only_the_neighbours_near_the_centre() -> None:
    depth = np.full((8, 8), 2.0, np.float32)
    depth[:, 4:] = 3.0  # a 1 m step: neither side blurs into the other
    depth[0, 0] = np.nan  # a hole stays a hole
    depth[2, 2] = 2.1  # within max_diff: averaged in
    down = pyrdown_depth(depth, max_diff=0.14)
    assert down.shape == (4, 4)
    assert np.isnan(down[0, 0])
    assert np.allclose(down[:, 2:], 3.0)
    # centre (2, 2) = 2.1 weighs its 5x5 window's 2 m pixels (columns 0-3, not the hole at
    # (0, 0)) by the binomial weights (1 4 6 4 1) / 16 in each direction
    weight = 1.0 * (1.0 - 0.0625) - 0.0625**2
    expected = 2.0 + 0.1 * 0.375**2 / weight
    assert np.isclose(down[1, 1], expected, atol=1e-6)
