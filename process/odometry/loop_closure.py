"""Drift correction: a keyframe pose graph (GTSAM) and place recognition among old keyframes."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import gtsam
import numpy as np
import numpy.typing as npt

from process.odometry.features import Keyframe
from process.odometry.matching import match
from process.odometry.pnp import PnpSolver, information_from_points, rigid_inverse
from process.odometry.pose_refine import refine_with_depth

if TYPE_CHECKING:
    from process.odometry.config import OdometryConfig

_FIXED = gtsam.noiseModel.Isotropic.Sigma(6, 1e-6)  # holds keyframe 0 where it is


@dataclass(frozen=True, slots=True)
class Edge:
    """A measured relative pose between two keyframes."""

    source: int
    target: int
    target_from_source: npt.NDArray[np.float64]  # (4, 4)
    information: npt.NDArray[np.float64]  # (6, 6)
    uncertain: bool  # loop closures are uncertain: the optimiser may prune them


class PoseGraph:
    """Keyframe poses (world_from_keyframe) and the constraints between them."""

    def __init__(self) -> None:
        self.poses: list[npt.NDArray[np.float64]] = []
        self.edges: list[Edge] = []

    def add_node(self, world_from_keyframe: npt.NDArray[np.float64]) -> int:
        """Add a keyframe pose and return its id."""
        self.poses.append(np.asarray(world_from_keyframe, np.float64).copy())
        return len(self.poses) - 1

    def add_edge(self, edge: Edge) -> None:
        """Add a constraint between two existing keyframes."""
        self.edges.append(edge)

    @property
    def n_loops(self) -> int:
        """Return how many loop-closure constraints the graph holds."""
        return sum(e.uncertain for e in self.edges)

    def optimise(self, *, max_correspondence_m: float, prune_threshold: float) -> tuple[float, int]:
        """Optimise every pose (GTSAM, sparse Levenberg-Marquardt) and prune bad loop closures.

        Loop closures get a Geman-McClure kernel whose weight (mu / (mu + chi2))^2 is the line
        process of Open3D's global_optimization (Choi et al. 2015), with Open3D's scale mu =
        max_correspondence_m^2 x the mean correspondence count of the edges; closures whose weight
        ends below prune_threshold are dropped and the rest optimised again. GTSAM rather than
        Open3D: Open3D solves a dense 6N x 6N system (1.1 GB and 2 s at 1,000 keyframes, a
        10-minute recording makes ~2,400); GTSAM's sparse solver needs megabytes and milliseconds.
        Returns the largest move of a keyframe position in metres and the loop closures kept.
        """
        if len(self.poses) < 2 or not self.edges:
            return 0.0, self.n_loops
        mu = max_correspondence_m**2 * float(np.mean([e.information[5, 5] for e in self.edges]))
        new = _solve(self.poses, self.edges, mu)
        kept = [
            e for e in self.edges if not e.uncertain or _line_process(e, new, mu) >= prune_threshold
        ]
        if len(kept) < len(self.edges):
            new = _solve(self.poses, kept, mu)
        moved = max(
            float(np.linalg.norm(a[:3, 3] - b[:3, 3])) for a, b in zip(new, self.poses, strict=True)
        )
        self.poses, self.edges = new, kept
        return moved, self.n_loops


def _gaussian(edge: Edge) -> gtsam.noiseModel.Base:
    """Return the edge's Gaussian noise (its information, nudged to be positive definite)."""
    info = edge.information + np.eye(6) * 1e-9 * max(float(np.trace(edge.information)), 1.0)
    return gtsam.noiseModel.Gaussian.Information(info)


def _noise(edge: Edge, mu: float) -> gtsam.noiseModel.Base:
    """Return the edge's Gaussian noise, robust (Geman-McClure, c^2 = mu) for a loop closure."""
    gaussian = _gaussian(edge)
    if not edge.uncertain:
        return gaussian
    kernel = gtsam.noiseModel.mEstimator.GemanMcClure.Create(float(np.sqrt(mu)))
    return gtsam.noiseModel.Robust.Create(kernel, gaussian)


def _factor(edge: Edge, noise: gtsam.noiseModel.Base) -> gtsam.BetweenFactorPose3:
    # between(target, source) = world_from_target^-1 @ world_from_source = target_from_source
    return gtsam.BetweenFactorPose3(
        edge.target, edge.source, gtsam.Pose3(edge.target_from_source), noise
    )


def _solve(
    poses: Sequence[npt.NDArray[np.float64]], edges: Sequence[Edge], mu: float
) -> list[npt.NDArray[np.float64]]:
    """Return the poses that best agree with the edges, keyframe 0 held fixed."""
    graph = gtsam.NonlinearFactorGraph()
    initial = gtsam.Values()
    for i, pose in enumerate(poses):
        initial.insert(i, gtsam.Pose3(pose))
    graph.add(gtsam.PriorFactorPose3(0, gtsam.Pose3(poses[0]), _FIXED))
    for edge in edges:
        graph.add(_factor(edge, _noise(edge, mu)))
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(100)
    result = gtsam.LevenbergMarquardtOptimizer(graph, initial, params).optimize()
    return [np.asarray(result.atPose3(i).matrix(), np.float64) for i in range(len(poses))]


