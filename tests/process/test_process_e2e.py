"""`semreplay-process run` end to end on a simulated recording: every output, checked."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import open3d as o3d
import pytest
from helpers_viz import RrdContents, assert_rrd_verifies, read_rrd, rerun_verify
from typer.testing import CliRunner

from capture.recording import RecordingReader, RecordingWriter
from process import outputs
from process.cli import app
from process.cloud import read_cloud
from process.errors import StageError
from process.odometry.odometry import Odometry
from process.pipeline import ReplayPipeline
from process.segmentation.config import beside_odometry_threads
from process.trajectory import Trajectory, read_tum

runner = CliRunner()
OUTPUTS = (
    outputs.RRD,
    outputs.MAP_FUSED,
    outputs.MAP_REFINED,
    outputs.TRAJECTORY,
    outputs.METRICS,
    outputs.CONFIG,
    outputs.PREVIEW,
)
PER_FRAME_ENTITIES = (
    "/world/camera",
    "/world/camera/image/rgb",
    "/world/camera/image/depth",
    "/world/camera/image/keypoints",
)
PER_STAGE_ENTITIES = (
    "/world/map/fused",
    "/world/map/refined",
    "/world/refine/planes",
    "/world/refine/outliers",
    "/world/refine/clusters",
)


@pytest.fixture(scope="module")
def run_twice(sim_recording: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """Run the whole job twice into one folder; return the folder and the first run's mtimes."""
    out = tmp_path_factory.mktemp("run")
    first = runner.invoke(app, ["run", str(sim_recording), "--out", str(out)])
    assert first.exit_code == 0, first.output
    mtimes = {name: (out / name).stat().st_mtime_ns for name in OUTPUTS}
    second = runner.invoke(app, ["run", str(sim_recording), "--out", str(out), "--force"])
    assert second.exit_code == 0, second.output
    return {"out": out, "mtimes": mtimes, "output": second.output}


def test_every_output_is_written_and_replaced_whole(run_twice: dict[str, Any]) -> None:
    out: Path = run_twice["out"]
    assert sorted(p.name for p in out.iterdir()) == sorted(OUTPUTS)  # no temporary files left
    for name in OUTPUTS:
        assert (out / name).stat().st_mtime_ns > run_twice["mtimes"][name], name
    assert f"semreplay-view {out / outputs.RRD}" in run_twice["output"]


def test_the_rrd_verifies_and_holds_the_layout(run_twice: dict[str, Any]) -> None:
    rrd = run_twice["out"] / outputs.RRD
    assert rerun_verify(rrd).returncode == 0
    contents = read_rrd(rrd)
    for entity in PER_FRAME_ENTITIES:
        assert {"frame", "capture_time"} <= contents.timelines(entity), entity
    for entity in ("/world/camera/image/segmentation", "/world/camera/image/depth_registered"):
        assert "frame" in contents.timelines(entity), entity
    for entity in PER_STAGE_ENTITIES:
        assert "stage" in contents.timelines(entity), entity
    entities = contents.entities()
    for entity in ("/world/trajectory/estimated", "/world/trajectory/ground_truth", "/logs"):
        assert entity in entities, entity
    assert any(e.startswith("/plots/dbscan") for e in entities)
    assert any(e.startswith("/plots/timing") for e in entities)
    assert contents.rows[("/world/camera/image/rgb", "frame")] == 30
    # The log says which segmentation model ran and why (issue 11), as metrics.json does.
    logs = [" ".join(map(str, t)) for t in contents.column("/logs", "TextLog:text")]
    note = "segmentation model: simulator (torch), because simulated recording"
    assert any(note in t for t in logs), logs[:3]


def test_the_clouds_load_with_their_label_fields(run_twice: dict[str, Any]) -> None:
    out: Path = run_twice["out"]
    for name in (outputs.MAP_FUSED, outputs.MAP_REFINED):
        pcd = o3d.io.read_point_cloud(out / name)
        cloud = read_cloud(out / name)
        assert len(pcd.points) == len(cloud) > 1000
        assert np.allclose(np.asarray(pcd.points), cloud.points, atol=1e-5)
        assert set(np.unique(cloud.labels)) - {0}, name
    header = (out / outputs.MAP_REFINED).read_bytes()[:400].decode("latin-1")
    assert "property uchar label" in header
    assert "property int cluster" in header


