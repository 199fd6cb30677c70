"""Keyframe pose-graph optimisation: ours (GTSAM, sparse) beside Open3D's global_optimization.

The graph is what a handheld recording makes: keyframes every ~12 cm round a 15 m loop, walked
lap after lap, odometry edges with a small rotation bias (drift) and a loop closure every fourth
keyframe from the second lap on, a tenth of them false (50 cm off). Each optimiser runs in its own
child process so that its peak RSS is its own (VmHWM); the baseline of the same child with the
graph built but not optimised is subtracted. 1,000 keyframes is ~4 minutes of walking; a 10-minute
recording makes ~2,400 (Open3D would need ~7 GB there, so it is measured at 1,000 only).
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

from benchmarks.common import Row, run_with_peak_rss
from process.odometry.pose_graph import Edge, PoseGraph

AREA = "pose graph"
SIDE_BY_SIDE = 1000
TEN_MINUTES = 2400
STEP_M = 0.12
LOOP_M = 15.0


def drifted_chain(
    truth: list[npt.NDArray[np.float64]],
    *,
    bias_deg: tuple[str, float],
    information: npt.NDArray[np.float64],
) -> PoseGraph:
    """Return a pose graph of odometry edges along `truth`, each step turned by a small bias.

    The chain drifts as real odometry does (a constant rotation error per step); loop edges are
    the caller's. `bias_deg` is an axis and an angle in degrees, e.g. ("z", 0.1).
    """
    bias = np.eye(4)
    bias[:3, :3] = Rotation.from_euler(bias_deg[0], bias_deg[1], degrees=True).as_matrix()
    graph = PoseGraph()
    pose = truth[0].copy()
    graph.add_node(pose)
    for i in range(1, len(truth)):
        step = np.linalg.inv(truth[i - 1]) @ truth[i] @ bias
        pose = pose @ step
        graph.add_node(pose)
        graph.add_edge(Edge(i, i - 1, step, information, False))
    return graph


def _graph(n: int) -> tuple[PoseGraph, npt.NDArray[np.float64]]:
    """Return a drifted graph with loop closures, and the true positions (n, 3)."""
    rng = np.random.default_rng(0)
    per_lap = int(LOOP_M / STEP_M)
    radius = LOOP_M / (2 * np.pi)
    truth = []
    for i in range(n):
        a = 2 * np.pi * i / per_lap
        pose = np.eye(4)
        pose[:3, :3] = Rotation.from_euler("z", a).as_matrix()
        pose[:3, 3] = [radius * np.cos(a), radius * np.sin(a), 0.02 * np.sin(7 * a)]
        truth.append(pose)
    info = np.eye(6) * 300.0
    graph = drifted_chain(truth, bias_deg=("z", 0.1), information=info)
    for i in range(per_lap, n, 4):
        j = i - per_lap + int(rng.integers(-1, 2))
        measured = np.linalg.inv(truth[j]) @ truth[i]
        if rng.random() < 0.1:
            measured[:3, 3] += [0.5, 0.0, 0.0]
        graph.add_edge(Edge(i, j, measured, info, True))
    return graph, np.array([t[:3, 3] for t in truth])


def _open3d(graph: PoseGraph) -> list[npt.NDArray[np.float64]]:
    """Optimise with Open3D's dense global_optimization, the options our pipeline used before."""
    import open3d as o3d

    reg = o3d.pipelines.registration
    g = reg.PoseGraph()
    for p in graph.poses:
        g.nodes.append(reg.PoseGraphNode(p))
    for e in graph.edges:
        g.edges.append(
            reg.PoseGraphEdge(
                e.source, e.target, e.target_from_source, e.information, uncertain=e.uncertain
            )
        )
    option = reg.GlobalOptimizationOption(
        max_correspondence_distance=0.05,
        edge_prune_threshold=0.25,
        preference_loop_closure=1.0,
        reference_node=0,
    )
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        reg.global_optimization(
            g,
            reg.GlobalOptimizationLevenbergMarquardt(),
            reg.GlobalOptimizationConvergenceCriteria(),
            option,
        )
    return [np.asarray(node.pose) for node in g.nodes]


def _child(method: str, n: int) -> None:
    """Build the graph, optimise it with `method` (or not: "none"), print seconds and ATE."""
    if "open3d" in method:
        import open3d  # noqa: F401  (its import is part of the baseline, not of the solve)
    graph, truth = _graph(n)
    t0 = time.perf_counter()
    if method == "ours":
        graph.optimise(max_correspondence_m=0.05, prune_threshold=0.25)
        poses = graph.poses
    elif method == "open3d":
        poses = _open3d(graph)
    else:
        poses = graph.poses
    seconds = time.perf_counter() - t0
    error = np.linalg.norm(np.array([p[:3, 3] for p in poses]) - truth, axis=1)
    print(json.dumps({"seconds": seconds, "ate_m": float(np.sqrt(np.mean(error**2)))}))


def _measure(method: str, n: int) -> tuple[float, float, float]:
    """Return (seconds, position RMSE in m, peak RSS in MB above the unoptimised baseline)."""
    peaks = []
    result: dict[str, float] = {}
    for what in (f"none-{method}", method):
        child = run_with_peak_rss("benchmarks.bench_posegraph", what, str(n))
        result = json.loads(child.stdout)
        peaks.append(child.peak_gb * 1024)
    return result["seconds"], result["ate_m"], peaks[1] - peaks[0]


def run() -> list[Row]:
    """Return time, accuracy and memory of both optimisers at 1,000 keyframes, ours at 2,400."""
    ours_s, ours_ate, ours_mb = _measure("ours", SIDE_BY_SIDE)
    o3d_s, o3d_ate, o3d_mb = _measure("open3d", SIDE_BY_SIDE)
    long_s, long_ate, long_mb = _measure("ours", TEN_MINUTES)
    src = "Open3D global_optimization, same graph"
    n = SIDE_BY_SIDE
    return [
        Row(AREA, f"optimise {n} keyframes", "s", ours_s, o3d_s, src),
        Row(AREA, f"memory to optimise {n} keyframes", "MB", max(ours_mb, 0.1), o3d_mb, src),
        Row(AREA, f"position RMSE after optimising {n} keyframes", "m", ours_ate, o3d_ate, src),
        Row(
            AREA,
            f"optimise {TEN_MINUTES} keyframes (a 10-minute walk)",
            "s",
            long_s,
            o3d_s,
            f"Open3D at {n} keyframes",
        ),
        Row(
            AREA,
            f"memory to optimise {TEN_MINUTES} keyframes",
            "MB",
            max(long_mb, 0.1),
            o3d_mb,
            f"Open3D at {n} keyframes",
        ),
        Row(
            AREA,
            f"position RMSE after optimising {TEN_MINUTES} keyframes",
            "m",
            long_ate,
            o3d_ate,
            f"Open3D at {n} keyframes",
        ),
    ]


if __name__ == "__main__":
    _child(sys.argv[1], int(sys.argv[2]))
