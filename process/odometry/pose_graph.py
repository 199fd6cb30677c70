"""The keyframe pose graph: relative-pose constraints, optimised with GTSAM (sparse)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import gtsam
import numpy as np
import numpy.typing as npt

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

    def optimise(
        self, *, max_correspondence_m: float, prune_threshold: float, first_free: int = 0
    ) -> tuple[float, int]:
        """Optimise the poses (GTSAM, sparse Levenberg-Marquardt) and prune bad loop closures.

        Keyframes before `first_free` are held where they are and only edges reaching a later
        keyframe take part (a local optimisation whose cost does not grow with the map); with 0
        every pose is optimised.

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
        local = [e for e in self.edges if max(e.source, e.target) >= first_free]
        new = _solve(self.poses, local, mu, first_free)
        pruned = [e for e in local if e.uncertain and _line_process(e, new, mu) < prune_threshold]
        if pruned:
            local = [e for e in local if all(e is not p for p in pruned)]
            new = _solve(self.poses, local, mu, first_free)
        moved = max(
            float(np.linalg.norm(a[:3, 3] - b[:3, 3])) for a, b in zip(new, self.poses, strict=True)
        )
        self.poses = new
        self.edges = [e for e in self.edges if all(e is not p for p in pruned)]
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
    poses: Sequence[npt.NDArray[np.float64]], edges: Sequence[Edge], mu: float, first_free: int
) -> list[npt.NDArray[np.float64]]:
    """Return the poses that best agree with the edges; keyframe 0 and those < first_free held."""
    graph = gtsam.NonlinearFactorGraph()
    initial = gtsam.Values()
    nodes = {i for e in edges for i in (e.source, e.target)} | set(range(first_free, len(poses)))
    for i in sorted(nodes | {0}):
        initial.insert(i, gtsam.Pose3(poses[i]))
        if i == 0 or i < first_free:
            graph.add(gtsam.PriorFactorPose3(i, gtsam.Pose3(poses[i]), _FIXED))
    for edge in edges:
        graph.add(_factor(edge, _noise(edge, mu)))
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(100)
    result = gtsam.LevenbergMarquardtOptimizer(graph, initial, params).optimize()
    return [
        np.asarray(result.atPose3(i).matrix(), np.float64) if i in nodes else pose
        for i, pose in enumerate(poses)
    ]


def _line_process(edge: Edge, poses: Sequence[npt.NDArray[np.float64]], mu: float) -> float:
    """Return Open3D's line-process weight (mu / (mu + chi2))^2 of an edge at these poses."""
    values = gtsam.Values()
    values.insert(edge.target, gtsam.Pose3(poses[edge.target]))
    values.insert(edge.source, gtsam.Pose3(poses[edge.source]))
    chi2 = 2.0 * _factor(edge, _gaussian(edge)).error(values)
    return float((mu / (mu + chi2)) ** 2)