def test_the_trajectory_is_tum_and_near_the_ground_truth(
    run_twice: dict[str, Any], sim_recording: Path
) -> None:
    trajectory = read_tum(run_twice["out"] / outputs.TRAJECTORY)
    stamps, poses = trajectory.stamps_ns, trajectory.poses
    with RecordingReader(sim_recording) as rec:
        truth = {
            f.stamp_ns: f.ground_truth.world_from_camera for f in rec.frames() if f.ground_truth
        }
    assert len(stamps) == 30
    gt = np.array([truth[int(s)] for s in stamps])
    assert np.allclose(poses[0], gt[0], atol=1e-6)  # the map lives in the recording's world
    assert np.max(np.linalg.norm(poses[:, :3, 3] - gt[:, :3, 3], axis=1)) < 0.10


def test_metrics_follow_the_schema(run_twice: dict[str, Any]) -> None:
    metrics = json.loads((run_twice["out"] / outputs.METRICS).read_text())
    expected = {"odometry", "segmentation", "refinement", "seconds", "stages", "job", "preview"}
    assert set(metrics) == expected
    assert metrics["preview"] == outputs.PREVIEW
    odo = metrics["odometry"]
    assert {"frames", "keyframes", "fps", "ate_rmse_m", "rpe_trans_m", "rpe_rot_deg"} <= set(odo)
    assert odo["frames"] == 30 and 0 < odo["keyframes"] <= 30
    seg = metrics["segmentation"]
    assert {"keyframes", "ms_per_keyframe", "miou_2d", "iou_2d", "load_s", "threads"} <= set(seg)
    assert seg["threads"] == beside_odometry_threads()  # the count make bench's row uses
    assert 1 <= seg["keyframes"] <= odo["keyframes"]
    assert seg["keyframes"] + seg["keyframes_geometry_only"] == odo["keyframes"]
    assert 0.0 <= seg["miou_2d"] <= 1.0
    assert seg["model"] == "simulator" and "simulated recording" in seg["model_reason"]
    phases = metrics["refinement"]["phases"]
    assert set(phases) == {"I", "II", "III"}
    for per_class in phases.values():
        assert set(per_class["all"]) == {"iou", "precision", "recall", "f1"}
    for params in metrics["refinement"]["dbscan"].values():
        assert {"k", "eps_m", "min_pts"} <= set(params)
    assert set(metrics["seconds"]) >= {"depth", "odometry", "segmentation", "fusion", "refinement"}
    for stage, figures in metrics["stages"].items():
        assert figures["wall_s"] == metrics["seconds"][stage] and figures["cpu_s"] >= 0
    job = metrics["job"]
    assert job["frames"] == 30 and job["fps"] == pytest.approx(30 / job["wall_s"], rel=0.01)
    assert sum(job["bottleneck_share"].values()) == pytest.approx(1.0, abs=0.002)


def test_the_preview_is_a_small_top_view_of_the_refined_map(run_twice: dict[str, Any]) -> None:
    import cv2

    from capture.recording import LABEL_COLORS

    path = run_twice["out"] / outputs.PREVIEW
    assert path.stat().st_size < 200_000
    rgb = np.asarray(cv2.imread(str(path)), np.uint8)[..., ::-1]
    refined = read_cloud(run_twice["out"] / outputs.MAP_REFINED)
    main_label = int(np.bincount(refined.labels[refined.labels != 1]).argmax())  # not ceiling
    assert np.all(rgb == LABEL_COLORS[main_label], axis=-1).sum() > 500


