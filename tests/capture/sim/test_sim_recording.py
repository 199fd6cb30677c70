"""Simulated recordings: written like a real capture, replayable, with ground truth, repeatable."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from capture.recording import GT_CLOUD_ATTACHMENT, RecordingReader
from capture.recording.frames import RgbdFrame
from capture.sim import FrameSimulator, handheld_loop, read_ply, simulate_recording
from capture.sim.trajectory import SIM_EPOCH_NS

W, H = 160, 120


@pytest.fixture(scope="module")
def small_recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("sim") / "small.mcap"
    simulate_recording(path, seed=5, frames=4, width=W, height=H)
    return path


def read_all(path: Path) -> list[RgbdFrame]:
    with RecordingReader(path) as rec:
        return list(rec.frames())


def test_recording_replays_with_ground_truth_and_unaligned_depth(small_recording: Path) -> None:
    with RecordingReader(small_recording) as rec:
        assert len(rec) == 4 and rec.has_ground_truth and rec.has_ground_truth_labels
        assert not rec.aligned
        device = rec.metadata["device"]
        assert (
            device["name"] == "Simulated Intel RealSense D435"
            and device["serial_number"] == "SIM-5"
        )
        assert device["product_line"] == "D400" and device["simulated"] == "true"
        assert device["depth_scale_m"] == "0.001"
        assert (
            rec.metadata["capture"]["frames_written"]
            == '{"color": 4, "depth": 4, "ground_truth": 4}'
        )
        frames = list(rec.frames())
    first = frames[0]
    assert first.stamp_ns == SIM_EPOCH_NS and frames[1].stamp_ns - first.stamp_ns == 33_333_333
    assert first.color.shape == (H, W, 3) and first.depth_m.shape == (H, W)
    assert first.depth_to_color is not None
    np.testing.assert_allclose(
        first.depth_to_color.color_from_depth[:3, 3], [0.0147, 0.0001, 0.0003]
    )
    assert first.color_intrinsics.fx == pytest.approx(615.0 * W / 640)
    assert first.depth_intrinsics.fx == pytest.approx(385.0 * W / 640)
    gt = first.ground_truth
    assert gt is not None and gt.world_from_camera is not None
    assert gt.labels is not None and gt.labels.shape == (H, W) and gt.labels.max() <= 10
    assert gt.instances is not None and gt.instances.min() > 0
    valid = first.depth_m > 0
    assert 0.5 < valid.mean() < 1.0  # holes where a D435 has them, depth elsewhere


def test_ground_truth_cloud_has_every_class(small_recording: Path) -> None:
    with RecordingReader(small_recording) as rec:
        data = rec.attachment(GT_CLOUD_ATTACHMENT)
    assert data is not None and data.startswith(b"ply\nformat binary_little_endian 1.0\n")
    cloud = read_ply(data)
    assert set(np.unique(cloud["label"])) == set(range(1, 11))
    assert len(cloud) > 100_000
    labels_of_instance: dict[int, int] = {}
    for instance, label in zip(cloud["instance"], cloud["label"], strict=True):
        assert labels_of_instance.setdefault(int(instance), int(label)) == label


def test_the_same_seed_gives_identical_frames(small_recording: Path, tmp_path: Path) -> None:
    again = tmp_path / "again.mcap"
    simulate_recording(again, seed=5, frames=4, width=W, height=H)
    for a, b in zip(read_all(small_recording), read_all(again), strict=True):
        assert a.stamp_ns == b.stamp_ns
        assert a.color.tobytes() == b.color.tobytes() and a.depth_m.tobytes() == b.depth_m.tobytes()
        assert a.ground_truth is not None and b.ground_truth is not None
        for x, y in zip(
            (a.ground_truth.labels, a.ground_truth.instances, a.ground_truth.world_from_camera),
            (b.ground_truth.labels, b.ground_truth.instances, b.ground_truth.world_from_camera),
            strict=True,
        ):
            assert x is not None and y is not None and x.tobytes() == y.tobytes()
    with RecordingReader(small_recording) as ra, RecordingReader(again) as rb:
        assert ra.attachment(GT_CLOUD_ATTACHMENT) == rb.attachment(GT_CLOUD_ATTACHMENT)


def test_another_seed_gives_another_room(small_recording: Path, tmp_path: Path) -> None:
    other = tmp_path / "other.mcap"
    simulate_recording(other, seed=6, frames=1, width=W, height=H)
    assert read_all(other)[0].color.tobytes() != read_all(small_recording)[0].color.tobytes()


def test_pipelined_frames_equal_frames_rendered_one_by_one() -> None:
    def render(pipelined: bool) -> list[bytes]:
        with FrameSimulator(9, width=80, height=60) as sim:
            poses = handheld_loop(sim.scene, frames=5, fps=30.0, seed=9).world_from_camera
            frames = list(sim.frames(poses)) if pipelined else [sim.render(p) for p in poses]
        return [f.color.color.tobytes() + f.depth_mm.tobytes() for f in frames]

    assert render(pipelined=True) == render(pipelined=False)
