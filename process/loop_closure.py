"""Drift correction: a keyframe pose graph (Open3D) and place recognition among old keyframes."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
import open3d as o3d

from process.odometry_features import Keyframe
from process.odometry_matching import match
from process.odometry_pnp import PnpSolver, information_from_points

if TYPE_CHECKING:
    from process.odometry_config import OdometryConfig


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
        """Optimise every pose with Open3D (Levenberg-Marquardt with line processes).

        Returns the largest move of a keyframe position in metres and the number of loop
        closures the optimiser kept (it prunes those inconsistent with the rest).
        """
        graph = o3d.pipelines.registration.PoseGraph()
        for p in self.poses:
            graph.nodes.append(o3d.pipelines.registration.PoseGraphNode(p))
        for e in self.edges:
            graph.edges.append(
                o3d.pipelines.registration.PoseGraphEdge(
                    e.source, e.target, e.target_from_source, e.information, uncertain=e.uncertain
                )
            )
        option = o3d.pipelines.registration.GlobalOptimizationOption(
            max_correspondence_distance=max_correspondence_m,
            edge_prune_threshold=prune_threshold,
            preference_loop_closure=1.0,
            reference_node=0,
        )
        with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
            o3d.pipelines.registration.global_optimization(
                graph,
                o3d.pipelines.registration.GlobalOptimizationLevenbergMarquardt(),
                o3d.pipelines.registration.GlobalOptimizationConvergenceCriteria(),
                option,
            )
        new = [np.asarray(n.pose, np.float64).copy() for n in graph.nodes]
        moved = max(
            (
                float(np.linalg.norm(a[:3, 3] - b[:3, 3]))
                for a, b in zip(new, self.poses, strict=True)
            ),
            default=0.0,
        )
        self.poses = new
        kept = {(e.source_node_id, e.target_node_id) for e in graph.edges if e.uncertain}
        self.edges = [e for e in self.edges if not e.uncertain or (e.source, e.target) in kept]
        return moved, len(kept)


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
    scores = np.array([float(k.thumbnail @ current.thumbnail) for k in old])
    order = np.argsort(-scores)
    ids = [old[i].id for i in order[:count] if scores[i] >= min_similarity]
    here = poses[current.id]
    near = []
    for k in old:
        there = poses[k.id]
        dist = float(np.linalg.norm(there[:3, 3] - here[:3, 3]))
        cos = float(there[:3, 2] @ here[:3, 2])
        if dist <= radius_m and cos >= np.cos(np.radians(45.0)) and k.id not in ids:
            near.append((dist, k.id))
    ids += [i for _, i in sorted(near)[: max(1, count // 2)]]
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
        support = information_from_points(old.points[t[result.inliers]])
        old_from_current = result.reference_from_camera
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
