"""7-Scenes sequences: invalid depth, 4x4 poses, frame-number stamps, intrinsics file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from helpers_importers import has_pose, pose_of, read_frames, write_seven_scenes

from capture.importers import SEVEN_SCENES_K, import_dataset


def test_seven_scenes_depth_poses_and_stamps(tmp_path: Path) -> None:
    written = write_seven_scenes(tmp_path / "chess" / "seq-01", numbers=(0, 1, 3))
    assert import_dataset("7scenes", tmp_path / "chess" / "seq-01", tmp_path / "o.mcap") == 3
    frames = read_frames(tmp_path / "o.mcap")
    assert [f.stamp_ns for f in frames] == [0, 33_333_333, 100_000_000]  # frame number / 30 fps
    for frame, known in zip(frames, written, strict=True):
        expected_mm = np.where(known.depth_mm == 65535, 0, known.depth_mm)
        assert np.array_equal(np.rint(frame.depth_m * 1000), expected_mm)
        assert frame.depth_m[15, 35] == 0.0  # 65535 = invalid -> no depth
        np.testing.assert_allclose(pose_of(frame), known.world_from_camera, atol=1e-9)
        assert frame.color_intrinsics == SEVEN_SCENES_K
        assert frame.color[0, 0].tolist() == [10 * known.number + 5, 100, 200]


def test_seven_scenes_reads_camera_intrinsics_beside_the_sequence(tmp_path: Path) -> None:
    write_seven_scenes(tmp_path / "scene" / "seq-02", numbers=(0,))
    K = np.array([[532.5, 0.0, 320.5], [0.0, 531.0, 245.0], [0.0, 0.0, 1.0]])
    np.savetxt(tmp_path / "scene" / "camera-intrinsics.txt", K)
    import_dataset("7scenes", tmp_path / "scene" / "seq-02", tmp_path / "o.mcap")
    k = read_frames(tmp_path / "o.mcap")[0].color_intrinsics
    assert (k.fx, k.fy, k.cx, k.cy, k.width, k.height) == (532.5, 531.0, 320.5, 245.0, 640, 480)


def test_seven_scenes_jpg_colour_and_an_invalid_pose(tmp_path: Path) -> None:
    seq = tmp_path / "seq-03"
    write_seven_scenes(seq, numbers=(0, 1), color_suffix=".jpg")
    (seq / "frame-000001.pose.txt").write_text("\n".join(["-inf -inf -inf -inf"] * 4) + "\n")
    assert import_dataset("7scenes", seq, tmp_path / "o.mcap") == 2
    frames = read_frames(tmp_path / "o.mcap")
    assert np.abs(frames[1].color.astype(int) - [15, 100, 200]).max() <= 3  # JPEG of a flat colour
    assert has_pose(frames[0])
    assert not has_pose(frames[1])
