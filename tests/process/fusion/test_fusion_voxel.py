"""Fusion: posed views of a plane land on the plane with the confidence-voted label."""

from __future__ import annotations

import numpy as np
import pytest

from capture.recording import Intrinsics
from process.errors import ConfigError, StageError
from process.fusion.votes import Fusion, FusionConfig

K = Intrinsics(64, 48, 500.0, 500.0, 31.5, 23.5)  # 4 mm pixels at 2 m: ~25 per 2 cm voxel
PLANE_Z_M = 2.01  # the world plane, mid-voxel (a voxel boundary would split it in two layers)


def _rotation_y(deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _view_of_plane(world_from_camera: np.ndarray) -> np.ndarray:
    """Return the depth image (camera z) of the world plane z = PLANE_Z_M seen from a pose."""
    v, u = np.mgrid[0 : K.height, 0 : K.width]
    rays = np.stack([(u - K.cx) / K.fx, (v - K.cy) / K.fy, np.ones(u.shape)], axis=-1)
    world_rays = rays @ world_from_camera[:3, :3].T
    t = (PLANE_Z_M - world_from_camera[2, 3]) / world_rays[..., 2]
    depth: np.ndarray = t.astype(np.float32)  # camera-frame z of the hit: each ray has z = 1
    return depth


def _images(label: int, confidence: float, depth: np.ndarray) -> tuple[np.ndarray, ...]:
    color = np.full((K.height, K.width, 3), 10 * label, np.uint8)
    return (
        color,
        depth,
        np.full(depth.shape, label, np.uint8),
        np.full(depth.shape, confidence, np.float32),
    )


def test_two_views_of_a_plane_land_on_it_with_the_voted_label() -> None:
    first = np.eye(4)
    second = np.eye(4)
    second[:3, :3] = _rotation_y(1.0)
    second[:3, 3] = (0.08, 0.02, 0.2)
    fusion = Fusion(
        FusionConfig(voxel_size_m=0.02, pixel_stride=1, max_depth_m=5.0, surface="voxels")
    )
    fusion.integrate(*_images(4, 0.9, _view_of_plane(first)), intrinsics=K, world_from_camera=first)
    fusion.integrate(
        *_images(5, 0.6, _view_of_plane(second)), intrinsics=K, world_from_camera=second
    )
    cloud = fusion.cloud()
    np.testing.assert_allclose(cloud.points[:, 2], PLANE_Z_M, atol=1e-5)
    # the first view covers x in [-0.126, 0.130] m and y in [-0.094, 0.098] m of the plane
    x, y = cloud.points[:, 0], cloud.points[:, 1]
    inside = (np.abs(x - 0.002) < 0.128 - 0.03) & (np.abs(y - 0.002) < 0.096 - 0.03)
    outside = x > 0.13 + 0.02
    assert inside.sum() > 30 and outside.sum() > 30
    assert (cloud.labels[inside] == 4).all()  # ~25 pixels x 0.9 outvote ~31 x 0.3
    assert (cloud.labels[outside] == 5).all()  # only the second view saw these


def test_votes_add_up_over_views() -> None:
    pose = np.eye(4)
    depth = _view_of_plane(pose)
    fusion = Fusion(FusionConfig(pixel_stride=2, surface="voxels"))
    fusion.integrate(*_images(4, 0.9, depth), intrinsics=K, world_from_camera=pose)
    for _ in range(2):  # two weaker votes for 7 beat one strong vote for 4
        fusion.integrate(*_images(7, 0.5, depth), intrinsics=K, world_from_camera=pose)
    cloud = fusion.cloud()
    assert (cloud.labels == 7).all()
    assert (cloud.colors == np.uint8(round((40 + 70 + 70) / 3))).all()  # mean colour


def test_unsure_pixels_add_geometry_but_no_vote_and_far_depth_is_dropped() -> None:
    pose = np.eye(4)
    depth = _view_of_plane(pose)
    depth[:, :10] = 9.0  # beyond max_depth_m
    fusion = Fusion(FusionConfig(min_confidence=0.5, max_depth_m=4.0, surface="voxels"))
    fusion.integrate(*_images(4, 0.2, depth), intrinsics=K, world_from_camera=pose)
    cloud = fusion.cloud()
    assert len(cloud) > 0 and (cloud.labels == 0).all()
    assert cloud.points[:, 2].max() < 4.0


def _noisy_views(fusion: Fusion, n: int, *, sigma_m: float) -> None:
    """Integrate n views of the plane from poses 1 cm apart, depth with Gaussian noise."""
    rng = np.random.default_rng(3)
    for i in range(n):
        pose = np.eye(4)
        pose[:3, 3] = (0.01 * (i % 5) - 0.02, 0.01 * (i // 5) - 0.02, 0.0)
        depth = _view_of_plane(pose) + rng.normal(0.0, sigma_m, (K.height, K.width))
        images = _images(4, 0.9, depth.astype(np.float32))
        fusion.integrate(*images, intrinsics=K, world_from_camera=pose)


def test_tsdf_surface_of_a_noisy_plane_is_thin_where_voxels_are_thick() -> None:
    tsdf = Fusion(FusionConfig(pixel_stride=1, surface="tsdf"))
    voxels = Fusion(FusionConfig(pixel_stride=1, surface="voxels"))
    for fusion in (tsdf, voxels):
        _noisy_views(fusion, 25, sigma_m=0.02)  # the D435's RMS at ~2.8 m
    thin, thick = tsdf.cloud(), voxels.cloud()
    assert len(thin) > 50 and (thin.labels == 4).all()
    assert len(thick) > 2 * len(thin)

    def interior_error(points: np.ndarray) -> np.ndarray:  # away from the seen area's edges
        inside = (np.abs(points[:, 0]) < 0.08) & (np.abs(points[:, 1]) < 0.05)
        assert inside.sum() > 20
        error: np.ndarray = np.abs(points[inside, 2] - PLANE_Z_M)
        return error

    assert np.percentile(interior_error(thin.points), 95) < 0.008  # 25 views: sigma / 5 = 4 mm
    assert np.percentile(interior_error(thick.points), 95) > 0.02  # every voxel a sample hit


def test_tsdf_points_need_min_views() -> None:
    fusion = Fusion(FusionConfig(pixel_stride=1, surface="tsdf", min_views=3))
    pose = np.eye(4)
    fusion.integrate(*_images(4, 0.9, _view_of_plane(pose)), intrinsics=K, world_from_camera=pose)
    single = fusion.cloud()  # fewer keyframes than min_views: the one view is the map
    assert len(single) > 50
    aside = np.eye(4)
    aside[0, 3] = 0.3  # sees x in [0.17, 0.43]: beside the first view's [-0.13, 0.13]
    for _ in range(2):
        images = _images(4, 0.9, _view_of_plane(aside))
        fusion.integrate(*images, intrinsics=K, world_from_camera=aside)
    cloud = fusion.cloud()  # three keyframes, but each place was seen once or twice
    assert len(cloud) == 0
    fusion.integrate(*_images(4, 0.9, _view_of_plane(aside)), intrinsics=K, world_from_camera=aside)
    x = fusion.cloud().points[:, 0]
    assert len(x) > 50 and x.min() > 0.13  # only the place seen three times


def test_tsdf_points_take_the_nearest_vote_within_two_voxels() -> None:
    # every 16th pixel votes (6.4 cm apart at 2 m); the TSDF integrates every pixel
    sparse, dense, votes = (
        Fusion(FusionConfig(pixel_stride=stride, surface=surface))
        for stride, surface in ((16, "tsdf"), (1, "tsdf"), (16, "voxels"))
    )
    pose = np.eye(4)
    for fusion in (sparse, dense, votes):
        for _ in range(3):
            fusion.integrate(
                *_images(4, 0.9, _view_of_plane(pose)), intrinsics=K, world_from_camera=pose
            )
    kept, surface, voted = sparse.cloud(), dense.cloud(), votes.cloud()
    assert len(voted) < len(kept) < len(surface)  # most points borrow a neighbour's vote
    assert (kept.labels == 4).all()
    nearest = np.linalg.norm(surface.points[:, None] - voted.points[None], axis=2).min(axis=1)
    assert len(kept) == int((nearest <= 2 * 0.02 + 1e-6).sum())  # the rest had no vote near


def test_a_keyframe_without_depth_in_range_adds_nothing() -> None:
    fusion = Fusion(FusionConfig(surface="tsdf"))
    far = np.full((K.height, K.width), 9.0, np.float32)  # beyond max_depth_m everywhere
    for depth in (np.zeros_like(far), far):
        fusion.integrate(*_images(4, 0.9, depth), intrinsics=K, world_from_camera=np.eye(4))
    assert len(fusion.cloud()) == 0


def test_images_of_another_size_are_refused() -> None:
    fusion = Fusion(FusionConfig())
    small = np.zeros((10, 10), np.float32)
    with pytest.raises(StageError, match="register depth to colour"):
        fusion.integrate(
            np.zeros((48, 64, 3), np.uint8), small, np.zeros((48, 64), np.uint8),
            np.ones((48, 64), np.float32), intrinsics=K, world_from_camera=np.eye(4),
        )  # fmt: skip


@pytest.mark.parametrize(
    "field",
    [
        {"voxel_size_m": 0.0},
        {"pixel_stride": 0},
        {"min_confidence": 2.0},
        {"surface": "mesh"},
        {"truncation_voxels": 0.5},
        {"min_views": 0},
    ],
)
def test_bad_config_values_are_refused(field: dict[str, float]) -> None:
    with pytest.raises(ConfigError):
        FusionConfig(**field)  # type: ignore[arg-type]
