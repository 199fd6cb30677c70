"""How the project looks in Rerun: timelines, entity paths, the annotation context, the blueprint.

Every name another module logs to or queries is a `Final` constant here, so a path is spelled once.

Timelines:
- `capture_time` (timestamp, the frame's `stamp_ns`) and `frame` (sequence, the frame index) for
  everything that happens per frame;
- `stage` (sequence, `STAGE_*`) for the refinement steps of the fused cloud;
- `dbscan_k` (sequence, K of the adaptive DBSCAN) for the eps / MinPts / cluster-count curves of
  the paper's Figs. 4-5. Rerun plots a time series against the timeline selected in the time
  panel, so these curves show when `dbscan_k` is selected there; they carry no other timeline.
"""

from __future__ import annotations

import re
from typing import Final

import numpy as np
import numpy.typing as npt
import rerun as rr
import rerun.blueprint as rrb

from capture.recording import LABEL_COLORS, LABEL_NAMES

APPLICATION_ID: Final = "semreplay"

# Timelines.
TIMELINE_CAPTURE_TIME: Final = "capture_time"
TIMELINE_FRAME: Final = "frame"
TIMELINE_STAGE: Final = "stage"
TIMELINE_DBSCAN_K: Final = "dbscan_k"

# Steps of the `stage` timeline (the refinement of the fused cloud, paper Fig. 1).
STAGE_FUSED: Final = 0
STAGE_PLANES: Final = 1
STAGE_SOR: Final = 2
STAGE_DBSCAN: Final = 3
STAGE_REGROWTH: Final = 4
STAGE_FINAL: Final = 5
STAGE_NAMES: Final[tuple[str, ...]] = ("fused", "planes", "SOR", "DBSCAN", "regrowth", "final")

# The world and the camera (colour optical frame, RDF).
WORLD: Final = "/world"
CAMERA: Final = "/world/camera"
IMAGE: Final = "/world/camera/image"
RGB: Final = "/world/camera/image/rgb"
DEPTH: Final = "/world/camera/image/depth"  # raw depth, depth camera geometry: 2-D view only
DEPTH_REGISTERED: Final = "/world/camera/image/depth_registered"  # in colour geometry
SEGMENTATION: Final = "/world/camera/image/segmentation"
CONFIDENCE: Final = "/world/camera/image/confidence"
KEYPOINTS: Final = "/world/camera/image/keypoints"
MATCHES: Final = "/world/camera/image/matches"  # keypoint -> its match in the reference keyframe

# Trajectories.
TRAJECTORY: Final = "/world/trajectory"
TRAJECTORY_ESTIMATED: Final = "/world/trajectory/estimated"  # whole, from log_trajectory
TRAJECTORY_GROUND_TRUTH: Final = "/world/trajectory/ground_truth"
TRAJECTORY_TRACKED: Final = "/world/trajectory/tracked"  # one point per frame, as tracked
TRAJECTORY_KEYFRAMES: Final = "/world/trajectory/keyframes"  # one point per keyframe
TRAJECTORY_KINDS: Final[dict[str, str]] = {
    "estimated": TRAJECTORY_ESTIMATED,
    "ground_truth": TRAJECTORY_GROUND_TRUTH,
}

# Maps and refinement steps.
MAP: Final = "/world/map"
MAP_FUSED: Final = "/world/map/fused"
MAP_REFINED: Final = "/world/map/refined"
MAP_KINDS: Final[dict[str, str]] = {"fused": MAP_FUSED, "refined": MAP_REFINED}
MAP_RGB_CHILD: Final = "rgb"  # `<map>/rgb`: the same points in their colours, hidden by default
REFINE: Final = "/world/refine"
REFINE_KINDS: Final[dict[str, str]] = {
    kind: f"{REFINE}/{kind}" for kind in ("planes", "outliers", "clusters", "regrown", "seams")
}

# Plots (scalars) and logs.
PLOTS: Final = "/plots"
PLOT_TRACKING: Final = "/plots/tracking"
PLOT_INLIERS: Final = "/plots/tracking/inliers"
PLOT_TRACKING_STATUS: Final = "/plots/tracking/status"  # StateChange, logged when it changes
TRACKING_OK: Final = "ok"  # the tracking status that is not a warning
PLOT_TIMING: Final = "/plots/timing"  # /plots/timing/<stage>, seconds
PLOT_METRICS: Final = "/plots/metrics"  # /plots/metrics/<section>/<name>
PLOT_DBSCAN: Final = "/plots/dbscan"
PLOT_DBSCAN_CURVES: Final[tuple[str, ...]] = ("eps_m", "min_pts", "n_clusters")
DBSCAN_CHOSEN_CHILD: Final = "chosen"  # <curve>/<label>/chosen: a marker at the chosen K
LOGS: Final = "/logs"

# Colours (RGB) of what has no label colour.
INLIER_RGB: Final = (40, 220, 60)
OUTLIER_RGB: Final = (230, 50, 50)
KEYFRAME_RGB: Final = (30, 140, 250)
TRACKED_RGB: Final = (255, 200, 120)
TRAJECTORY_RGB: Final[dict[str, tuple[int, int, int]]] = {
    "estimated": (255, 140, 0),
    "ground_truth": (60, 200, 60),
}
NO_CLUSTER_RGB: Final = (128, 128, 128)


def cluster_palette(n: int = 64) -> npt.NDArray[np.uint8]:
    """Return n well-spread colours (golden-ratio hues); row 0 is the grey of 'no cluster'."""
    hue = (np.arange(n) * 0.618033988749895) % 1.0
    # HSV (s = 0.75, v = 0.95) to RGB, vectorised over the six sectors of the hue wheel.
    k = (np.array([5.0, 3.0, 1.0])[None, :] + hue[:, None] * 6.0) % 6.0
    rgb = 0.95 - 0.95 * 0.75 * np.clip(np.minimum(k, 4.0 - k), 0.0, 1.0)
    palette: npt.NDArray[np.uint8] = np.round(rgb * 255.0).astype(np.uint8)
    palette[0] = NO_CLUSTER_RGB
    return palette


