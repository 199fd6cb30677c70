"""Edges from a new keyframe to the few keyframes before its parent, and a local optimisation.

A keyframe tracked against its parent alone carries that one measurement's error (0.3-0.6 deg on
TUM fr1_rpy, where the Kinect turns up to 180 deg/s) into every later pose. Locating it also
against the keyframes just before the parent, as a tracked frame is (guided matching around the
pose the graph predicts, PnP, refinement with depth), gives the graph several measurements of
the same stretch of path. The keyframes involved are then optimised with the older ones held,
so the cost stays flat in the length of the map (like a small sliding-window smoother).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from process.geometry import rigid_inverse
from process.odometry.features import Keyframe
from process.odometry.locate import Locator
from process.odometry.pose_graph import Edge, PoseGraph

if TYPE_CHECKING:
    from process.odometry.config import OdometryConfig


def link_recent(
    kf: Keyframe,
    parent: Keyframe,
    image: tuple[npt.NDArray[np.float32], npt.NDArray[np.uint8], npt.NDArray[np.float32]],
    *,
    keyframes: Sequence[Keyframe],
    graph: PoseGraph,
    locator: Locator,
    cfg: OdometryConfig,
    twist: npt.NDArray[np.float64] | None = None,
) -> int:
    """Add edges from kf to up to cfg.covisible_keyframes recent keyframes; return how many.

    image is the new keyframe's (keypoints, descriptors, depth); twist its camera's motion per
    second, for a rolling shutter (process.odometry.rolling_shutter). A keyframe is linked only when
    it is located with at least cfg.keyframe_min_inliers inliers; the linked stretch is then
    optimised (keyframes before the oldest linked one held).
    """
    n = cfg.covisible_keyframes
    recent = (
        [k for k in keyframes[-n - 2 : -1] if k is not parent and k is not kf][-n:] if n else []
    )
    xy, descriptors, depth = image
    linked = []
    for other in recent:
        prior = rigid_inverse(graph.poses[kf.id]) @ graph.poses[other.id]
        found = locator.locate(other, xy, descriptors, depth, prior=prior, twist=twist)
        if isinstance(found, str) or len(found.pnp.inliers) < cfg.keyframe_min_inliers:
            continue
        assert found.pnp.information is not None  # Locator gives every pose its information
        edge = Edge(kf.id, other.id, found.pnp.reference_from_camera, found.pnp.information, False)
        graph.add_edge(edge)
        linked.append(other.id)
    if linked:
        graph.optimise(
            max_correspondence_m=cfg.loop_max_correspondence_m,
            prune_threshold=cfg.loop_prune_threshold,
            first_free=min([*linked, parent.id]),
        )
    return len(linked)
