"""Pose information, depth that disagrees, local optimisation and covisibility edges.

Known answers: the refinement's information predicts the spread of its estimates; depth offset
from the image (Kinect v1 under fast rotation) does not pull the pose; a windowed optimisation
leaves the held keyframes exactly where they were; a rendered sideways walk gets edges to
keyframes before the parent that agree with the true motion.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from helpers_odometry import K_QVGA, pose, render, rotation_deg, to_frame, track_all
from scipy.spatial.transform import Rotation

from process.odometry.config import OdometryConfig
from process.odometry.odometry import Odometry
from process.odometry.pose_graph import Edge, PoseGraph
from process.odometry.pose_refine import refine_with_depth
from process.trajectory import Trajectory, ate_rmse

FOCAL = 500.0
TRUTH = pose((0.03, -0.02, 0.05), yaw_deg=4.0, pitch_deg=-2.0)  # camera_from_reference


def _scene(n: int, seed: int) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.float64]]:
    """Return reference-frame points 1-3 m away and their exact normalised observations."""
    rng = np.random.default_rng(seed)
    z = rng.uniform(1.0, 3.0, n)
    points = np.stack([rng.uniform(-0.5, 0.5, n) * z, rng.uniform(-0.4, 0.4, n) * z, z], 1)
    q = points @ TRUTH[:3, :3].T + TRUTH[:3, 3]
    return points.astype(np.float32), q


def _errors(estimate: npt.NDArray[np.float64]) -> tuple[float, float]:
    return float(np.linalg.norm(estimate[:3, 3] - TRUTH[:3, 3])), rotation_deg(estimate, TRUTH)


def _nudged() -> npt.NDArray[np.float64]:
    start = TRUTH.copy()
    start[:3, 3] += [0.01, -0.005, 0.008]
    start[:3, :3] = Rotation.from_euler("y", 0.5, degrees=True).as_matrix() @ start[:3, :3]
    return start


def test_information_predicts_the_spread_of_the_estimates() -> None:
    points, q = _scene(150, seed=1)
    exact = (q[:, :2] / q[:, 2:]).astype(np.float32)
    no_depth = np.full(len(points), np.nan, np.float32)
    rng = np.random.default_rng(2)
    twists, information = [], None
    for _ in range(150):
        noisy = exact + rng.normal(0.0, 1.0 / FOCAL, exact.shape).astype(np.float32)  # 1 px
        refined = refine_with_depth(
            points, noisy, no_depth, camera_from_reference=TRUTH, focal_px=FOCAL
        )
        delta = refined.camera_from_reference @ np.linalg.inv(TRUTH)  # left update
        twists.append(
            np.concatenate([Rotation.from_matrix(delta[:3, :3]).as_rotvec(), delta[:3, 3]])
        )
        information = refined.information
    assert information is not None
    predicted = np.sqrt(np.diag(np.linalg.inv(information)))
    measured = np.std(np.array(twists), axis=0)
    np.testing.assert_allclose(measured, predicted, rtol=0.3)


def test_depth_that_disagrees_with_the_image_does_not_pull_the_pose() -> None:
    points, q = _scene(200, seed=3)
    exact = (q[:, :2] / q[:, 2:]).astype(np.float32)
    # Depth taken 15 ms away from the colour while the camera turns: the keypoints' depths are
    # off by centimetres, the same way over much of the image (here 3 cm too far, +-2 cm).
    off = 0.03 + np.random.default_rng(4).uniform(-0.02, 0.02, len(q))
    depth = (q[:, 2] + off).astype(np.float32)
    refined = refine_with_depth(
        points, exact, depth, camera_from_reference=_nudged(), focal_px=FOCAL
    )
    moved_m, turned_deg = _errors(refined.camera_from_reference)
    # measured 4.1 mm; weighed with the sensor's noise (0.05 px) the depth pulls it 20 mm off
    assert moved_m < 0.006 and turned_deg < 0.1
    # With depth as good as the sensor's, the depth term is used: the same answer, exactly.
    good = refine_with_depth(
        points, exact, q[:, 2].astype(np.float32), camera_from_reference=_nudged(), focal_px=FOCAL
    )
    moved_m, turned_deg = _errors(good.camera_from_reference)
    assert moved_m < 1e-5 and turned_deg < 1e-4


def _chain(n: int) -> tuple[PoseGraph, list[npt.NDArray[np.float64]]]:
    """Return a straight chain whose every step turns 0.2 deg too much, and the true poses."""
    truth = [pose((0.1 * i, 0.0, 0.0)) for i in range(n)]
    bias = pose((0.0, 0.0, 0.0), yaw_deg=0.2)
    graph, current = PoseGraph(), truth[0].copy()
    graph.add_node(current)
    for i in range(1, n):
        step = np.linalg.inv(truth[i - 1]) @ truth[i] @ bias
        current = current @ step
        graph.add_node(current)
        graph.add_edge(Edge(i, i - 1, step, np.eye(6) * 1e4, False))
    return graph, truth


def test_windowed_optimisation_holds_the_older_keyframes() -> None:
    graph, truth = _chain(20)
    before = [p.copy() for p in graph.poses]
    graph.add_edge(Edge(19, 12, np.linalg.inv(truth[12]) @ truth[19], np.eye(6) * 1e4, True))
    graph.optimise(max_correspondence_m=0.05, prune_threshold=0.25, first_free=12)
    for held, was in zip(graph.poses[:13], before[:13], strict=True):
        np.testing.assert_allclose(held, was, atol=1e-9)
    # The loop's measured motion is met between its ends (half of it before: equal weights).
    relative = np.linalg.inv(graph.poses[12]) @ graph.poses[19]
    wanted = np.linalg.inv(truth[12]) @ truth[19]
    assert rotation_deg(relative, wanted) < 0.5 * rotation_deg(
        np.linalg.inv(before[12]) @ before[19], wanted
    )


def _walk(covisible: int) -> tuple[Odometry, list[npt.NDArray[np.float64]], float]:
    """Track a rendered sideways walk (a keyframe every other frame); return odometry, ATE."""
    poses = [pose((0.025 * i, 0.0, 0.0), yaw_deg=-1.0 * i) for i in range(12)]
    frames = [to_frame(render(p, K_QVGA), index=i, intr=K_QVGA) for i, p in enumerate(poses)]
    cfg = OdometryConfig(  # no dense step, so every keyframe is linked; no loops to hide it
        min_inliers=15,
        keyframe_min_inliers=40,
        loop_min_inliers=40,
        keyframe_translation_m=0.04,
        dense_refine=False,
        loop_closure=False,
        covisible_keyframes=covisible,
    )
    odometry = Odometry(cfg, intrinsics=K_QVGA)
    assert all(r.state.status == "ok" for r in track_all(odometry, frames))
    out = odometry.finish()
    return odometry, poses, ate_rmse(out, Trajectory(out.stamps_ns, np.array(poses)))


def test_new_keyframes_are_linked_to_the_ones_before_their_parent() -> None:
    odometry, poses, linked_ate = _walk(2)
    kfs = odometry.keyframes
    skips = [e for e in odometry.graph.edges if e.source - e.target >= 2]
    assert len(kfs) >= 5 and len(skips) >= len(kfs) - 3
    for e in skips:  # each measures the true motion as well as a parent edge (QVGA: mm)
        truth = np.linalg.inv(poses[kfs[e.target].frame_index]) @ poses[kfs[e.source].frame_index]
        assert np.linalg.norm(e.target_from_source[:3, 3] - truth[:3, 3]) < 0.008  # max 5.8 mm
        assert rotation_deg(e.target_from_source, truth) < 0.15  # max 0.11 deg
    _, _, chained_ate = _walk(0)
    assert linked_ate < 0.7 * chained_ate  # measured 4.5 mm against 7.8 mm