_UNSAFE = re.compile(r"[^A-Za-z0-9_\-]+")


def path_part(name: str) -> str:
    """Return `name` as one entity-path part: runs of other than [A-Za-z0-9_-] become '_'."""
    part = _UNSAFE.sub("_", name.strip()).strip("_")
    return part or "_"


def timing_path(stage: str) -> str:
    """Return the entity path of a stage's time in seconds."""
    return f"{PLOT_TIMING}/{path_part(stage)}"


def metric_path(section: str, name: str) -> str:
    """Return the entity path of one metric of a section (e.g. phase `III`, `iou`)."""
    return f"{PLOT_METRICS}/{path_part(section)}/{path_part(name)}"


def dbscan_path(curve: str, label_name: str) -> str:
    """Return the entity path of one adaptive-DBSCAN curve (`PLOT_DBSCAN_CURVES`) of a class."""
    return f"{PLOT_DBSCAN}/{curve}/{path_part(label_name)}"


def annotation_context(*, unlabelled_alpha: int = 255) -> rr.AnnotationContext:
    """Return the label table of RECORDING.md with its fixed colours (label 0 at an alpha)."""
    alphas = [unlabelled_alpha] + [255] * (len(LABEL_NAMES) - 1)
    return rr.AnnotationContext(
        [
            rr.AnnotationInfo(id=i, label=name, color=(*color, alpha))
            for i, (name, color, alpha) in enumerate(
                zip(LABEL_NAMES, LABEL_COLORS, alphas, strict=True)
            )
        ]
    )


def _trail() -> rrb.VisibleTimeRanges:
    """Return a time range that shows everything logged up to the time cursor."""
    everything_so_far = [
        rr.VisibleTimeRange(
            timeline,
            start=rr.TimeRangeBoundary.infinite(),
            end=rr.TimeRangeBoundary.cursor_relative(),
        )
        for timeline in (TIMELINE_FRAME, TIMELINE_CAPTURE_TIME)
    ]
    return rrb.VisibleTimeRanges(everything_so_far)


def _world_view() -> rrb.Spatial3DView:
    """Return the 3-D view: camera, depth cloud, trajectories, maps and refinement steps."""
    return rrb.Spatial3DView(
        name="World",
        origin=WORLD,
        contents=[
            "+ $origin/**",
            f"- {DEPTH}",  # raw depth is in the depth camera's geometry, not the pinhole's
            f"- {SEGMENTATION}",
            f"- {CONFIDENCE}",
            f"- {MATCHES}",
        ],
        overrides={
            TRAJECTORY_TRACKED: _trail(),
            TRAJECTORY_KEYFRAMES: _trail(),
            f"{MAP_FUSED}/{MAP_RGB_CHILD}": rrb.EntityBehavior(visible=False),
            f"{MAP_REFINED}/{MAP_RGB_CHILD}": rrb.EntityBehavior(visible=False),
        },
    )


def _image_views() -> rrb.Vertical:
    """Return the 2-D views: colour with keypoints, depth, segmentation and its confidence."""
    colour = rrb.Spatial2DView(
        name="Colour + keypoints", origin=IMAGE, contents=[RGB, KEYPOINTS, MATCHES]
    )
    depth = rrb.Tabs(
        rrb.Spatial2DView(name="Depth (raw)", origin=IMAGE, contents=[DEPTH]),
        rrb.Spatial2DView(name="Depth (registered)", origin=IMAGE, contents=[DEPTH_REGISTERED]),
    )
    labels = rrb.Tabs(
        rrb.Spatial2DView(name="Segmentation", origin=IMAGE, contents=[RGB, SEGMENTATION]),
        rrb.Spatial2DView(name="Confidence", origin=IMAGE, contents=[CONFIDENCE]),
    )
    return rrb.Vertical(colour, depth, labels)


def _plot_views() -> rrb.Tabs:
    """Return the plots: tracking, timing, metrics and the adaptive-DBSCAN curves."""
    tracking = rrb.Vertical(
        rrb.TimeSeriesView(name="Tracking inliers", origin=PLOT_INLIERS),
        rrb.StateTimelineView(name="Tracking status", origin=PLOT_TRACKING_STATUS),
        row_shares=[3, 1],
        name="Tracking",
    )
    dbscan = rrb.Horizontal(
        *(
            rrb.TimeSeriesView(name=f"DBSCAN {curve} over K", origin=f"{PLOT_DBSCAN}/{curve}")
            for curve in PLOT_DBSCAN_CURVES
        ),
        name="DBSCAN (select timeline dbscan_k)",
    )
    return rrb.Tabs(
        tracking,
        rrb.TimeSeriesView(name="Time per stage (s)", origin=PLOT_TIMING),
        rrb.TimeSeriesView(name="Metrics", origin=PLOT_METRICS),
        dbscan,
    )


def blueprint() -> rrb.Blueprint:
    """Build the viewer layout: world and plots on the left, images and logs on the right."""
    left = rrb.Vertical(_world_view(), _plot_views(), row_shares=[3, 2])
    right = rrb.Vertical(
        _image_views(), rrb.TextLogView(name="Log", origin=LOGS), row_shares=[4, 1]
    )
    return rrb.Blueprint(
        rrb.Horizontal(left, right, column_shares=[3, 2]),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(timeline=TIMELINE_CAPTURE_TIME),
    )
