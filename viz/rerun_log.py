"""A logger with one method per domain object, writing an `.rrd` with our blueprint; and its twin.

The pipeline holds a `Logger`: a `RerunLogger` normally, a `NullLogger` for `--no-viz`. Methods
take numpy arrays, plain values or capture types, never `process` objects, and hand arrays to
Rerun without Python loops.
"""

from __future__ import annotations

import uuid
from collections.abc import Mapping
from pathlib import Path
from types import TracebackType
from typing import Final, Literal, Self

import numpy as np
import numpy.typing as npt
import rerun as rr

from capture.recording import LABEL_COLORS, LABEL_NAMES, Intrinsics, RgbdFrame
from viz import layout

TrajectoryKind = Literal["estimated", "ground_truth"]
MapKind = Literal["fused", "refined"]
RefineKind = Literal["planes", "outliers", "clusters", "regrown"]
FloatArray = npt.NDArray[np.floating]
IntArray = npt.NDArray[np.integer]

_MM_PER_M: Final = 1000.0
_POINT_RADIUS: Final = rr.Radius.ui_points(1.5)
_PALETTE: Final = layout.cluster_palette()


def _depth_mm(depth_m: FloatArray) -> npt.NDArray[np.uint16]:
    """Return depth in whole millimetres (half the bytes of float32 in the .rrd)."""
    mm: npt.NDArray[np.uint16] = np.clip(depth_m * _MM_PER_M + 0.5, 0.0, 65535.0).astype(np.uint16)
    return mm


def _points(points: FloatArray, name: str) -> npt.NDArray[np.float32]:
    """Return (N, 3) float32 points, or raise ValueError naming the argument."""
    arr = np.asarray(points, dtype=np.float32)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"expected {name} of shape (N, 3), found {arr.shape}; pass xyz rows")
    return arr


def _path_of(kind: str, kinds: Mapping[str, str], what: str) -> str:
    """Return the entity path of a kind, or raise ValueError listing the valid kinds."""
    if kind not in kinds:
        raise ValueError(f"expected a {what} kind in {sorted(kinds)}, found {kind!r}")
    return kinds[kind]


class NullLogger:
    """What the pipeline logs, one method per domain object; this twin does nothing (--no-viz).

    `RerunLogger` overrides every method to write an `.rrd` (kiss-icp's StubVisualizer pattern):
    a method added here without an override logs nothing rather than failing.
    """

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def set_frame(self, index: int, *, stamp_ns: int) -> None:
        """Set the `frame` and `capture_time` timelines for what follows."""

    def set_stage(self, step: int) -> None:
        """Set the `stage` timeline (layout.STAGE_*) for what follows."""

    def log_calibration(self, color_intrinsics: Intrinsics) -> None:
        """Log the colour camera's pinhole, once, static."""

    def log_frame(self, frame: RgbdFrame) -> None:
        """Log a frame's colour (JPEG) and raw depth."""

    def log_registered_depth(self, depth_m: FloatArray) -> None:
        """Log depth registered to the colour camera, in metres."""

    def log_pose(self, world_from_camera: FloatArray, *, keyframe: bool) -> None:
        """Log the camera pose of the current frame and mark keyframes."""

    def log_keypoints(
        self,
        xy: FloatArray,
        *,
        inliers: npt.NDArray[np.bool_],
        matched_xy: FloatArray | None = None,
    ) -> None:
        """Log keypoints in colour pixels, inliers green; optionally their matched pixels."""

    def log_tracking(self, n_inliers: int, *, status: str, event: str | None = None) -> None:
        """Log the tracking inlier count, the status when it changes, and an event."""

    def log_trajectory(
        self, kind: TrajectoryKind, stamps_ns: IntArray, positions: FloatArray
    ) -> None:
        """Log a whole trajectory (estimated or ground truth)."""

    def log_segmentation(self, labels: IntArray, *, confidence: FloatArray | None = None) -> None:
        """Log a label image (RECORDING.md ids) and its per-pixel confidence in [0, 1]."""

    def log_timing(self, stage: str, seconds: float) -> None:
        """Log the time a stage took, in seconds."""

    def log_text(self, message: str, *, level: str = "INFO") -> None:
        """Log a line of text at a level (TRACE, DEBUG, INFO, WARN, ERROR, CRITICAL)."""

    def log_map(
        self,
        kind: MapKind,
        points: FloatArray,
        *,
        colors: npt.NDArray[np.uint8] | None = None,
        labels: IntArray | None = None,
    ) -> None:
        """Log a labelled point map (fused or refined)."""

    def log_refine(
        self,
        kind: RefineKind,
        points: FloatArray,
        *,
        labels: IntArray | None = None,
        clusters: IntArray | None = None,
    ) -> None:
        """Log the points of one refinement step, coloured by cluster where given."""

    def log_dbscan_curves(
        self,
        label_name: str,
        *,
        ks: IntArray,
        eps_m: FloatArray,
        min_pts: FloatArray,
        n_clusters: IntArray,
        chosen_k: int,
    ) -> None:
        """Log the adaptive-DBSCAN curves over K of one class and mark the chosen K."""

    def log_metrics(self, section: str, values: Mapping[str, float]) -> None:
        """Log named scalar metrics of one section."""

    def close(self) -> None:
        """Flush and finish the output."""