def test_a_recording_without_ground_truth_runs_and_says_so(
    recording: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    bare = tmp_path / "bare.mcap"
    with RecordingReader(recording) as rec, RecordingWriter(bare) as writer:
        writer.write_calibration(next(rec.frames()).depth_to_color, stamp_ns=1)  # type: ignore[arg-type]
        for frame in rec.frames():
            writer.write_color(
                frame.color, stamp_ns=frame.stamp_ns, intrinsics=frame.color_intrinsics
            )
            depth_mm = np.round(frame.depth_m * 1000).astype(np.uint16)
            writer.write_depth(depth_mm, stamp_ns=frame.stamp_ns, intrinsics=frame.depth_intrinsics)
    out = tmp_path / "out"
    with caplog.at_level("INFO"):
        result = runner.invoke(app, ["run", str(bare), "--out", str(out), "--stages", "odometry"])
    assert result.exit_code == 0, result.output
    metrics = json.loads((out / outputs.METRICS).read_text())
    assert metrics["odometry"]["frames"] == 5
    assert "ate_rmse_m" not in metrics["odometry"]
    assert "no ground truth" in caplog.text
    assert_rrd_verifies(out / outputs.RRD)


def test_an_unfinished_recording_replays_its_recovered_frames(
    sim_recording: Path, tmp_path: Path
) -> None:
    # A capture killed after 20 frames: chunks of 0.2 s were closed, the rest never written.
    cut = tmp_path / "cut.mcap"
    writer = RecordingWriter(cut, chunk_interval_s=0.2)
    with RecordingReader(sim_recording) as rec:
        for frame in rec.frames(end_ns=rec.start_ns + 20 * 33_333_333):
            if frame.index == 0:
                writer.write_calibration(frame.depth_to_color, stamp_ns=frame.stamp_ns)  # type: ignore[arg-type]
            writer.write_frame(frame)
    writer.close_unfinished()
    out = tmp_path / "out"
    result = runner.invoke(
        app, ["run", str(cut), "--out", str(out), "--stages", "odometry", "--no-viz"]
    )
    assert result.exit_code == 0, result.output
    frames = json.loads((out / outputs.METRICS).read_text())["odometry"]["frames"]
    assert 10 <= frames <= 20  # all but the chunk still open when it was killed


def test_ctrl_c_leaves_no_file_and_says_so(
    sim_recording: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def interrupt(*_: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(ReplayPipeline, "_on_keyframe", interrupt)
    out = tmp_path / "out"
    result = runner.invoke(app, ["run", str(sim_recording), "--out", str(out)])
    assert result.exit_code == 1
    assert f"interrupted; no output was written and {out} is as it was" in result.output
    assert list(out.iterdir()) == []  # not even the staging folder


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["run", "absent.mcap", "--out", "o"], "error: expected a recording file, found none"),
        (["run", "{nav2}", "--out", "o"], "error: no colour topic"),
        (["run", "{rec}", "--out", "o", "--stages", "slam"], "error: unknown stage(s) ['slam']"),
        (["run", "{rec}", "--out", "o", "--weights", "absent.pt"], "error: segmentation weights"),
        (["refine", "absent.ply", "--out", "o"], "error: "),
    ],
)
def test_bad_input_is_one_line(
    args: list[str], message: str, recording: Path, shared_data: Path, tmp_path: Path
) -> None:
    nav2 = shared_data / "ros2_other" / "nav2_turtlebot.mcap"
    args = [a.format(rec=recording, nav2=nav2) for a in args]
    args = [str(tmp_path / a) if a == "o" else a for a in args]
    result = runner.invoke(app, args)
    assert result.exit_code == 1, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(message), result.output


