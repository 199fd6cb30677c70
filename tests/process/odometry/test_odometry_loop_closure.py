"""Loop closure: the pose graph removes drift (known answer), and a rendered loop is closed."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from helpers_odometry import K_QVGA, loop_poses, render, to_frame, track_all
from scipy.spatial.transform import Rotation

from benchmarks.bench_posegraph import drifted_chain
from process.odometry.config import OdometryConfig
from process.odometry.odometry import Odometry
from process.odometry.pose_graph import Edge, PoseGraph
from process.trajectory import Trajectory, ate_rmse


def _circle(n: int) -> list[npt.NDArray[np.float64]]:
    poses = []
    for i in range(n):
        a = 2 * np.pi * i / n
        p = np.eye(4)
        p[:3, :3] = Rotation.from_euler("y", a).as_matrix()
        p[:3, 3] = [np.sin(a), 0.0, np.cos(a)]
        poses.append(p)
    return poses


def test_pose_graph_removes_drift_with_one_loop_edge() -> None:
    truth = _circle(24)
    bias = np.eye(4)
    bias[:3, :3] = Rotation.from_euler(
        "y", 0.15, degrees=True
    ).as_matrix()  # each step turns too much
    graph = PoseGraph()
    pose = truth[0].copy()
    graph.add_node(pose)
    info = np.eye(6) * 1000.0
    for i in range(1, 24):
        step = np.linalg.inv(truth[i - 1]) @ truth[i] @ bias
        pose = pose @ step
        graph.add_node(pose)
        graph.add_edge(Edge(i, i - 1, step, info, False))
    drifted = max(
        np.linalg.norm(p[:3, 3] - t[:3, 3]) for p, t in zip(graph.poses, truth, strict=True)
    )
    graph.add_edge(Edge(23, 0, np.linalg.inv(truth[0]) @ truth[23], info, True))
    moved, kept = graph.optimise(max_correspondence_m=0.05, prune_threshold=0.25)
    after = max(
        np.linalg.norm(p[:3, 3] - t[:3, 3]) for p, t in zip(graph.poses, truth, strict=True)
    )
    assert kept == 1
    assert drifted > 0.05  # 3.5 deg of heading error at the end of a 6 m circle
    assert after < 0.3 * drifted
    assert moved > 0.5 * drifted


def test_inconsistent_loop_edge_is_pruned() -> None:
    truth = _circle(12)
    graph = PoseGraph()
    for p in truth:
        graph.add_node(p)
    info = np.eye(6) * 1000.0
    for i in range(1, 12):
        graph.add_edge(Edge(i, i - 1, np.linalg.inv(truth[i - 1]) @ truth[i], info, False))
    wrong = np.linalg.inv(truth[0]) @ truth[11]
    wrong[:3, 3] += [0.5, 0.0, 0.0]  # a false place match, 50 cm off
    graph.add_edge(Edge(11, 0, wrong, info, True))
    _, kept = graph.optimise(max_correspondence_m=0.05, prune_threshold=0.25)
    assert kept == 0
    assert graph.n_loops == 0
    assert (
        max(np.linalg.norm(p[:3, 3] - t[:3, 3]) for p, t in zip(graph.poses, truth, strict=True))
        < 0.01
    )


def test_many_laps_keep_the_true_loops_and_prune_the_false_ones() -> None:
    """Five laps of 120 keyframes, a loop edge every 4th keyframe, every 10th of them 50 cm off."""
    per_lap, n = 120, 600
    truth = _circle(per_lap) * (n // per_lap)
    info = np.eye(6) * 300.0
    graph = drifted_chain(truth, bias_deg=("y", 0.1), information=info)
    false = set()
    for k, i in enumerate(range(per_lap, n, 4)):
        measured = np.linalg.inv(truth[i - per_lap]) @ truth[i]
        if k % 10 == 5:
            measured[:3, 3] += [0.5, 0.0, 0.0]
            false.add(i)
        graph.add_edge(Edge(i, i - per_lap, measured, info, True))
    drifted = max(
        np.linalg.norm(p[:3, 3] - t[:3, 3]) for p, t in zip(graph.poses, truth, strict=True)
    )
    _, kept = graph.optimise(max_correspondence_m=0.05, prune_threshold=0.25)
    after = max(
        np.linalg.norm(p[:3, 3] - t[:3, 3]) for p, t in zip(graph.poses, truth, strict=True)
    )
    loops = {e.source for e in graph.edges if e.uncertain}
    assert loops.isdisjoint(false)
    assert kept == len(range(per_lap, n, 4)) - len(false)
    assert drifted > 0.5 and after < 0.02


def test_rendered_loop_is_closed() -> None:
    poses = loop_poses(40, radius_m=0.5, turns=1.15)
    frames = [to_frame(render(p, K_QVGA), index=i, intr=K_QVGA) for i, p in enumerate(poses)]
    cfg = OdometryConfig(  # 320x240 frames: the dense alignment at full size
        min_inliers=15, keyframe_min_inliers=60, loop_min_gap=6, loop_min_inliers=60, dense_scale=1
    )
    odometry = Odometry(cfg, intrinsics=K_QVGA)
    results = track_all(odometry, frames)
    assert all(r.state.status == "ok" for r in results)
    closures = [r for r in results if r.state.event and "loop closure" in r.state.event]
    assert closures, [r.state.event for r in results if r.state.event]
    assert all(r.state.trajectory_corrected for r in closures)
    assert odometry.graph.n_loops >= 1
    out = odometry.finish()
    assert ate_rmse(out, Trajectory(out.stamps_ns, np.array(poses))) < 0.01
