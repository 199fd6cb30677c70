"""Labelled cloud files: our PLY round trip, Open3D compatibility, PCD, one-line errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from process.cloud import LabelledCloud, parse_ply, read_cloud, write_ply
from process.errors import CloudError


def _cloud(n: int = 50, *, clusters: bool = True) -> LabelledCloud:
    rng = np.random.default_rng(1)
    return LabelledCloud(
        rng.normal(size=(n, 3)).astype(np.float32),
        rng.integers(0, 256, (n, 3), dtype=np.uint8),
        rng.integers(0, 11, n, dtype=np.uint8),
        rng.integers(0, 9, n, dtype=np.int32) if clusters else None,
    )


@pytest.mark.parametrize("clusters", [True, False])
def test_ply_round_trip_keeps_every_field(tmp_path: Path, clusters: bool) -> None:
    cloud = _cloud(clusters=clusters)
    write_ply(tmp_path / "c.ply", cloud)
    back = read_cloud(tmp_path / "c.ply")
    np.testing.assert_array_equal(back.points, cloud.points)
    np.testing.assert_array_equal(back.colors, cloud.colors)
    np.testing.assert_array_equal(back.labels, cloud.labels)
    if clusters:
        assert back.clusters is not None and cloud.clusters is not None
        np.testing.assert_array_equal(back.clusters, cloud.clusters)
    else:
        assert back.clusters is None
    assert not list(tmp_path.glob(".*tmp"))  # the temporary file was renamed away


def test_our_ply_loads_in_open3d(tmp_path: Path) -> None:
    import open3d as o3d

    cloud = _cloud()
    write_ply(tmp_path / "c.ply", cloud)
    loaded = o3d.io.read_point_cloud(tmp_path / "c.ply")
    np.testing.assert_allclose(np.asarray(loaded.points), cloud.points, atol=1e-6)
    np.testing.assert_allclose(np.asarray(loaded.colors) * 255, cloud.colors, atol=0.5)


def test_ascii_ply_with_double_coordinates_is_read() -> None:
    text = (
        "ply\nformat ascii 1.0\nelement vertex 2\nproperty double x\nproperty double y\n"
        "property double z\nproperty int label\nend_header\n0 1 2 4\n3 4 5 7\n"
    )
    cloud = parse_ply(text.encode(), source="mem")
    np.testing.assert_array_equal(cloud.points, [[0, 1, 2], [3, 4, 5]])
    assert list(cloud.labels) == [4, 7]
    assert (cloud.colors == 128).all()


def test_pcd_with_a_label_field_is_read_through_open3d(tmp_path: Path) -> None:
    import open3d as o3d

    cloud = _cloud(clusters=False)
    pcd = o3d.t.geometry.PointCloud()
    pcd.point.positions = o3d.core.Tensor.from_numpy(cloud.points)
    pcd.point.colors = o3d.core.Tensor.from_numpy(cloud.colors)
    pcd.point.label = o3d.core.Tensor.from_numpy(cloud.labels.astype(np.uint32)[:, None].copy())
    path = tmp_path / "c.pcd"
    assert o3d.t.io.write_point_cloud(path, pcd, compressed=True)  # binary_compressed
    back = read_cloud(path)
    np.testing.assert_array_equal(back.points, cloud.points)
    np.testing.assert_array_equal(back.labels, cloud.labels)
    np.testing.assert_array_equal(back.colors, cloud.colors)


def test_real_pcd_without_labels_is_refused_or_read_unlabelled(shared_data: Path) -> None:
    path = shared_data / "pcl" / "table_scene_mug_stereo_textured.pcd"
    with pytest.raises(CloudError, match="expected a 'label' field") as err:
        read_cloud(path)
    assert "\n" not in str(err.value) and str(err.value).endswith(str(path))
    cloud = read_cloud(path, require_labels=False)
    assert 200_000 < len(cloud) < 307_200  # organised 640x480 less the NaN points
    assert np.isfinite(cloud.points).all() and (cloud.labels == 0).all()


def test_ply_without_labels_is_refused_in_one_line(tmp_path: Path) -> None:
    props = "".join(f"property float {a}\n" for a in "xyz")
    text = f"ply\nformat ascii 1.0\nelement vertex 1\n{props}end_header\n0 0 0\n"
    (tmp_path / "u.ply").write_text(text)
    with pytest.raises(CloudError, match=r"expected a 'label' field.*u\.ply$"):
        read_cloud(tmp_path / "u.ply")


TRUNCATED = (
    b"ply\nformat binary_little_endian 1.0\nelement vertex 10\nproperty float x\n"
    b"property float y\nproperty float z\nproperty uchar label\nend_header\n" + b"\0" * 13
)


TRUNCATED = (
    b"ply\nformat binary_little_endian 1.0\nelement vertex 10\nproperty float x\n"
    b"property float y\nproperty float z\nproperty uchar label\nend_header\n" + b"\0" * 13
)


@pytest.mark.parametrize(
    ("name", "data", "match"),
    [
        ("x.ply", b"not a ply", "expected a PLY file"),
        ("x.ply", TRUNCATED, "ends early"),
        ("x.xyz", b"0 0 0", "expected a .ply or .pcd"),
        ("x.pcd", b"garbage", "FIELDS"),
    ],
)
def test_bad_files_give_one_line_errors(tmp_path: Path, name: str, data: bytes, match: str) -> None:
    (tmp_path / name).write_bytes(data)
    with pytest.raises(CloudError, match=match) as err:
        read_cloud(tmp_path / name)
    assert "\n" not in str(err.value)


def test_a_missing_file_is_a_cloud_error(tmp_path: Path) -> None:
    with pytest.raises(CloudError, match="cannot read"):
        read_cloud(tmp_path / "none.ply")


def test_wrong_array_types_are_refused() -> None:
    with pytest.raises(CloudError, match="labels must be uint8"):
        LabelledCloud(
            np.zeros((2, 3), np.float32), np.zeros((2, 3), np.uint8), np.zeros(2, np.int64)
        )  # type: ignore[arg-type]


def test_labels_outside_the_recording_table_are_refused() -> None:
    text = (
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
        "property float z\nproperty uchar label\nend_header\n0 0 0 42\n"
    )
    with pytest.raises(CloudError, match=r"integer 'label' values in 0\.\.10, found 42"):
        parse_ply(text.encode(), source="mem")
