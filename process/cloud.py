"""The labelled point cloud value and its files: binary PLY (ours and others') and PCD (Open3D)."""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Final

import numpy as np
import numpy.typing as npt

from capture.errors import RecordingError
from capture.recording import NUM_LABELS, ply
from process.errors import CloudError
from process.outputs import write_bytes_atomic

logger = logging.getLogger(__name__)

_GREY: Final = 128  # colour of points whose file has none
MAX_COORD_M: Final = 1e5  # a room, a building, a campus: never farther than this


@dataclass(frozen=True)
class LabelledCloud:
    """A world-frame point cloud with a colour, a RECORDING.md label and a cluster id per point."""

    points: npt.NDArray[np.float32]  # (N, 3), world frame, metres
    colors: npt.NDArray[np.uint8]  # (N, 3) RGB
    labels: npt.NDArray[np.uint8]  # (N,) RECORDING.md label ids, 0 = unlabelled
    clusters: npt.NDArray[np.int32] | None = None  # (N,) 0 = none; None before refinement

    def __post_init__(self) -> None:
        n = len(self.points)
        shapes = {
            "points": (self.points.shape, (n, 3), np.float32),
            "colors": (self.colors.shape, (n, 3), np.uint8),
            "labels": (self.labels.shape, (n,), np.uint8),
        }
        if self.clusters is not None:
            shapes["clusters"] = (self.clusters.shape, (n,), np.int32)
        for name, (found, expected, dtype) in shapes.items():
            array = getattr(self, name)
            if found != expected or array.dtype != dtype:
                raise CloudError(
                    f"LabelledCloud.{name} must be {np.dtype(dtype)} of shape {expected}; "
                    f"got {array.dtype} of shape {found}; convert it before building the cloud"
                )

    def __len__(self) -> int:
        return len(self.points)

    @staticmethod
    def empty() -> LabelledCloud:
        """Return a cloud without points."""
        return LabelledCloud(
            np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint8), np.zeros(0, np.uint8)
        )

    def select(self, indices: npt.NDArray[np.intp] | npt.NDArray[np.bool_]) -> LabelledCloud:
        """Return the points at `indices` (an index array or a boolean mask)."""
        clusters = None if self.clusters is None else self.clusters[indices]
        return LabelledCloud(
            self.points[indices], self.colors[indices], self.labels[indices], clusters
        )

    def with_labels(
        self,
        labels: npt.NDArray[np.uint8],
        *,
        clusters: npt.NDArray[np.int32] | None = None,
    ) -> LabelledCloud:
        """Return the same points and colours with other labels (and clusters)."""
        return LabelledCloud(self.points, self.colors, labels, clusters)


def ply_bytes(cloud: LabelledCloud) -> bytes:
    """Encode a cloud as binary little-endian PLY (x y z, red green blue, label, [cluster])."""
    fields: list[tuple[str, str]] = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    fields += [("red", "u1"), ("green", "u1"), ("blue", "u1"), ("label", "u1")]
    if cloud.clusters is not None:
        fields.append(("cluster", "<i4"))
    vertices = np.empty(len(cloud), dtype=fields)
    vertices["x"], vertices["y"], vertices["z"] = cloud.points.T
    vertices["red"], vertices["green"], vertices["blue"] = cloud.colors.T
    vertices["label"] = cloud.labels
    if cloud.clusters is not None:
        vertices["cluster"] = cloud.clusters
    return ply.encode(vertices, comment="semreplay labelled cloud")


def write_ply(path: Path, cloud: LabelledCloud) -> None:
    """Write a cloud as binary little-endian PLY, atomically (temporary name, then rename)."""
    write_bytes_atomic(path, ply_bytes(cloud))


def read_cloud(path: Path, *, require_labels: bool = True, min_points: int = 0) -> LabelledCloud:
    """Read a labelled cloud from PLY (our own reader) or PCD (through Open3D).

    Non-finite points are dropped. Without a `label` field the cloud is refused, or, with
    `require_labels=False`, every point gets label 0.

    Raises:
        CloudError: the file is missing, of another format, malformed, lacks x y z (or label),
            or has fewer than `min_points` finite points.
    """
    cloud = _read_cloud(path, require_labels=require_labels)
    if len(cloud) < min_points:
        raise CloudError(
            f"expected at least {min_points} finite point(s), found {len(cloud)}; "
            f"is the cloud empty?: {path}"
        )
    return cloud


def _read_cloud(path: Path, *, require_labels: bool) -> LabelledCloud:
    suffix = path.suffix.lower()
    if suffix not in (".ply", ".pcd"):
        raise CloudError(
            f"expected a .ply or .pcd point cloud, got {suffix or 'no suffix'!r}: {path}"
        )
    try:
        data = path.read_bytes()
    except OSError as err:
        raise CloudError(f"cannot read the point cloud ({err.strerror}): {path}") from err
    if suffix == ".ply":
        return parse_ply(data, source=str(path), require_labels=require_labels)
    return _read_pcd(path, data, require_labels=require_labels)


