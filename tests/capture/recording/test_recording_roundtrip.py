"""RecordingWriter -> RecordingReader round trips: bit-exact images, calibration, ground truth."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from scipy.spatial.transform import Rotation

from capture.recording import (
    Extrinsics,
    GroundTruth,
    Intrinsics,
    RecordingReader,
    RecordingWriter,
    RgbdFrame,
)
from capture.recording import messages as m

COLOR_K = Intrinsics(64, 48, 60.5, 61.0, 31.5, 23.25, "plumb_bob", (0.1, -0.2, 0.001, 0.002, 0.03))
DEPTH_K = Intrinsics(40, 30, 38.0, 38.5, 19.5, 14.5)
# A non-symmetric rotation (30 degrees about x+y) and a 15 mm baseline.
_AXIS = np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0)
_R = cv2.Rodrigues(_AXIS * np.deg2rad(30.0))[0]
COLOR_FROM_DEPTH = np.eye(4)
COLOR_FROM_DEPTH[:3, :3] = _R
COLOR_FROM_DEPTH[:3, 3] = [0.015, -0.001, 0.002]
T0_NS = 1_700_000_000_123_456_789


def _frame_data(i: int) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.uint16]]:
    rng = np.random.default_rng(i)
    color = rng.integers(0, 256, (48, 64, 3), dtype=np.uint8)
    depth = rng.integers(0, 65536, (30, 40), dtype=np.uint16)
    depth[0, :5] = 0  # no depth
    return color, depth


def _write(path: Path, *, frames: int, compression: str = "zstd", fps: float = 30.0) -> None:
    with RecordingWriter(path, compression=compression) as w:
        w.write_metadata("device", {"name": "test", "depth_scale_m": "0.001"})
        w.write_calibration(Extrinsics(COLOR_FROM_DEPTH), stamp_ns=T0_NS - 1)
        for i in range(frames):
            stamp = T0_NS + round(i * 1e9 / fps)
            color, depth = _frame_data(i)
            w.write_color(color, stamp_ns=stamp, intrinsics=COLOR_K, metadata={"frame_number": i})
            w.write_depth(depth, stamp_ns=stamp + 1000, intrinsics=DEPTH_K)
            pose = np.eye(4)
            pose[:3, 3] = [0.1 * i, -0.05 * i, 1.0]
            labels = np.full((48, 64), i % 11, np.uint8)
            instances = np.arange(48 * 64, dtype=np.uint16).reshape(48, 64) + i
            w.write_ground_truth(
                stamp_ns=stamp, world_from_camera=pose, labels=labels, instances=instances
            )


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_images_calibration_and_ground_truth_come_back_exactly(
    tmp_path: Path, compression: str
) -> None:
    path = tmp_path / f"{compression}.mcap"
    _write(path, frames=4, compression=compression)
    with RecordingReader(path) as rec:
        assert rec.finished and len(rec) == 4 and not rec.aligned
        frames = list(rec.frames())
    assert [f.index for f in frames] == [0, 1, 2, 3]
    for i, frame in enumerate(frames):
        color, depth = _frame_data(i)
        assert frame.stamp_ns == T0_NS + round(i * 1e9 / 30.0)
        np.testing.assert_array_equal(frame.color, color)
        np.testing.assert_array_equal(np.rint(frame.depth_m * 1000.0).astype(np.uint16), depth)
        assert frame.color_intrinsics == COLOR_K and frame.depth_intrinsics == DEPTH_K
        assert frame.depth_to_color is not None
        np.testing.assert_allclose(frame.depth_to_color.color_from_depth, COLOR_FROM_DEPTH, atol=0)
        assert frame.metadata == {"frame_number": str(i)}
        gt = frame.ground_truth
        assert gt is not None and gt.world_from_camera is not None and gt.labels is not None
        np.testing.assert_allclose(gt.world_from_camera[:3, 3], [0.1 * i, -0.05 * i, 1.0])
        np.testing.assert_allclose(gt.world_from_camera[:3, :3], np.eye(3), atol=1e-15)
        assert (gt.labels == i % 11).all()
        assert gt.instances is not None and gt.instances[47, 63] == 48 * 64 - 1 + i


def test_an_independent_mcap_reader_decodes_every_message(tmp_path: Path) -> None:
    path = tmp_path / "r.mcap"
    _write(path, frames=3)
    counts: dict[str, int] = {}
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        for _, channel, _, msg in reader.iter_decoded_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if channel.topic.endswith(m.DEPTH_IMAGE):
                assert (msg.encoding, msg.step, msg.header.frame_id) == (
                    "16UC1",
                    80,
                    m.DEPTH_FRAME_ID,
                )
        assert sum(counts.values()) == summary.statistics.message_count
    ns = m.DEFAULT_NAMESPACE
    assert counts[ns + m.COLOR_IMAGE] == counts[ns + m.COLOR_INFO] == 3
    assert counts[ns + m.EXTRINSICS] == counts[m.TF_STATIC] == 1


def test_chunks_close_every_second_of_log_time(tmp_path: Path) -> None:
    path = tmp_path / "chunks.mcap"
    _write(path, frames=35, fps=10.0)  # 3.4 s of recording
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    spans = [c.message_end_time - c.message_start_time for c in summary.chunk_indexes]
    assert len(spans) >= 4
    assert max(spans) <= 1_000_000_000


def test_aligned_depth_is_read_in_the_colour_camera(tmp_path: Path) -> None:
    path = tmp_path / "aligned.mcap"
    depth = np.full((48, 64), 1234, np.uint16)
    with RecordingWriter(path) as w:
        w.write_color(_frame_data(0)[0], stamp_ns=T0_NS, intrinsics=COLOR_K)
        w.write_depth(depth, stamp_ns=T0_NS, intrinsics=COLOR_K, aligned=True)
    with RecordingReader(path) as rec:
        (frame,) = list(rec.frames())
    assert frame.aligned and frame.depth_to_color is None
    assert frame.depth_intrinsics == frame.color_intrinsics == COLOR_K
    assert np.all(frame.depth_m == np.float32(1234) * np.float32(0.001))


def test_frames_of_a_time_range_and_whole_frame_values(tmp_path: Path) -> None:
    path = tmp_path / "range.mcap"
    rng = np.random.default_rng(5)
    with RecordingWriter(path, compression="lz4") as w:
        for i in range(6):
            frame = RgbdFrame(
                index=i,
                stamp_ns=T0_NS + i * 100_000_000,
                color=rng.integers(0, 256, (48, 64, 3), dtype=np.uint8),
                depth_m=np.full((48, 64), 0.5 + 0.25 * i, np.float32),
                color_intrinsics=COLOR_K,
                depth_intrinsics=COLOR_K,
                aligned=True,
                ground_truth=GroundTruth(world_from_camera=np.eye(4)),
            )
            w.write_frame(frame)
    with RecordingReader(path) as rec:
        picked = list(rec.frames(start_ns=T0_NS + 200_000_000, end_ns=T0_NS + 400_000_000))
    assert [f.stamp_ns - T0_NS for f in picked] == [200_000_000, 300_000_000, 400_000_000]
    assert [f.index for f in picked] == [0, 1, 2]
    assert [float(f.depth_m[0, 0]) for f in picked] == pytest.approx([1.0, 1.25, 1.5], abs=1e-6)


def test_jpeg_colour_decodes_close_to_the_original(tmp_path: Path, shared_data: Path) -> None:
    bgr = np.asarray(cv2.imread(str(shared_data / "icl_nuim" / "color" / "00000.jpg")))
    color = np.asarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), dtype=np.uint8)
    k = Intrinsics(640, 480, 525.0, 525.0, 319.5, 239.5)
    path = tmp_path / "jpeg.mcap"
    with RecordingWriter(path, color_jpeg=True, jpeg_quality=95) as w:
        w.write_color(color, stamp_ns=T0_NS, intrinsics=k)
        w.write_depth(np.ones((480, 640), np.uint16), stamp_ns=T0_NS, intrinsics=k, aligned=True)
    with RecordingReader(path) as rec:
        assert m.DEFAULT_NAMESPACE + m.COLOR_COMPRESSED in rec.topics
        (frame,) = list(rec.frames())
    assert frame.color.shape == color.shape
    assert np.abs(frame.color.astype(int) - color.astype(int)).mean() < 2.0


def test_bgr8_colour_is_returned_as_rgb(tmp_path: Path) -> None:
    rgb = _frame_data(3)[0]
    path = tmp_path / "bgr.mcap"
    with RecordingWriter(path) as w:
        msg = m.image(T0_NS, m.COLOR_FRAME_ID, width=64, height=48, encoding="bgr8", step=192,
                      data=np.ascontiguousarray(rgb[..., ::-1]).tobytes())  # fmt: skip
        w.write_message(w.namespace + m.COLOR_IMAGE, m.IMAGE, msg, stamp_ns=T0_NS, log_ns=T0_NS)
        w.write_message(w.namespace + m.COLOR_INFO, m.CAMERA_INFO,
                        m.camera_info(T0_NS, m.COLOR_FRAME_ID, width=64, height=48,
                                      k=(60.0, 60.0, 32.0, 24.0), distortion_model="plumb_bob",
                                      coeffs=(0.0,) * 5), stamp_ns=T0_NS, log_ns=T0_NS)  # fmt: skip
        w.write_depth(
            np.ones((48, 64), np.uint16), stamp_ns=T0_NS, intrinsics=COLOR_K, aligned=True
        )
    with RecordingReader(path) as rec:
        (frame,) = list(rec.frames())
    np.testing.assert_array_equal(frame.color, rgb)


def test_device_depth_scale_is_honoured(tmp_path: Path) -> None:
    path = tmp_path / "scale.mcap"
    with RecordingWriter(path) as w:
        w.write_metadata("device", {"name": "x", "depth_scale_m": "0.0001"})
        w.write_color(_frame_data(0)[0], stamp_ns=T0_NS, intrinsics=COLOR_K)
        depth = np.full((48, 64), 12345, np.uint16)
        w.write_depth(depth, stamp_ns=T0_NS, intrinsics=COLOR_K, aligned=True)
    with RecordingReader(path) as rec:
        assert rec.depth_scale_m == pytest.approx(1e-4)
        (frame,) = list(rec.frames())
    assert float(frame.depth_m[0, 0]) == pytest.approx(1.2345, abs=1e-6)


def test_metadata_and_attachments_round_trip(tmp_path: Path) -> None:
    path = tmp_path / "meta.mcap"
    _write(path, frames=1)
    with RecordingWriter(tmp_path / "att.mcap") as w:
        w.write_metadata("capture", {"frames_written": {"color": 3}, "host": "h"})
        w.write_attachment("cloud.ply", b"ply\n123", media_type="text/plain", log_ns=T0_NS)
        w.write_color(_frame_data(0)[0], stamp_ns=T0_NS, intrinsics=COLOR_K)
        w.write_depth(
            np.ones((48, 64), np.uint16), stamp_ns=T0_NS, intrinsics=COLOR_K, aligned=True
        )
    with RecordingReader(tmp_path / "att.mcap") as rec:
        assert rec.metadata["capture"] == {"frames_written": '{"color": 3}', "host": "h"}
        assert rec.attachment_names == ["cloud.ply"]
        assert rec.attachment("cloud.ply") == b"ply\n123"
        assert rec.attachment("missing.ply") is None
    with RecordingReader(path) as rec:
        assert rec.metadata["device"] == {"name": "test", "depth_scale_m": "0.001"}
        assert rec.duration_ns == rec.end_ns - rec.start_ns == 1 + 1000


def test_tf_static_composes_back_to_the_extrinsics(tmp_path: Path) -> None:
    path = tmp_path / "tf.mcap"
    _write(path, frames=1)
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        (msg,) = [d for _, _, _, d in reader.iter_decoded_messages(topics=[m.TF_STATIC])]
    link_from: dict[str, npt.NDArray[np.float64]] = {}
    for tf in msg.transforms:
        assert tf.header.frame_id == m.LINK_FRAME_ID
        t, q = tf.transform.translation, tf.transform.rotation
        mat = np.eye(4)
        mat[:3, :3] = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
        mat[:3, 3] = [t.x, t.y, t.z]
        link_from[tf.child_frame_id] = mat
    # camera_link is x forward, z up: the depth optical z axis (forward) is link x.
    np.testing.assert_allclose(link_from[m.DEPTH_FRAME_ID][:3, 2], [1.0, 0.0, 0.0], atol=1e-12)
    color_from_depth = np.linalg.inv(link_from[m.COLOR_FRAME_ID]) @ link_from[m.DEPTH_FRAME_ID]
    np.testing.assert_allclose(color_from_depth, COLOR_FROM_DEPTH, atol=1e-12)