def test_refine_command_on_a_labelled_cloud(run_twice: dict[str, Any], tmp_path: Path) -> None:
    fused = run_twice["out"] / outputs.MAP_FUSED
    out = tmp_path / "refined"
    result = runner.invoke(app, ["refine", str(fused), "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in out.iterdir()) == [
        outputs.CONFIG,
        outputs.MAP_REFINED,
        outputs.METRICS,
    ]
    assert len(read_cloud(out / outputs.MAP_REFINED)) <= len(read_cloud(fused))


def test_the_pipeline_keeps_blas_to_one_thread() -> None:
    from threadpoolctl import threadpool_info

    from process.pipeline import _limit_threads

    _limit_threads()
    blas = [pool for pool in threadpool_info() if pool["user_api"] == "blas"]
    assert blas and all(pool["num_threads"] == 1 for pool in blas)


def test_python_dash_m_is_the_same_program() -> None:
    import subprocess
    import sys

    result = subprocess.run(
        [sys.executable, "-m", "process", "--help"], capture_output=True, text=True, check=False
    )
    assert result.returncode == 0
    assert "run" in result.stdout and "refine" in result.stdout and "train" in result.stdout


def test_images_every_n_thins_the_rrd_but_keeps_every_pose_and_keyframe(
    sim_recording: Path, tmp_path: Path
) -> None:
    config = tmp_path / "thin.toml"
    config.write_text("[viz]\nimages_every_n = 10\n")
    out = tmp_path / "out"
    args = ["run", str(sim_recording), "--out", str(out), "--stages", "odometry"]
    result = runner.invoke(app, [*args, "--config", str(config)])
    assert result.exit_code == 0, result.output
    contents = read_rrd(out / outputs.RRD)
    keyframes = json.loads((out / outputs.METRICS).read_text())["odometry"]["keyframes"]
    rgb_rows = contents.rows[("/world/camera/image/rgb", "frame")]
    assert 3 <= rgb_rows <= 3 + keyframes < 30  # frames 0, 10, 20 and the keyframes
    assert contents.rows[("/world/camera/image/keypoints", "frame")] == rgb_rows
    assert contents.rows[("/world/camera", "frame")] == 30


def _odometry_rrd(sim_recording: Path, tmp_path: Path, viz: str) -> RrdContents:
    """Run the odometry stage with a [viz] section; return what its .rrd holds."""
    config = tmp_path / "viz.toml"
    config.write_text(f"[viz]\n{viz}\n")
    out = tmp_path / "out"
    args = ["run", str(sim_recording), "--out", str(out), "--stages", "odometry"]
    result = runner.invoke(app, [*args, "--config", str(config)])
    assert result.exit_code == 0, result.output
    return read_rrd(out / outputs.RRD)


def test_by_default_colour_is_every_frame_and_depth_on_keyframes_and_every_nth(
    sim_recording: Path, tmp_path: Path
) -> None:
    contents = _odometry_rrd(sim_recording, tmp_path, "depth_every_n = 20")
    keyframes = set(contents.values("/world/trajectory/keyframes", "frame"))
    assert 0 < len(keyframes) < 30
    assert contents.rows[("/world/camera/image/rgb", "frame")] == 30
    assert set(contents.values("/world/camera/image/rgb", "EncodedImage:media_type")) == {
        "image/jpeg"
    }
    for entity in ("/world/camera/image/depth", "/world/camera/image/depth_registered"):
        assert set(contents.values(entity, "frame")) == keyframes | {0, 20}, entity


def test_full_fidelity_logs_raw_colour_and_depth_of_every_frame(
    sim_recording: Path, tmp_path: Path
) -> None:
    contents = _odometry_rrd(sim_recording, tmp_path, "compress = false\ndepth_every_n = 1")
    for entity in ("rgb", "depth", "depth_registered"):
        assert contents.rows[(f"/world/camera/image/{entity}", "frame")] == 30, entity
    assert contents.values("/world/camera/image/rgb", "Image:buffer").size == 30 * 480 * 640 * 3
    assert "DepthImage:buffer" in contents.columns["/world/camera/image/depth"]


def test_a_failing_stage_is_one_line_and_leaves_no_partial_rrd(
    sim_recording: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def fail(*_: object) -> None:
        raise StageError("segmentation failed on purpose")

    monkeypatch.setattr(ReplayPipeline, "_on_keyframe", fail)
    out = tmp_path / "out"
    result = runner.invoke(app, ["run", str(sim_recording), "--out", str(out)])
    assert result.exit_code == 1
    assert result.output.strip().splitlines()[-1] == "error: segmentation failed on purpose"
    assert list(out.iterdir()) == []


def test_fusion_places_keyframes_at_their_final_poses(
    run_twice: dict[str, Any], sim_recording: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Loop closure moves poses after their keyframes were tracked: the map must use the final
    # trajectory. Shift it by 10 m and the whole fused map moves by 10 m.
    finish = Odometry.finish

    def shifted(self: Odometry) -> Trajectory:
        out = finish(self)
        moved = out.poses.copy()
        moved[:, 0, 3] += 10.0
        return Trajectory(out.stamps_ns, moved)

    monkeypatch.setattr(Odometry, "finish", shifted)
    out = tmp_path / "out"
    args = ["run", str(sim_recording), "--out", str(out), "--stages", "fusion", "--no-viz"]
    assert runner.invoke(app, args).exit_code == 0
    expected = np.array([10.0, 0.0, 0.0])  # the trajectory is in the map's world
    normal = read_cloud(run_twice["out"] / outputs.MAP_FUSED).points.mean(axis=0)
    moved = read_cloud(out / outputs.MAP_FUSED).points.mean(axis=0)
    assert np.allclose(moved - normal, expected, atol=0.05)


def test_sigterm_is_handled_like_ctrl_c(sim_recording: Path, tmp_path: Path) -> None:
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "out"
    child = subprocess.Popen(
        [sys.executable, "-m", "process", "run", str(sim_recording), "--out", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 60
    staged_config = out / f"{outputs.STAGING_PREFIX}{child.pid}" / outputs.CONFIG
    while not staged_config.exists() and time.monotonic() < deadline:
        time.sleep(0.02)  # config.toml is written first: the run has started
    child.send_signal(signal.SIGTERM)
    _, err = child.communicate(timeout=60)
    assert child.returncode == 1, err
    assert "error: interrupted; no output was written" in err
    assert list(out.iterdir()) == []


def test_an_empty_map_is_said_and_refinement_skipped(
    sim_recording: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    config = tmp_path / "near.toml"
    config.write_text("[fusion]\nmin_depth_m = 0.2\nmax_depth_m = 0.21\n")  # nothing is that near
    out = tmp_path / "out"
    args = ["run", str(sim_recording), "--out", str(out), "--config", str(config), "--no-viz"]
    with caplog.at_level("WARNING"):
        result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert "the fused map is empty" in caplog.text and "0.2..0.21 m" in caplog.text
    assert len(read_cloud(out / outputs.MAP_FUSED)) == 0
    assert not (out / outputs.MAP_REFINED).exists()
    assert "refinement" not in json.loads((out / outputs.METRICS).read_text())
