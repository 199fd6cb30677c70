"""Redwood/ICL-NUIM and slambook2 folders, on the real data in ../shared/data and a tiny folder."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from helpers_importers import (
    has_pose,
    imread,
    pose_of,
    read_frames,
    read_pgm16,
    read_redwood_log,
    write_redwood,
)
from scipy.spatial.transform import Rotation

from capture.importers import import_dataset
from capture.recording import RecordingReader

MM = np.float32(0.001)  # what the reader multiplies 16UC1 values by


@pytest.fixture(scope="module")
def icl_mcap(shared_data: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("icl") / "icl.mcap"
    assert import_dataset("redwood", shared_data / "icl_nuim", out) == 5
    return out


@pytest.fixture(scope="module")
def slambook_mcap(shared_data: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("slambook") / "slambook.mcap"
    assert import_dataset("redwood", shared_data / "slambook2_rgbd", out) == 5
    return out


def test_icl_nuim_depth_colour_poses_and_intrinsics_equal_the_files(
    icl_mcap: Path, shared_data: Path
) -> None:
    src = shared_data / "icl_nuim"
    frames = read_frames(icl_mcap)
    poses = read_redwood_log(src / "trajectory.log")
    camera = json.loads((src / "camera_primesense.json").read_text())
    assert len(frames) == 5
    for i, frame in enumerate(frames):
        png = imread(src / "depth" / f"{i:05d}.png")
        assert np.array_equal(frame.depth_m, png.astype(np.float32) * MM)
        jpg = imread(src / "color" / f"{i:05d}.jpg", cv2.IMREAD_COLOR)
        assert np.array_equal(frame.color, jpg[..., ::-1])
        np.testing.assert_allclose(pose_of(frame), poses[i], atol=1e-9)
    k = frames[0].color_intrinsics
    K = np.array(camera["intrinsic_matrix"]).reshape(3, 3).T
    assert (k.width, k.height) == (camera["width"], camera["height"])
    assert np.array_equal(k.matrix, K)


def test_icl_nuim_import_matches_the_independent_recording(
    icl_mcap: Path, shared_data: Path
) -> None:
    ours = read_frames(icl_mcap)
    theirs = read_frames(shared_data / "icl_nuim" / "icl_nuim_5frames.mcap")
    assert len(ours) == len(theirs) == 5
    for a, b in zip(ours, theirs, strict=True):
        assert a.aligned and b.aligned
        assert np.array_equal(a.depth_m, b.depth_m)
        assert a.color_intrinsics == b.color_intrinsics
        np.testing.assert_allclose(pose_of(a), pose_of(b), atol=1e-9)


def test_slambook2_depth_poses_and_intrinsics_equal_the_files(
    slambook_mcap: Path, shared_data: Path
) -> None:
    src = shared_data / "slambook2_rgbd"
    frames = read_frames(slambook_mcap)
    rows = np.loadtxt(src / "pose.txt")
    assert len(frames) == 5
    for i, frame in enumerate(frames):
        pgm = read_pgm16(src / "depth" / f"{i + 1}.pgm")
        assert pgm.max() > 1000  # real 16-bit mm values, so byte order matters
        assert np.array_equal(frame.depth_m, pgm.astype(np.float32) * MM)
        pose = pose_of(frame)
        np.testing.assert_allclose(pose[:3, 3], rows[i, :3], atol=1e-12)
        q = Rotation.from_matrix(pose[:3, :3]).as_quat()
        q_file = rows[i, 3:] / np.linalg.norm(rows[i, 3:])
        np.testing.assert_allclose(q * np.sign(q @ q_file), q_file, atol=1e-9)
    k = frames[0].color_intrinsics
    assert (k.fx, k.fy, k.cx, k.cy, k.width, k.height) == (518.0, 519.0, 325.5, 253.5, 640, 480)
    with RecordingReader(slambook_mcap) as rec:
        assert rec.metadata["capture"]["layout"] == "slambook2"


def test_redwood_camera_json_is_column_major_and_unposed_frames_have_no_pose(
    tmp_path: Path,
) -> None:
    src = write_redwood(tmp_path / "rw", frames=3, posed=(0, 2))
    assert import_dataset("redwood", src, tmp_path / "o.mcap", compression="lz4") == 3
    frames = read_frames(tmp_path / "o.mcap")
    k = frames[0].color_intrinsics
    assert (k.fx, k.fy, k.cx, k.cy, k.width, k.height) == (50.0, 60.0, 31.5, 23.5, 64, 48)
    assert [np.rint(f.depth_m[0, 0] * 1000) for f in frames] == [800, 801, 802]
    assert not has_pose(frames[1])
    np.testing.assert_allclose(pose_of(frames[2])[:3, 3], [0.2, 0.0, 0.0])
