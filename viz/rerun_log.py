"""A `Logger` that writes an `.rrd` with our blueprint, one method per domain object.

`RerunLogger` hands arrays to Rerun without Python loops; `viz.logger.NullLogger` is its
do-nothing twin for `--no-viz`.
"""

from __future__ import annotations

import uuid
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Final

import numpy as np
import numpy.typing as npt
import rerun as rr

from capture.recording import Intrinsics, RgbdFrame
from viz import layout, rerun_arrays
from viz.logger import (
    DbscanCurves,
    FloatArray,
    IntArray,
    MapKind,
    NullLogger,
    RefineKind,
    TrajectoryKind,
)

_POINT_RADIUS: Final = rr.Radius.ui_points(1.5)
_PALETTE: Final = layout.cluster_palette()


@dataclass(frozen=True, slots=True)
class LiveViewer:
    """Stream the log to a viewer as it is written: spawn a native one, or serve on a port."""

    spawn: bool = False
    port: int = 9876

    @property
    def url(self) -> str:
        """Return the address a viewer connects to: `rerun URL`, or the web viewer's ?url=."""
        return f"rerun+http://127.0.0.1:{self.port}/proxy"


class RerunLogger(NullLogger):
    """A `Logger` that writes an `.rrd` file with the blueprint of `viz.layout`."""

    def __init__(
        self,
        rrd_path: Path,
        *,
        application_id: str = layout.APPLICATION_ID,
        recording_name: str,
        compress: bool = True,
        jpeg_quality: int = 70,
        depth_every_n: int = 30,
        live: LiveViewer | None = None,
    ) -> None:
        """Open rrd_path for writing.

        Args:
            rrd_path: the .rrd to write.
            application_id: the application id the viewer matches blueprints by.
            recording_name: the name the viewer shows.
            compress: colour and confidence as JPEG, depth as lossless PNG; False logs raw
                images (full fidelity, ~1 MB a frame).
            jpeg_quality: the JPEG quality, 1..100.
            depth_every_n: depth (raw and registered) of every n-th frame; keyframes always.
            live: also stream to a viewer (spawned, or a local gRPC server), if given.
        """
        if not 1 <= jpeg_quality <= 100:
            raise ValueError(f"expected jpeg_quality in 1..100, found {jpeg_quality}")
        if depth_every_n < 1:
            raise ValueError(f"expected depth_every_n >= 1, found {depth_every_n}")
        self._compress = compress
        self._jpeg = jpeg_quality if compress else None  # None: raw colour
        self._depth_every_n = depth_every_n
        self._frame = 0
        self._rec = rr.RecordingStream(application_id, recording_id=uuid.uuid4())
        self._rec.set_log_time_enabled(False)  # only our timelines: wall-clock time means nothing
        sinks: list[rr.FileSink | rr.GrpcSink | rr.GrpcServerSink] = [rr.FileSink(rrd_path)]
        if live is not None and live.spawn:  # a native viewer of its own, fed over gRPC
            rr.spawn(port=live.port, connect=False, recording=self._rec)
            sinks.append(rr.GrpcSink(live.url))
        elif live is not None:  # a gRPC server on this machine that viewers connect to
            sinks.append(rr.GrpcServerSink(bind_ip="127.0.0.1", port=live.port))
        self._rec.set_sinks(*sinks, default_blueprint=layout.blueprint())
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
        self._frame = index
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

    def log_frame(self, frame: RgbdFrame, *, keyframe: bool = False) -> None:
        """Log a frame's colour and, on keyframes and every depth_every_n-th frame, its depth.

        The pinhole is logged too if it was not yet.
        """
        if not self._calibrated:
            self.log_calibration(frame.color_intrinsics)
        self._rec.log(layout.RGB, rerun_arrays.image(frame.color, "RGB", jpeg_quality=self._jpeg))
        if self._depth_due(keyframe):
            self._rec.log(layout.DEPTH, rerun_arrays.depth(frame.depth_m, png=self._compress))

    def log_registered_depth(self, depth_m: FloatArray, *, keyframe: bool = False) -> None:
        """Log depth registered to the colour camera, in metres (drawn as a cloud in 3-D).

        Logged on keyframes and every depth_every_n-th frame, as the raw depth.
        """
        if self._depth_due(keyframe):
            self._rec.log(layout.DEPTH_REGISTERED, rerun_arrays.depth(depth_m, png=self._compress))

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
        path = rerun_arrays.path_of(kind, layout.TRAJECTORY_KINDS, "trajectory")
        xyz = rerun_arrays.points(positions, "positions")
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
            self._rec.log(layout.CONFIDENCE, rerun_arrays.image(grey, "L", jpeg_quality=self._jpeg))

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
        path = rerun_arrays.path_of(kind, layout.MAP_KINDS, "map")
        xyz = rerun_arrays.points(points, "points")
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
        path = rerun_arrays.path_of(kind, layout.REFINE_KINDS, "refine")
        xyz = rerun_arrays.points(points, "points")
        colors = None if clusters is None else _PALETTE[np.asarray(clusters) % len(_PALETTE)]
        self._rec.log(path, rr.Points3D(xyz, class_ids=labels, colors=colors, radii=_POINT_RADIUS))

    def log_dbscan_curves(self, label_name: str, *, curves: DbscanCurves) -> None:
        """Log eps, MinPts and cluster count over K (timeline `dbscan_k`) and mark the chosen K."""
        chosen_k = curves.chosen_k
        named = {"eps_m": curves.eps_m, "min_pts": curves.min_pts, "n_clusters": curves.n_clusters}
        k, values, chosen = rerun_arrays.curves_over_k(curves.ks, named, chosen_k=chosen_k)
        color = rerun_arrays.label_color(label_name)
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

    def _depth_due(self, keyframe: bool) -> bool:
        """Return whether the current frame's depth is logged: keyframes and every n-th frame."""
        return keyframe or self._frame % self._depth_every_n == 0

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
