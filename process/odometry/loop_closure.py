"""Place recognition among old keyframes: loop candidates, verified by PnP, as pose-graph edges."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from capture.recording import Intrinsics
from process.geometry import rigid_inverse
from process.odometry.features import Keyframe
from process.odometry.matching import guided_match, match
from process.odometry.pnp import PnpResult, PnpSolver
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


def find_loops(
    current: Keyframe,
    candidates: Sequence[Keyframe],
    *,
    pnp: PnpSolver,
    match_ratio: float,
    min_inliers: int,
    guide: Guide | None = None,
) -> list[tuple[Edge, int]]:
    """Return the verified loop edges (current -> old keyframes) and inlier counts, most first.

    Each candidate is verified by PnP of its 3-D points against the current keypoints, refined
    with the current keyframe's depth. With a guide (the graph's current poses), features are
    first matched by projection around the pose the graph predicts and that pose seeds PnP, as
    in tracking: on texture that repeats (the desk's keyboard, book spines) all-against-all
    matching can reach a consensus that is degrees off. Where that finds fewer matches than
    min_inliers (the graph has drifted far), all-against-all matching is the fallback.
    """
    found: list[tuple[Edge, int]] = []
    for old in candidates:
        prior = guide.camera_from(current.id, old.id) if guide is not None else None
        verified = _verify(current, old, pnp, match_ratio, min_inliers, prior, guide)
        if verified is None:
            continue
        (q, t), result = verified
        inliers_q, inliers_t = q[result.inliers], t[result.inliers]
        k = pnp.camera_matrix
        xy = current.xy[inliers_q].astype(np.float64)
        normalised = np.stack([(xy[:, 0] - k[0, 2]) / k[0, 0], (xy[:, 1] - k[1, 2]) / k[1, 1]], 1)
        refined = refine_with_depth(
            old.points[inliers_t],
            normalised.astype(np.float32),
            current.points[inliers_q, 2],
            camera_from_reference=result.camera_from_reference,
            focal_px=float(k[0, 0]),
        )
        old_from_current = rigid_inverse(refined.camera_from_reference)
        edge = Edge(current.id, old.id, old_from_current, refined.information, True)
        found.append((edge, len(result.inliers)))
    return sorted(found, key=lambda f: -f[1])


@dataclass(frozen=True, slots=True)
class Guide:
    """The graph's current poses, to predict where an old keyframe's points appear."""

    poses: Sequence[npt.NDArray[np.float64]]
    intrinsics: Intrinsics
    radius_px: float

    def camera_from(self, current: int, old: int) -> npt.NDArray[np.float64]:
        """Return the predicted pose of keyframe `old` in keyframe `current`'s camera."""
        return rigid_inverse(self.poses[current]) @ self.poses[old]


def _verify(
    current: Keyframe,
    old: Keyframe,
    pnp: PnpSolver,
    match_ratio: float,
    min_inliers: int,
    prior: npt.NDArray[np.float64] | None,
    guide: Guide | None,
) -> tuple[tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]], PnpResult] | None:
    """Return the matches and PnP pose of old's points in current, or None below min_inliers."""
    if prior is not None and guide is not None and guide.radius_px > 0:
        q, t = guided_match(
            old.points,
            old.descriptors,
            current.xy,
            current.descriptors,
            camera_from_points=prior,
            intrinsics=guide.intrinsics,
            radius_px=guide.radius_px,
            ratio=match_ratio,
        )
        if len(q) >= min_inliers:  # the prediction held: no need to search the whole image
            # A hypothesis grown from the prediction with min_inliers verifies the loop already.
            result = pnp.solve(
                old.points[t],
                current.xy[q],
                min_inliers=min_inliers,
                prior=prior,
                prior_enough=min_inliers,
            )
            return None if result is None else ((q, t), result)
    q, t = match(current.descriptors, old.descriptors, ratio=match_ratio)
    result = pnp.solve(old.points[t], current.xy[q], min_inliers=min_inliers, prior=prior)
    return None if result is None else ((q, t), result)


class LoopCloser:
    """Search each new keyframe's place among old keyframes; on a match, optimise the graph."""

    def __init__(
        self, cfg: OdometryConfig, *, pnp: PnpSolver, graph: PoseGraph, intrinsics: Intrinsics
    ) -> None:
        self.cfg = cfg
        self.pnp = pnp
        self.graph = graph
        self.intrinsics = intrinsics
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
        found = find_loops(
            kf,
            candidates,
            pnp=self.pnp,
            match_ratio=cfg.match_ratio,
            min_inliers=cfg.loop_min_inliers,
            guide=Guide(self.graph.poses, self.intrinsics, cfg.loop_guided_radius_px),
        )
        if not found:
            return ""
        edges = [edge for edge, _ in found[: cfg.loop_edges]]
        for edge in edges:
            self.graph.add_edge(edge)
        edge, n_inliers = found[0]
        # The keyframes before the loops' oldest end keep their poses: only the loops move.
        moved_m, kept = self.graph.optimise(
            max_correspondence_m=cfg.loop_max_correspondence_m,
            prune_threshold=cfg.loop_prune_threshold,
            first_free=min(e.target for e in edges),
        )
        self._cooldown = cfg.loop_cooldown
        return (
            f"loop closure: keyframe {kf.id} matched keyframe {edge.target} ({n_inliers} inliers)"
            f"{f' and {len(edges) - 1} more' if len(edges) > 1 else ''};"
            f" {kept} loop edge(s) kept, keyframes moved by up to {moved_m:.3f} m"
        )
