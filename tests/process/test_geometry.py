"""The shared pinhole and rigid-transform maths: known answers."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from capture.recording import Intrinsics
from process.geometry import normalise, project, rigid_inverse, transform_points

K = Intrinsics(width=640, height=480, fx=500.0, fy=400.0, cx=320.0, cy=240.0)


def test_a_point_one_metre_ahead_and_ten_centimetres_right_lands_fifty_pixels_right() -> None:
    uv = project(np.array([[0.1, -0.05, 1.0]], np.float32), K)
    np.testing.assert_allclose(uv, [[370.0, 220.0]], atol=1e-4)
    assert uv.dtype == np.float32


def test_normalise_undoes_project() -> None:
    points = np.random.default_rng(0).uniform([-1, -1, 0.5], [1, 1, 4], (100, 3))
    xy = normalise(project(points, K), K)
    np.testing.assert_allclose(xy, points[:, :2] / points[:, 2:], atol=1e-12)


def test_rigid_inverse_and_transform_points_round_trip() -> None:
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_euler("xyz", [10, -20, 30], degrees=True).as_matrix()
    pose[:3, 3] = [0.5, -1.0, 2.0]
    np.testing.assert_allclose(pose @ rigid_inverse(pose), np.eye(4), atol=1e-12)
    points = np.random.default_rng(1).normal(size=(50, 3)).astype(np.float32)
    back = transform_points(rigid_inverse(pose), transform_points(pose, points))
    assert back.dtype == np.float32
    np.testing.assert_allclose(back, points, atol=1e-5)
