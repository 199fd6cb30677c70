"""Wrong kinds, wrong folders and failed imports: one-line errors and no half-written file."""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers_importers import write_redwood, write_seven_scenes, write_tum_folder

from capture.errors import ImportFormatError
from capture.importers import KINDS, detect_kind, import_dataset


@pytest.fixture
def folders(tmp_path: Path) -> dict[str, Path]:
    return {
        "tum": write_tum_folder(tmp_path, "rgbd_dataset_freiburg1_xyz", groundtruth=False),
        "7scenes": (write_seven_scenes(tmp_path / "seq-01"), tmp_path / "seq-01")[1],
        "redwood": write_redwood(tmp_path / "redwood"),
    }


def test_unknown_kind_lists_the_valid_kinds(tmp_path: Path) -> None:
    with pytest.raises(ImportFormatError, match="expected one of tum, 7scenes, redwood"):
        import_dataset("scannet", tmp_path, tmp_path / "o.mcap")
    assert KINDS == ("tum", "7scenes", "redwood")


@pytest.mark.parametrize(
    ("kind", "folder", "missing"),
    [
        ("tum", "redwood", "missing rgb.txt and depth.txt"),
        ("7scenes", "tum", "missing frame-XXXXXX.color.png|jpg"),
        ("redwood", "7scenes", "missing color/ and depth/ and trajectory.log"),
    ],
)
def test_wrong_kind_names_what_is_missing_what_was_found_and_the_likely_kind(
    folders: dict[str, Path], tmp_path: Path, kind: str, folder: str, missing: str
) -> None:
    out = tmp_path / "o.mcap"
    with pytest.raises(ImportFormatError, match=missing) as err:
        import_dataset(kind, folders[folder], out)
    message = str(err.value)
    assert "\n" not in message
    assert f"looks like a {folder!r} dataset" in message
    assert message.endswith(str(folders[folder]))
    assert not out.exists() and not out.with_suffix(".mcap.part").exists()


def test_detect_kind_recognises_each_layout(folders: dict[str, Path], tmp_path: Path) -> None:
    assert {kind: detect_kind(path) for kind, path in folders.items()} == {k: k for k in folders}
    assert detect_kind(tmp_path / "nowhere") is None


def test_missing_folder_is_an_import_error(tmp_path: Path) -> None:
    with pytest.raises(ImportFormatError, match="found no directory"):
        import_dataset("tum", tmp_path / "nowhere", tmp_path / "o.mcap")


def test_a_failed_import_leaves_no_part_file_and_the_old_output_intact(
    folders: dict[str, Path], tmp_path: Path
) -> None:
    (folders["tum"] / "depth" / "1.052000.png").write_bytes(b"not a png")
    out = tmp_path / "o.mcap"
    out.write_bytes(b"previous recording")
    with pytest.raises(
        ImportFormatError, match=r"depth image, found an unreadable file: .*1\.052000"
    ):
        import_dataset("tum", folders["tum"], out)
    assert out.read_bytes() == b"previous recording"
    assert not out.with_suffix(".mcap.part").exists()


def test_redwood_with_unequal_colour_and_depth_counts_is_refused(
    folders: dict[str, Path], tmp_path: Path
) -> None:
    (folders["redwood"] / "depth" / "00002.png").unlink()
    with pytest.raises(ImportFormatError, match="found 3 in color/ and 2 in depth/"):
        import_dataset("redwood", folders["redwood"], tmp_path / "o.mcap")


def test_seven_scenes_colour_without_depth_is_refused(
    folders: dict[str, Path], tmp_path: Path
) -> None:
    (folders["7scenes"] / "frame-000001.depth.png").unlink()
    with pytest.raises(ImportFormatError, match=r"missing frame-000001\.depth\.png beside"):
        import_dataset("7scenes", folders["7scenes"], tmp_path / "o.mcap")


def test_redwood_pose_for_a_frame_that_does_not_exist_is_refused(tmp_path: Path) -> None:
    src = write_redwood(tmp_path / "rw", frames=2, posed=(0, 5))
    with pytest.raises(ImportFormatError, match=r"frames 0\.\.1, found one for frame 5"):
        import_dataset("redwood", src, tmp_path / "o.mcap")


def test_a_listed_image_that_does_not_exist_is_refused_before_writing(
    folders: dict[str, Path], tmp_path: Path
) -> None:
    (folders["tum"] / "rgb" / "1.066000.png").unlink()
    with pytest.raises(ImportFormatError, match=r"found none: .*rgb/1\.066000\.png$"):
        import_dataset("tum", folders["tum"], tmp_path / "o.mcap")
    assert not (tmp_path / "o.mcap").exists()