def parse_ply(data: bytes, *, source: str, require_labels: bool = True) -> LabelledCloud:
    """Decode PLY bytes (ascii or binary; the vertex element) into a labelled cloud."""
    try:
        vertices = ply.decode(data, source=source)
    except RecordingError as err:
        raise CloudError(str(err)) from err
    return _cloud_from_fields(vertices, source, require_labels=require_labels)


def _cloud_from_fields(
    fields: npt.NDArray[np.void], source: str, *, require_labels: bool
) -> LabelledCloud:
    names = set(fields.dtype.names or ())
    if not {"x", "y", "z"} <= names:
        raise CloudError(f"expected vertex fields x y z, found {sorted(names)}: {source}")
    points = np.stack([fields[a] for a in "xyz"], axis=1).astype(np.float32)
    colors = _colors(fields, names, len(points))
    labels = _integer_field(fields, "label", source, require=require_labels, high=NUM_LABELS - 1)
    clusters = None
    if "cluster" in names:
        clusters = _integer_field(fields, "cluster", source, require=True, high=2**31 - 1)
    keep = np.isfinite(points).all(axis=1)
    if len(points) and not keep.any():
        raise CloudError(f"none of the cloud's {len(points)} points is finite (NaN/inf): {source}")
    if keep.any() and float(np.abs(points[keep]).max()) > MAX_COORD_M:
        raise CloudError(
            f"coordinates up to {float(np.abs(points[keep]).max()):.3g} m; expected metres "
            f"within +-{MAX_COORD_M:g} (another unit, or a corrupt file?): {source}"
        )
    cloud = LabelledCloud(
        points,
        colors,
        labels.astype(np.uint8),
        None if clusters is None else clusters.astype(np.int32),
    )
    return cloud if bool(keep.all()) else cloud.select(np.asarray(keep, bool))


def _colors(fields: npt.NDArray[np.void], names: set[str], n: int) -> npt.NDArray[np.uint8]:
    if not {"red", "green", "blue"} <= names:
        return np.full((n, 3), _GREY, np.uint8)
    rgb = np.stack([fields[c] for c in ("red", "green", "blue")], axis=1)
    if rgb.dtype.kind == "f":  # float colours in [0, 1]
        rgb = np.clip(np.nan_to_num(rgb) * 255.0 + 0.5, 0, 255)
    return rgb.astype(np.uint8)


def _integer_field(
    fields: npt.NDArray[np.void], name: str, source: str, *, require: bool, high: int
) -> npt.NDArray[np.int64]:
    if name not in (fields.dtype.names or ()):
        if require:
            found = " ".join(fields.dtype.names or ())
            raise CloudError(
                f"expected a {name!r} field per point, found fields {found}; "
                f"label the cloud first (e.g. `semreplay-process run`): {source}"
            )
        return np.zeros(len(fields), np.int64)
    values = np.asarray(fields[name])
    as_int: npt.NDArray[np.int64] = np.nan_to_num(values).astype(np.int64)
    if len(values) and (as_int.min() < 0 or as_int.max() > high or (as_int != values).any()):
        raise CloudError(
            f"expected integer {name!r} values in 0..{high}, found {values.min()}..{values.max()}: "
            f"{source}"
        )
    return as_int


def _read_pcd(path: Path, data: bytes, *, require_labels: bool) -> LabelledCloud:
    match = re.search(rb"^FIELDS ([^\n]*)$", data[:4096], flags=re.MULTILINE)
    if match is None:
        raise CloudError(f"expected a PCD header with a FIELDS line, found none: {path}")
    declared = match.group(1).decode("ascii", errors="replace").split()
    if require_labels and "label" not in declared:
        raise CloudError(
            f"expected a 'label' field per point, found fields {' '.join(declared)}; "
            f"label the cloud first (e.g. `semreplay-process run`): {path}"
        )
    import open3d as o3d  # heavy: imported only when a PCD is read

    pcd = o3d.t.io.read_point_cloud(path)
    if "positions" not in pcd.point or len(pcd.point["positions"]) == 0:
        raise CloudError(f"Open3D could not read any point from this PCD: {path}")
    attrs = {name: pcd.point[name].numpy() for name in pcd.point}
    fields = np.empty(len(attrs["positions"]), dtype=_pcd_dtype(attrs))
    for axis, name in enumerate("xyz"):
        fields[name] = attrs["positions"][:, axis]
    if "colors" in attrs:
        for channel, name in enumerate(("red", "green", "blue")):
            fields[name] = attrs["colors"][:, channel]
    for name in ("label", "cluster"):
        if name in attrs:
            fields[name] = attrs[name].reshape(-1)
    return _cloud_from_fields(fields, str(path), require_labels=require_labels)


def _pcd_dtype(attrs: dict[str, npt.NDArray[np.generic]]) -> list[tuple[str, str]]:
    dtype = [("x", "f4"), ("y", "f4"), ("z", "f4")]
    if "colors" in attrs:
        kind = attrs["colors"].dtype.str
        dtype += [("red", kind), ("green", kind), ("blue", kind)]
    dtype += [(name, attrs[name].dtype.str) for name in ("label", "cluster") if name in attrs]
    return dtype
