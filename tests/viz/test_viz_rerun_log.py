"""RerunLogger writes what the pipeline hands it where viz.layout says; read back from the .rrd."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt
import pytest
from helpers_viz import RrdContents, assert_rrd_verifies, read_rrd, rerun_verify

from capture.recording import LABEL_NAMES, RecordingReader
from viz import layout
from viz.logger import DbscanCurves, Logger, NullLogger
from viz.rerun_log import RerunLogger

STAMPS_NS = [1_000_000_000 + i * 33_333_333 for i in range(5)]  # those of the `recording` fixture


def _log_recording(recording: Path, rrd: Path, **options: Any) -> RrdContents:
    """Log the 5 frames as the pipeline does (keyframes 2, 4; tracking lost at frame 3)."""
    rng = np.random.default_rng(1)
    with (
        RerunLogger(rrd, recording_name="synthetic", **options) as log,
        RecordingReader(recording) as rec,
    ):
        for frame in rec.frames():
            keyframe = frame.index in (2, 4)
            log.set_frame(frame.index, stamp_ns=frame.stamp_ns)
            log.log_frame(frame, keyframe=keyframe)
            log.log_registered_depth(np.full((480, 640), 1.5, np.float32), keyframe=keyframe)
            assert frame.ground_truth is not None
            assert frame.ground_truth.world_from_camera is not None
            log.log_pose(frame.ground_truth.world_from_camera, keyframe=keyframe)
            xy = rng.uniform(0, 600, (40, 2))
            log.log_keypoints(xy, inliers=np.arange(40) < 30, matched_xy=xy + 2.0)
            lost = frame.index == 3
            log.log_tracking(30, status="lost" if lost else "ok", event="lost" if lost else None)
            if keyframe:
                confidence = np.full((480, 640), 0.5)
                log.log_segmentation(np.full((480, 640), 4, np.uint8), confidence=confidence)
            log.log_timing("odometry", 0.01)
    return read_rrd(rrd)


@pytest.fixture
def logged(recording: Path, tmp_path: Path) -> RrdContents:
    return _log_recording(recording, tmp_path / "frames.rrd")


@pytest.fixture
def full(recording: Path, tmp_path: Path) -> RrdContents:
    return _log_recording(recording, tmp_path / "full.rrd", compress=False, depth_every_n=1)


def test_every_frame_entity_has_one_row_per_frame_on_both_timelines(logged: RrdContents) -> None:
    per_frame = [layout.RGB, layout.KEYPOINTS, layout.MATCHES, layout.CAMERA]
    per_frame += [layout.TRAJECTORY_TRACKED, layout.PLOT_INLIERS, layout.timing_path("odometry")]
    for entity in per_frame:
        assert logged.rows[(entity, layout.TIMELINE_FRAME)] == 5, entity
        assert logged.rows[(entity, layout.TIMELINE_CAPTURE_TIME)] == 5, entity
    assert list(logged.values(layout.RGB, layout.TIMELINE_CAPTURE_TIME)) == STAMPS_NS
    assert list(logged.values(layout.RGB, layout.TIMELINE_FRAME)) == [0, 1, 2, 3, 4]


def test_only_our_timelines_are_written(logged: RrdContents) -> None:
    timelines = {timeline for (_, timeline) in logged.rows}
    assert timelines == {layout.TIMELINE_FRAME, layout.TIMELINE_CAPTURE_TIME}


def test_depth_and_segmentation_are_on_keyframes_and_every_nth_frame(
    logged: RrdContents,
) -> None:
    for entity in (layout.DEPTH, layout.DEPTH_REGISTERED):
        assert list(logged.values(entity, layout.TIMELINE_FRAME)) == [0, 2, 4], entity
    for entity in (layout.SEGMENTATION, layout.CONFIDENCE):
        assert list(logged.values(entity, layout.TIMELINE_FRAME)) == [2, 4], entity


def _png_millimetres(contents: RrdContents, entity: str) -> list[npt.NDArray[Any]]:
    """Decode the lossless depth PNGs of an entity."""
    assert set(contents.values(entity, "EncodedDepthImage:media_type")) == {"image/png"}
    assert set(contents.values(entity, "EncodedDepthImage:meter")) == {1000.0}
    blobs = contents.column(entity, "EncodedDepthImage:blob")
    decoded = [cv2.imdecode(np.asarray(b[0], np.uint8), cv2.IMREAD_UNCHANGED) for b in blobs]
    return [np.asarray(d) for d in decoded]


def test_colour_is_jpeg_and_depth_lossless_png_millimetres(logged: RrdContents) -> None:
    assert set(logged.values(layout.RGB, "EncodedImage:media_type")) == {"image/jpeg"}
    assert set(logged.values(layout.CONFIDENCE, "EncodedImage:media_type")) == {"image/jpeg"}
    depth = _png_millimetres(logged, layout.DEPTH)
    assert len(depth) == 3
    assert all(d.dtype == np.uint16 and d.shape == (480, 640) for d in depth)
    assert all(np.all(d == 2000) for d in depth)  # the fixture's plane at 2 m
    assert all(np.all(d == 1500) for d in _png_millimetres(logged, layout.DEPTH_REGISTERED))


def test_full_fidelity_logs_raw_colour_and_depth_of_every_frame(
    full: RrdContents, recording: Path
) -> None:
    with RecordingReader(recording) as rec:
        colours = [frame.color for frame in rec.frames()]
    rgb = full.values(layout.RGB, "Image:buffer").view(np.uint8).reshape(5, 480, 640, 3)
    np.testing.assert_array_equal(rgb, np.stack(colours))  # not a bit lost
    depth = full.values(layout.DEPTH, "DepthImage:buffer").view(np.uint16)
    assert depth.size == 5 * 480 * 640
    assert np.all(depth == 2000)
    assert set(full.values(layout.DEPTH, "DepthImage:meter")) == {1000.0}
    registered = full.values(layout.DEPTH_REGISTERED, "DepthImage:buffer").view(np.uint16)
    assert registered.size == 5 * 480 * 640
    assert np.all(registered == 1500)
    confidence = full.values(layout.CONFIDENCE, "Image:buffer").view(np.uint8)
    assert np.all(confidence == 128)


@pytest.mark.parametrize(
    ("options", "match"), [({"jpeg_quality": 0}, "jpeg_quality"), ({"depth_every_n": 0}, "depth")]
)
def test_bad_options_are_refused(tmp_path: Path, options: dict[str, int], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        RerunLogger(tmp_path / "x.rrd", recording_name="x", **options)  # type: ignore[arg-type]


def test_pinhole_is_static_once_with_the_colour_intrinsics(logged: RrdContents) -> None:
    assert logged.static[layout.CAMERA] == 1
    k = logged.values(layout.CAMERA, "Pinhole:image_from_camera").reshape(3, 3).T
    np.testing.assert_allclose(k, [[615, 0, 320], [0, 615, 240], [0, 0, 1]])
    np.testing.assert_array_equal(logged.values(layout.CAMERA, "Pinhole:resolution"), [640, 480])


def test_pose_translations_are_the_ground_truth(logged: RrdContents) -> None:
    translation = logged.values(layout.CAMERA, "Transform3D:translation").reshape(-1, 3)
    np.testing.assert_allclose(translation[:, 0], [0.0, 0.01, 0.02, 0.03, 0.04], atol=1e-7)
    np.testing.assert_allclose(translation[:, 1:], 0.0)


def test_keyframes_and_status_changes_are_marked(logged: RrdContents) -> None:
    assert list(logged.values(layout.TRAJECTORY_KEYFRAMES, layout.TIMELINE_FRAME)) == [2, 4]
    status = logged.values(layout.PLOT_TRACKING_STATUS, "StateChange:state")
    assert list(status) == ["ok", "lost", "ok"]
    assert list(logged.values(layout.PLOT_TRACKING_STATUS, layout.TIMELINE_FRAME)) == [0, 3, 4]
    assert list(logged.values(layout.LOGS, "TextLog:level")) == ["WARN"]


def test_keypoints_colour_inliers_and_draw_only_inlier_matches(logged: RrdContents) -> None:
    colors = logged.values(layout.KEYPOINTS, "Points2D:colors")[:40]
    r, g, b = layout.INLIER_RGB
    assert np.all(colors[:30] == (r << 24 | g << 16 | b << 8 | 255))
    assert np.all(colors[30:] != colors[0])
    strips = logged.values(layout.MATCHES, "LineStrips2D:strips").reshape(5, 30, 2, 2)
    np.testing.assert_allclose(strips[:, :, 1] - strips[:, :, 0], 2.0, atol=1e-4)


def test_rrd_verifies_and_carries_the_blueprint(logged: RrdContents, tmp_path: Path) -> None:
    assert logged.application_id == layout.APPLICATION_ID
    assert logged.blueprints == 1
    result = rerun_verify(tmp_path / "frames.rrd")
    assert result.returncode == 0, result.stderr


def test_rerun_verify_fails_on_a_truncated_rrd(logged: RrdContents, tmp_path: Path) -> None:
    data = (tmp_path / "frames.rrd").read_bytes()
    (tmp_path / "cut.rrd").write_bytes(data[: len(data) // 2])
    assert rerun_verify(tmp_path / "cut.rrd").returncode != 0


def test_annotation_context_is_static_at_root_with_the_eleven_labels(tmp_path: Path) -> None:
    RerunLogger(tmp_path / "a.rrd", recording_name="a").close()
    contents = read_rrd(tmp_path / "a.rrd")
    assert contents.static["/"] == 1
    (row,) = contents.column("/", "AnnotationContext:context")
    assert isinstance(row, list)
    (context,) = row  # one instance: the whole table
    names = [c["class_description"]["info"]["label"] for c in context]
    assert names == list(LABEL_NAMES)
    assert names[9] == "tv monitor"
    assert len(names) == 11
    colour_of_wall = context[3]["class_description"]["info"]["color"]
    assert colour_of_wall == (170 << 24 | 170 << 16 | 170 << 8 | 255)


def test_trajectory_is_a_static_line_and_one_marker_per_stamp(tmp_path: Path) -> None:
    positions = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0]], np.float64)
    with RerunLogger(tmp_path / "t.rrd", recording_name="t") as log:
        for i, stamp in enumerate(STAMPS_NS[:3]):
            log.set_frame(i, stamp_ns=stamp)
        log.log_trajectory("estimated", np.array(STAMPS_NS[:3]), positions)
        log.log_trajectory("ground_truth", np.array([7, 8, 9]), positions + 1)  # stamps of no frame
    contents = read_rrd(tmp_path / "t.rrd")
    est, gt = layout.TRAJECTORY_ESTIMATED, layout.TRAJECTORY_GROUND_TRUTH
    strip = contents.values(est, "LineStrips3D:strips").reshape(-1, 3)
    np.testing.assert_allclose(strip, positions)
    assert list(contents.values(est, layout.TIMELINE_CAPTURE_TIME)) == STAMPS_NS[:3]
    assert list(contents.values(est, layout.TIMELINE_FRAME)) == [0, 1, 2]
    assert list(contents.values(gt, layout.TIMELINE_CAPTURE_TIME)) == [7, 8, 9]
    assert contents.rows[(gt, layout.TIMELINE_FRAME)] == 0


def test_map_of_300k_points_keeps_labels_and_rgb_apart(tmp_path: Path) -> None:
    n = 300_000
    rng = np.random.default_rng(2)
    points = rng.uniform(-5, 5, (n, 3)).astype(np.float32)
    labels = rng.integers(0, 11, n).astype(np.uint8)
    colors = rng.integers(0, 256, (n, 3)).astype(np.uint8)
    with RerunLogger(tmp_path / "m.rrd", recording_name="m") as log:
        log.set_stage(layout.STAGE_FUSED)
        t0 = time.perf_counter()
        log.log_map("fused", points, colors=colors, labels=labels)
        seconds = time.perf_counter() - t0
        log.log_map("refined", points[:10], labels=labels[:10])
    contents = read_rrd(tmp_path / "m.rrd")
    assert seconds < 2.0  # arrays go through without Python loops (~0.05 s here)
    np.testing.assert_array_equal(contents.values(layout.MAP_FUSED, "Points3D:class_ids"), labels)
    np.testing.assert_allclose(
        contents.values(layout.MAP_FUSED, "Points3D:positions"), points.ravel()
    )
    rgb = contents.values(f"{layout.MAP_FUSED}/rgb", "Points3D:colors")
    np.testing.assert_array_equal(rgb >> 24, colors[:, 0])
    assert "Points3D:colors" not in contents.columns[layout.MAP_FUSED]
    assert f"{layout.MAP_REFINED}/rgb" not in contents.entities()
    assert list(contents.values(layout.MAP_FUSED, layout.TIMELINE_STAGE)) == [0, 0]
    # the refined map replaces the fused one: a recursive clear, logged after the fused points
    assert list(contents.values(layout.MAP_FUSED, "Clear:is_recursive")) == [True]


def test_refine_step_colours_points_by_cluster_on_the_stage_timeline(tmp_path: Path) -> None:
    clusters = np.array([0, 1, 1, 2, 3, 0])
    with RerunLogger(tmp_path / "r.rrd", recording_name="r") as log:
        log.set_stage(layout.STAGE_DBSCAN)
        log.log_refine("clusters", np.zeros((6, 3)), labels=np.full(6, 5), clusters=clusters)
    contents = read_rrd(tmp_path / "r.rrd")
    path = layout.REFINE_KINDS["clusters"]
    colors = contents.values(path, "Points3D:colors")
    grey = layout.NO_CLUSTER_RGB[0] << 24 | layout.NO_CLUSTER_RGB[1] << 16
    assert colors[0] == colors[5] == grey | layout.NO_CLUSTER_RGB[2] << 8 | 255
    assert colors[1] == colors[2]
    assert len({colors[0], colors[1], colors[3], colors[4]}) == 4
    assert list(contents.values(path, "Points3D:class_ids")) == [5] * 6
    assert list(contents.values(path, layout.TIMELINE_STAGE)) == [layout.STAGE_DBSCAN]


def test_each_stage_clears_the_refine_points_of_earlier_steps_and_keeps_the_camera(
    tmp_path: Path,
) -> None:
    pose = np.eye(4)
    pose[:3, 3] = [1.0, 2.0, 3.0]
    with RerunLogger(tmp_path / "st.rrd", recording_name="st") as log:
        log.set_frame(0, stamp_ns=1)
        log.log_pose(pose, keyframe=True)
        for step in (layout.STAGE_PLANES, layout.STAGE_SOR):
            log.set_stage(step)
            log.log_refine("planes" if step == layout.STAGE_PLANES else "outliers", np.ones((4, 3)))
    contents = read_rrd(tmp_path / "st.rrd")
    assert list(contents.values(layout.REFINE, layout.TIMELINE_STAGE)) == [1, 2]
    assert list(contents.values(layout.REFINE, "Clear:is_recursive")) == [True, True]
    assert list(contents.values(layout.CAMERA, layout.TIMELINE_STAGE)) == [1, 2]
    translation = contents.values(layout.CAMERA, "Transform3D:translation").reshape(-1, 3)
    np.testing.assert_allclose(translation, [[1, 2, 3]] * 3)


def test_segmentation_overlay_shows_the_image_through_label_zero(tmp_path: Path) -> None:
    RerunLogger(tmp_path / "o.rrd", recording_name="o").close()
    contents = read_rrd(tmp_path / "o.rrd")
    ((context,),) = contents.column(layout.SEGMENTATION, "AnnotationContext:context")
    colours = [c["class_description"]["info"]["color"] for c in context]
    assert colours[0] & 0xFF == 0  # alpha of 'unlabelled'
    assert all(c & 0xFF == 255 for c in colours[1:])


def test_dbscan_curves_lie_on_the_k_timeline_only_with_the_chosen_k_marked(tmp_path: Path) -> None:
    ks = np.arange(1, 11)
    n_clusters = np.array([6, 4, 3, 3, 3, 2, 2, 1, 1, 1])
    with RerunLogger(tmp_path / "d.rrd", recording_name="d") as log:
        log.set_stage(layout.STAGE_DBSCAN)
        curves = DbscanCurves(ks, ks * 0.01, ks + 4.0, n_clusters, chosen_k=5)
        log.log_dbscan_curves("tv monitor", curves=curves)
    contents = read_rrd(tmp_path / "d.rrd")
    for curve, expected in (
        ("eps_m", ks * 0.01),
        ("min_pts", ks + 4.0),
        ("n_clusters", n_clusters),
    ):
        path = layout.dbscan_path(curve, "tv monitor")
        assert path == f"/plots/dbscan/{curve}/tv_monitor"
        assert contents.timelines(path) == {layout.TIMELINE_DBSCAN_K}
        assert list(contents.values(path, layout.TIMELINE_DBSCAN_K)) == list(ks)
        np.testing.assert_allclose(contents.values(path, "Scalars:scalars"), expected)
        marker = f"{path}/chosen"
        assert list(contents.values(marker, layout.TIMELINE_DBSCAN_K)) == [5]
        np.testing.assert_allclose(contents.values(marker, "Scalars:scalars"), expected[4])
    (text,) = contents.values(layout.LOGS, "TextLog:text")
    assert "K=5" in text and "eps=0.0500 m" in text


def test_metrics_are_one_scalar_per_name(tmp_path: Path) -> None:
    with RerunLogger(tmp_path / "s.rrd", recording_name="s") as log:
        log.set_stage(layout.STAGE_FINAL)
        log.log_metrics("phase III", {"iou": 0.75, "f1": 0.5})
    contents = read_rrd(tmp_path / "s.rrd")
    assert list(contents.values("/plots/metrics/phase_III/iou", "Scalars:scalars")) == [0.75]
    assert list(contents.values("/plots/metrics/phase_III/f1", "Scalars:scalars")) == [0.5]


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda log: log.log_map("dense", np.zeros((2, 3))), "map kind"),
        (lambda log: log.log_refine("sor", np.zeros((2, 3))), "refine kind"),
        (lambda log: log.log_trajectory("gt", np.zeros(2), np.zeros((2, 3))), "trajectory kind"),
        (lambda log: log.log_trajectory("estimated", np.zeros(3), np.zeros((2, 3))), "stamps_ns"),
        (lambda log: log.log_map("fused", np.zeros((2, 2))), r"shape \(N, 3\)"),
        (lambda log: log.log_pose(np.eye(3), keyframe=False), r"\(4, 4\)"),
        (lambda log: log.set_stage(6), "stage step"),
        (
            lambda log: log.log_dbscan_curves(
                "chair",
                curves=DbscanCurves(
                    np.arange(1, 4), np.ones(3), np.full(3, 4.0), np.ones(3, int), chosen_k=9
                ),
            ),
            "chosen_k",
        ),
    ],
)
def test_bad_arguments_raise_one_line_value_errors(tmp_path: Path, call, match: str) -> None:  # type: ignore[no-untyped-def]
    with (
        RerunLogger(tmp_path / "bad.rrd", recording_name="bad") as log,
        pytest.raises(ValueError, match=match) as info,
    ):
        call(log)
    assert "\n" not in str(info.value)
    assert_rrd_verifies(tmp_path / "bad.rrd")  # what was logged before the error stays readable


def test_empty_inputs_of_a_lost_frame_are_logged_and_verify(tmp_path: Path) -> None:
    with RerunLogger(tmp_path / "e.rrd", recording_name="e") as log:
        log.set_frame(0, stamp_ns=5)
        log.log_keypoints(np.zeros((0, 2)), inliers=np.zeros(0, bool), matched_xy=np.zeros((0, 2)))
        log.log_trajectory("estimated", np.zeros(0, np.int64), np.zeros((0, 3)))
        log.log_map("fused", np.zeros((0, 3)), labels=np.zeros(0, np.uint8))
    contents = read_rrd(tmp_path / "e.rrd")
    assert contents.rows[(layout.KEYPOINTS, layout.TIMELINE_FRAME)] == 1
    assert contents.values(layout.KEYPOINTS, "Points2D:positions").size == 0
    assert rerun_verify(tmp_path / "e.rrd").returncode == 0


def test_close_is_idempotent_and_both_loggers_are_loggers(tmp_path: Path) -> None:
    log: Logger = RerunLogger(tmp_path / "c.rrd", recording_name="c")  # a RerunLogger is a Logger
    assert isinstance(log, NullLogger)
    log.close()
    log.close()
    assert read_rrd(tmp_path / "c.rrd").static["/"] == 1
    null: Logger = NullLogger()
    assert isinstance(null, NullLogger)


def test_null_logger_does_nothing_and_costs_nothing(recording: Path, tmp_path: Path) -> None:
    log = NullLogger()
    with RecordingReader(recording) as rec:
        frame = next(iter(rec.frames()))
    pose, points = np.eye(4), np.zeros((300_000, 3))
    t0 = time.perf_counter()
    for i in range(10_000):
        log.set_frame(i, stamp_ns=i)
        log.log_frame(frame)
        log.log_pose(pose, keyframe=True)
        log.log_map("fused", points)
    per_frame_s = (time.perf_counter() - t0) / 10_000
    log.close()
    assert per_frame_s < 50e-6  # a few hundred ns of Python calls, nothing more
    assert list(tmp_path.iterdir()) == [recording]