def _line_process(edge: Edge, poses: Sequence[npt.NDArray[np.float64]], mu: float) -> float:
    """Return Open3D's line-process weight (mu / (mu + chi2))^2 of an edge at these poses."""
    values = gtsam.Values()
    values.insert(edge.target, gtsam.Pose3(poses[edge.target]))
    values.insert(edge.source, gtsam.Pose3(poses[edge.source]))
    chi2 = 2.0 * _factor(edge, _gaussian(edge)).error(values)
    return float((mu / (mu + chi2)) ** 2)


def loop_candidates(
    current: Keyframe,
    keyframes: Sequence[Keyframe],
    *,
    poses: Sequence[npt.NDArray[np.float64]],
    min_gap: int,
    count: int,
    min_similarity: float,
    radius_m: float,
) -> list[int]:
    """Return ids of old keyframes that may show the current one's place, most likely first.

    Two cues: thumbnail similarity (appearance, independent of drift) and nearness of the
    estimated poses (position within radius_m, viewing directions within 45 degrees).
    """
    old = [k for k in keyframes[: max(0, current.id - min_gap + 1)] if k.segment >= 0]
    if not old:
        return []
    scores = np.stack([k.thumbnail for k in old]) @ current.thumbnail
    order = np.argsort(-scores)
    ids = [old[i].id for i in order[:count] if scores[i] >= min_similarity]
    here = poses[current.id]
    there = np.stack([poses[k.id] for k in old])
    dist = np.linalg.norm(there[:, :3, 3] - here[:3, 3], axis=1)
    cos = there[:, :3, 2] @ here[:3, 2]
    near = np.flatnonzero((dist <= radius_m) & (cos >= np.cos(np.radians(45.0))))
    near = near[np.argsort(dist[near], kind="stable")]
    ids += [old[i].id for i in near if old[i].id not in ids][: max(1, count // 2)]
    return ids


def find_loop(
    current: Keyframe,
    candidates: Sequence[Keyframe],
    *,
    pnp: PnpSolver,
    match_ratio: float,
    min_inliers: int,
) -> tuple[Edge, int] | None:
    """Return the best verified loop edge (current -> an old keyframe) and its inlier count.

    Each candidate is verified by PnP of its 3-D points against the current keypoints; only the
    candidate with the most inliers is kept: the nearest view gives the most precise edge.
    """
    best: tuple[Edge, int] | None = None
    for old in candidates:
        q, t = match(current.descriptors, old.descriptors, ratio=match_ratio)
        result = pnp.solve(old.points[t], current.xy[q], min_inliers=min_inliers)
        if result is None or (best is not None and len(result.inliers) <= best[1]):
            continue
        inliers_q, inliers_t = q[result.inliers], t[result.inliers]
        support = information_from_points(old.points[inliers_t])
        # As for odometry edges: the current keyframe's own depth at the inliers refines the pose.
        k = pnp.camera_matrix
        xy = current.xy[inliers_q].astype(np.float64)
        normalised = np.stack([(xy[:, 0] - k[0, 2]) / k[0, 0], (xy[:, 1] - k[1, 2]) / k[1, 1]], 1)
        camera_from_old, _ = refine_with_depth(
            old.points[inliers_t],
            normalised.astype(np.float32),
            current.points[inliers_q, 2],
            camera_from_reference=result.camera_from_reference,
            focal_px=float(k[0, 0]),
        )
        old_from_current = rigid_inverse(camera_from_old)
        best = Edge(current.id, old.id, old_from_current, support, True), len(result.inliers)
    return best


class LoopCloser:
    """Search each new keyframe's place among old keyframes; on a match, optimise the graph."""

    def __init__(
        self, cfg: OdometryConfig, *, pnp: PnpSolver, graph: PoseGraph, keyframes: list[Keyframe]
    ) -> None:
        self.cfg = cfg
        self.pnp = pnp
        self.graph = graph
        self.keyframes = keyframes
        self._cooldown = 0

    def close(self, kf: Keyframe) -> str:
        """Return a description of the loop closed from this keyframe, or "" if none was."""
        cfg = self.cfg
        if not cfg.loop_closure:
            return ""
        if self._cooldown > 0:
            self._cooldown -= 1
            return ""
        ids = loop_candidates(
            kf,
            self.keyframes,
            poses=self.graph.poses,
            min_gap=cfg.loop_min_gap,
            count=cfg.loop_candidates,
            min_similarity=cfg.loop_min_similarity,
            radius_m=cfg.loop_search_radius_m,
        )
        candidates = [self.keyframes[i] for i in ids]
        found = find_loop(
            kf,
            candidates,
            pnp=self.pnp,
            match_ratio=cfg.match_ratio,
            min_inliers=cfg.loop_min_inliers,
        )
        if found is None:
            return ""
        edge, n_inliers = found
        self.graph.add_edge(edge)
        moved_m, kept = self.graph.optimise(
            max_correspondence_m=cfg.loop_max_correspondence_m,
            prune_threshold=cfg.loop_prune_threshold,
        )
        self._cooldown = cfg.loop_cooldown
        return (
            f"loop closure: keyframe {kf.id} matched keyframe {edge.target} ({n_inliers} inliers);"
            f" {kept} loop edge(s) kept, keyframes moved by up to {moved_m:.3f} m"
        )
