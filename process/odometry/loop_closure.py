"""Place recognition among old keyframes: loop candidates, verified by PnP, as pose-graph edges."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from process.geometry import rigid_inverse
from process.odometry.features import Keyframe
from process.odometry.matching import match
from process.odometry.pnp import PnpSolver, information_from_points
from process.odometry.pose_graph import Edge, PoseGraph
from process.odometry.pose_refine import refine_with_depth

if TYPE_CHECKING:
    from process.odometry.config import OdometryConfig


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

    def __init__(self, cfg: OdometryConfig, *, pnp: PnpSolver, graph: PoseGraph) -> None:
        self.cfg = cfg
        self.pnp = pnp
        self.graph = graph
        self._cooldown = 0

    def close(self, kf: Keyframe, keyframes: Sequence[Keyframe]) -> str:
        """Return a description of the loop closed from this keyframe, or "" if none was."""
        cfg = self.cfg
        if not cfg.loop_closure:
            return ""
        if self._cooldown > 0:
            self._cooldown -= 1
            return ""
        ids = loop_candidates(
            kf,
            keyframes,
            poses=self.graph.poses,
            min_gap=cfg.loop_min_gap,
            count=cfg.loop_candidates,
            min_similarity=cfg.loop_min_similarity,
            radius_m=cfg.loop_search_radius_m,
        )
        candidates = [keyframes[i] for i in ids]
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
