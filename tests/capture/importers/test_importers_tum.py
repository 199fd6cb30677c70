"""TUM RGB-D folders: association, depth units, ground-truth interpolation, intrinsics."""

from __future__ import annotations

import json
from decimal import Decimal
from pathlib import Path

import numpy as np
import pytest
from helpers_importers import (
    TUM_CORNER_MM,
    TUM_DEPTH_S,
    TUM_PAIRS,
    TUM_RGB_S,
    has_pose,
    pose_of,
    read_frames,
    tum_pose,
    write_tum_folder,
)

from capture.importers import TUM_INTRINSICS, associate, import_dataset
from capture.recording import RecordingReader


def ns(seconds: str) -> int:
    return int(Decimal(seconds) * 1_000_000_000)


@pytest.fixture
def tum_mcap(tmp_path: Path) -> Path:
    src = write_tum_folder(tmp_path, "rgbd_dataset_freiburg2_test")
    out = tmp_path / "tum.mcap"
    assert import_dataset("tum", src, out) == len(TUM_PAIRS)
    return out


def test_associate_takes_closest_pairs_first_and_excludes_the_max_difference() -> None:
    pairs = associate([ns(s) for s in TUM_RGB_S], [ns(s) for s in TUM_DEPTH_S])
    assert pairs == [(ns(TUM_RGB_S[a]), ns(TUM_DEPTH_S[b])) for a, b in TUM_PAIRS]


def test_tum_frames_carry_rgb_stamps_and_their_associated_depth(tum_mcap: Path) -> None:
    frames = read_frames(tum_mcap)
    assert [f.stamp_ns for f in frames] == [ns(TUM_RGB_S[a]) for a, _ in TUM_PAIRS]
    for frame, (a, b) in zip(frames, TUM_PAIRS, strict=True):
        assert frame.aligned
        assert frame.color[100, 100, 0] == 10 * a + 5  # the rgb image of index a
        assert frame.depth_m[100, 100] == np.float32(1000 + 100 * b) * np.float32(0.001)


def test_tum_depth_5000_units_per_metre_become_millimetres(tum_mcap: Path) -> None:
    frame = read_frames(tum_mcap)[0]
    corner_mm = np.rint(frame.depth_m[0, : len(TUM_CORNER_MM)] * 1000).astype(int)
    assert corner_mm.tolist() == list(TUM_CORNER_MM)


def test_tum_ground_truth_is_exact_interpolated_nearest_or_absent(tum_mcap: Path) -> None:
    frames = read_frames(tum_mcap)
    np.testing.assert_allclose(pose_of(frames[0]), tum_pose(1.000), atol=1e-8)  # sample at stamp
    np.testing.assert_allclose(pose_of(frames[1]), tum_pose(1.033), atol=1e-8)  # 1.03-1.04 slerp
    np.testing.assert_allclose(pose_of(frames[2]), tum_pose(1.060), atol=1e-8)  # past end: nearest
    assert not has_pose(frames[3])  # 1.133 s: no sample within 0.02 s


def test_tum_intrinsics_and_metadata_come_from_the_folder(tum_mcap: Path) -> None:
    with RecordingReader(tum_mcap) as rec:
        frame = next(rec.frames())
        meta = rec.metadata
    assert frame.color_intrinsics == TUM_INTRINSICS["2"]
    assert frame.color_intrinsics.coeffs == (0.2312, -0.7849, -0.0033, -0.0001, 0.9172)
    assert meta["device"] == {
        "name": "TUM RGB-D freiburg2",
        "depth_scale_m": "0.001",
        "rolling_shutter_readout_s": "0.02",  # the Kinect's colour camera: read by the odometry
    }
    assert meta["capture"]["kind"] == "tum"
    assert json.loads(meta["capture"]["frames_dropped"]) == {"color": 3}
    assert json.loads(meta["capture"]["frames_written"])["ground_truth_pose"] == 3


@pytest.mark.parametrize(
    ("folder", "camera"),
    [("rgbd_dataset_freiburg3_long_office", "3"), ("my_own_sequence", "1")],
)
def test_tum_camera_is_chosen_by_folder_name_default_freiburg1(
    tmp_path: Path, folder: str, camera: str
) -> None:
    src = write_tum_folder(tmp_path, folder, groundtruth=False)
    import_dataset("tum", src, tmp_path / "out.mcap")
    frames = read_frames(tmp_path / "out.mcap")
    assert frames[0].color_intrinsics == TUM_INTRINSICS[camera]
    assert not any(has_pose(f) for f in frames)