Logger = NullLogger  # the type the pipeline holds: a RerunLogger or its do-nothing twin


class RerunLogger(NullLogger):
    """A `Logger` that writes an `.rrd` file with the blueprint of `viz.layout`."""

    def __init__(
        self,
        rrd_path: Path,
        *,
        application_id: str = layout.APPLICATION_ID,
        recording_name: str,
        jpeg_quality: int = 90,
    ) -> None:
        if not 1 <= jpeg_quality <= 100:
            raise ValueError(f"expected jpeg_quality in 1..100, found {jpeg_quality}")
        self._jpeg_quality = jpeg_quality
        self._rec = rr.RecordingStream(application_id, recording_id=uuid.uuid4())
        self._rec.set_log_time_enabled(False)  # only our timelines: wall-clock time means nothing
        self._rec.save(rrd_path, default_blueprint=layout.blueprint())
        self._rec.send_recording_name(recording_name)
        self._rec.log("/", layout.annotation_context(), static=True)
        overlay = layout.annotation_context(unlabelled_alpha=0)  # see the image through label 0
        self._rec.log(layout.SEGMENTATION, overlay, static=True)
        self._rec.log(layout.WORLD, rr.ViewCoordinates.RDF, static=True)
        self._calibrated = False
        self._camera: rr.Transform3D | None = None
        self._status: str | None = None
        self._styled: set[str] = set()
        self._frame_of_stamp: dict[int, int] = {}  # 16 bytes a frame: kept for log_trajectory
        self._closed = False

    def set_frame(self, index: int, *, stamp_ns: int) -> None:
        """Set the `frame` and `capture_time` timelines for what follows."""
        self._rec.set_time(layout.TIMELINE_FRAME, sequence=index)
        self._rec.set_time(layout.TIMELINE_CAPTURE_TIME, timestamp=np.datetime64(stamp_ns, "ns"))
        self._frame_of_stamp[stamp_ns] = index

    def set_stage(self, step: int) -> None:
        """Set the `stage` timeline (layout.STAGE_*); clear the refine points of earlier steps."""
        if not layout.STAGE_FUSED <= step <= layout.STAGE_FINAL:
            raise ValueError(f"expected a stage step in 0..{layout.STAGE_FINAL}, found {step}")
        self._rec.set_time(layout.TIMELINE_STAGE, sequence=step)
        # Each step shows only its own points under /world/refine, not the steps before it.
        self._rec.log(layout.REFINE, rr.Clear(recursive=True))
        if self._camera is not None:  # the camera stays where the last frame left it
            self._rec.log(layout.CAMERA, self._camera)

    def log_calibration(self, color_intrinsics: Intrinsics) -> None:
        """Log the colour camera's pinhole, once, static."""
        k = color_intrinsics
        pinhole = rr.Pinhole(
            image_from_camera=k.matrix,
            resolution=[k.width, k.height],
            camera_xyz=rr.ViewCoordinates.RDF,
            image_plane_distance=0.3,
        )
        self._rec.log(layout.CAMERA, pinhole, static=True)
        self._calibrated = True

    def log_frame(self, frame: RgbdFrame) -> None:
        """Log a frame's colour (JPEG) and raw depth; the pinhole too if not logged yet."""
        if not self._calibrated:
            self.log_calibration(frame.color_intrinsics)
        rgb = rr.Image(frame.color, color_model="RGB").compress(jpeg_quality=self._jpeg_quality)
        self._rec.log(layout.RGB, rgb)
        self._rec.log(layout.DEPTH, rr.DepthImage(_depth_mm(frame.depth_m), meter=_MM_PER_M))

    def log_registered_depth(self, depth_m: FloatArray) -> None:
        """Log depth registered to the colour camera, in metres (drawn as a cloud in 3-D)."""
        self._rec.log(layout.DEPTH_REGISTERED, rr.DepthImage(_depth_mm(depth_m), meter=_MM_PER_M))

    def log_pose(self, world_from_camera: FloatArray, *, keyframe: bool) -> None:
        """Log the camera pose of the current frame and mark keyframes on the trail."""
        m = np.asarray(world_from_camera, dtype=np.float64)
        if m.shape != (4, 4):
            raise ValueError(f"expected world_from_camera of shape (4, 4), found {m.shape}")
        self._camera = rr.Transform3D(translation=m[:3, 3], mat3x3=m[:3, :3])
        self._rec.log(layout.CAMERA, self._camera)
        position = m[None, :3, 3]
        trail = rr.Points3D(position, colors=layout.TRACKED_RGB, radii=_POINT_RADIUS)
        self._rec.log(layout.TRAJECTORY_TRACKED, trail)
        if keyframe:
            mark = rr.Points3D(position, colors=layout.KEYFRAME_RGB, radii=rr.Radius.ui_points(4.0))
            self._rec.log(layout.TRAJECTORY_KEYFRAMES, mark)

    def log_keypoints(
        self,
        xy: FloatArray,
        *,
        inliers: npt.NDArray[np.bool_],
        matched_xy: FloatArray | None = None,
    ) -> None:
        """Log keypoints in colour pixels, inliers green; optionally lines to their matches."""
        inl = np.asarray(inliers, dtype=bool)
        colors = np.where(inl[:, None], layout.INLIER_RGB, layout.OUTLIER_RGB).astype(np.uint8)
        self._rec.log(layout.KEYPOINTS, rr.Points2D(xy, colors=colors, radii=_POINT_RADIUS))
        if matched_xy is not None:
            strips = np.stack([np.asarray(xy)[inl], np.asarray(matched_xy)[inl]], axis=1)
            self._rec.log(layout.MATCHES, rr.LineStrips2D(strips, colors=layout.INLIER_RGB))

    def log_tracking(self, n_inliers: int, *, status: str, event: str | None = None) -> None:
        """Log the inlier count, the status when it changes, an event as text (WARN unless ok)."""
        self._rec.log(layout.PLOT_INLIERS, rr.Scalars(float(n_inliers)))
        if status != self._status:
            self._rec.log(layout.PLOT_TRACKING_STATUS, rr.StateChange(state=status))
            self._status = status
        if event is not None:
            level = "INFO" if status == layout.TRACKING_OK else "WARN"
            self.log_text(f"tracking {status}: {event}", level=level)

    def log_trajectory(
        self, kind: TrajectoryKind, stamps_ns: IntArray, positions: FloatArray
    ) -> None:
        """Log a whole trajectory: a static line and, per stamp, a marker of where it is."""
        path = _path_of(kind, layout.TRAJECTORY_KINDS, "trajectory")
        xyz = _points(positions, "positions")
        stamps = np.asarray(stamps_ns, dtype=np.int64)
        if stamps.shape != (len(xyz),):
            raise ValueError(
                f"expected {len(xyz)} stamps_ns, one per position, found {stamps.shape}"
            )
        color = layout.TRAJECTORY_RGB[kind]
        self._rec.log(path, rr.LineStrips3D([xyz], colors=color), static=True)
        if len(xyz) == 0:
            return
        indexes = [rr.TimeColumn(layout.TIMELINE_CAPTURE_TIME, timestamp=stamps.view("M8[ns]"))]
        frames = [self._frame_of_stamp.get(int(s)) for s in stamps]
        if all(f is not None for f in frames):
            indexes.append(rr.TimeColumn(layout.TIMELINE_FRAME, sequence=frames))  # type: ignore[arg-type]
        self._rec.send_columns(path, indexes=indexes, columns=rr.Points3D.columns(positions=xyz))
        self._style(path, rr.Points3D.from_fields(colors=color, radii=rr.Radius.ui_points(4.0)))

    def log_segmentation(self, labels: IntArray, *, confidence: FloatArray | None = None) -> None:
        """Log a label image (RECORDING.md ids) and its per-pixel confidence in [0, 1]."""
        ids = np.asarray(labels, dtype=np.uint8)
        self._rec.log(layout.SEGMENTATION, rr.SegmentationImage(ids, opacity=0.5))
        if confidence is not None:
            grey = np.clip(np.asarray(confidence) * 255.0 + 0.5, 0.0, 255.0).astype(np.uint8)
            self._rec.log(layout.CONFIDENCE, rr.Image(grey, color_model="L"))

    def log_timing(self, stage: str, seconds: float) -> None:
        """Log the time a stage took, in seconds."""
        self._rec.log(layout.timing_path(stage), rr.Scalars(float(seconds)))

    def log_text(self, message: str, *, level: str = "INFO") -> None:
        """Log a line of text at a level (TRACE, DEBUG, INFO, WARN, ERROR, CRITICAL)."""
        self._rec.log(layout.LOGS, rr.TextLog(message, level=level))

    def log_map(
        self,
        kind: MapKind,
        points: FloatArray,
        *,
        colors: npt.NDArray[np.uint8] | None = None,
        labels: IntArray | None = None,
    ) -> None:
        """Log a map in label colours, RGB ones at `<map>/rgb`; a refined map replaces the fused."""
        path = _path_of(kind, layout.MAP_KINDS, "map")
        xyz = _points(points, "points")
        if kind == "refined":  # the same places, relabelled: hide the fused map from now on
            self._rec.log(layout.MAP_FUSED, rr.Clear(recursive=True))
        if labels is None:
            self._rec.log(path, rr.Points3D(xyz, colors=colors, radii=_POINT_RADIUS))
            return
        self._rec.log(path, rr.Points3D(xyz, class_ids=labels, radii=_POINT_RADIUS))
        if colors is not None:
            rgb = rr.Points3D(xyz, colors=colors, radii=_POINT_RADIUS)
            self._rec.log(f"{path}/{layout.MAP_RGB_CHILD}", rgb)

    def log_refine(
        self,
        kind: RefineKind,
        points: FloatArray,
        *,
        labels: IntArray | None = None,
        clusters: IntArray | None = None,
    ) -> None:
        """Log the points of one refinement step, coloured by cluster (0 = none, grey) if given."""
        path = _path_of(kind, layout.REFINE_KINDS, "refine")
        xyz = _points(points, "points")
        colors = None if clusters is None else _PALETTE[np.asarray(clusters) % len(_PALETTE)]
        self._rec.log(path, rr.Points3D(xyz, class_ids=labels, colors=colors, radii=_POINT_RADIUS))

    def log_dbscan_curves(
        self,
        label_name: str,
        *,
        ks: IntArray,
        eps_m: FloatArray,
        min_pts: FloatArray,
        n_clusters: IntArray,
        chosen_k: int,
    ) -> None:
        """Log eps, MinPts and cluster count over K (timeline `dbscan_k`) and mark the chosen K."""
        k = np.asarray(ks, dtype=np.int64)
        curves = {"eps_m": eps_m, "min_pts": min_pts, "n_clusters": n_clusters}
        values = {name: np.asarray(v, dtype=np.float64) for name, v in curves.items()}
        if any(v.shape != k.shape for v in values.values()) or k.ndim != 1:
            shapes = {name: v.shape for name, v in values.items()}
            raise ValueError(f"expected curves of the shape of ks {k.shape}, found {shapes}")
        chosen = np.flatnonzero(k == chosen_k)
        if len(chosen) == 0:
            raise ValueError(f"expected chosen_k among ks {k.min()}..{k.max()}, found {chosen_k}")
        color = self._label_color(label_name)
        for name, v in values.items():
            path = layout.dbscan_path(name, label_name)
            self._style(path, rr.SeriesLines(names=label_name, colors=color))
            self._send_curve(path, k, v)
            marker = f"{path}/{layout.DBSCAN_CHOSEN_CHILD}"
            self._style(marker, rr.SeriesPoints(names=f"{label_name} chosen", colors=color))
            self._send_curve(marker, k[chosen[:1]], v[chosen[:1]])
        i = chosen[0]
        self.log_text(
            f"adaptive DBSCAN {label_name}: K={chosen_k}, eps={values['eps_m'][i]:.4f} m, "
            f"MinPts={values['min_pts'][i]:.1f}, clusters={values['n_clusters'][i]:.0f}"
        )

    def log_metrics(self, section: str, values: Mapping[str, float]) -> None:
        """Log named scalar metrics of one section, each at /plots/metrics/<section>/<name>."""
        for name, value in values.items():
            self._rec.log(layout.metric_path(section, name), rr.Scalars(float(value)))

    def close(self) -> None:
        """Flush and finish the .rrd file (its footer included); later calls do nothing."""
        if self._closed:
            return
        self._closed = True
        self._rec.flush()
        self._rec.disconnect()

    def _style(self, path: str, style: rr.AsComponents) -> None:
        """Log a static style (series name, colour) for an entity once."""
        if path not in self._styled:
            self._rec.log(path, style, static=True)
            self._styled.add(path)

    def _send_curve(
        self, path: str, ks: npt.NDArray[np.int64], values: npt.NDArray[np.float64]
    ) -> None:
        """Send a whole curve as scalars over the `dbscan_k` timeline in one call."""
        index = rr.TimeColumn(layout.TIMELINE_DBSCAN_K, sequence=ks)
        self._rec.send_columns(path, indexes=[index], columns=rr.Scalars.columns(scalars=values))

    @staticmethod
    def _label_color(label_name: str) -> tuple[int, int, int] | None:
        """Return the colour of a label by name, None for an unknown name."""
        if label_name in LABEL_NAMES:
            return LABEL_COLORS[LABEL_NAMES.index(label_name)]
        return None


def make_logger(rrd_path: Path | None, *, recording_name: str) -> RerunLogger | NullLogger:
    """Return a RerunLogger writing rrd_path, or a NullLogger when rrd_path is None."""
    if rrd_path is None:
        return NullLogger()
    return RerunLogger(rrd_path, recording_name=recording_name)
