"""The labelled point cloud value and its files: binary PLY (ours and others') and PCD (Open3D)."""

from __future__ import annotations

import logging
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Final

import numpy as np
import numpy.typing as npt

from capture.recording import NUM_LABELS
from process.errors import CloudError

logger = logging.getLogger(__name__)

_PLY_TYPES: Final = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}  # fmt: skip
_PLY_FORMATS: Final = {"binary_little_endian": "<", "binary_big_endian": ">", "ascii": "ascii"}
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


def write_atomic(path: Path, data: bytes) -> None:
    """Write bytes to a temporary name beside `path`, then rename it into place."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        tmp.write_bytes(data)
        tmp.replace(path)
    except OSError as err:
        tmp.unlink(missing_ok=True)
        raise CloudError(
            f"cannot write {path.name}: {err.strerror}; check the folder: {path}"
        ) from err


def ply_bytes(cloud: LabelledCloud) -> bytes:
    """Encode a cloud as binary little-endian PLY (x y z, red green blue, label, [cluster])."""
    fields: list[tuple[str, str]] = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    fields += [("red", "u1"), ("green", "u1"), ("blue", "u1"), ("label", "u1")]
    if cloud.clusters is not None:
        fields.append(("cluster", "<i4"))
    vertices = np.empty(len(cloud), dtype=fields)
    for axis, name in enumerate("xyz"):
        vertices[name] = cloud.points[:, axis]
    for channel, name in enumerate(("red", "green", "blue")):
        vertices[name] = cloud.colors[:, channel]
    vertices["label"] = cloud.labels
    if cloud.clusters is not None:
        vertices["cluster"] = cloud.clusters
    names = {"<f4": "float", "u1": "uchar", "<i4": "int"}
    header = ["ply", "format binary_little_endian 1.0", "comment semreplay labelled cloud"]
    header.append(f"element vertex {len(cloud)}")
    header += [f"property {names[dtype]} {name}" for name, dtype in fields]
    header.append("end_header\n")
    return "\n".join(header).encode("ascii") + vertices.tobytes()


def write_ply(path: Path, cloud: LabelledCloud) -> None:
    """Write a cloud as binary little-endian PLY, atomically (temporary name, then rename)."""
    write_atomic(path, ply_bytes(cloud))


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
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise CloudError(
            f"expected a PLY file ('ply' ... 'end_header'), found other bytes: {source}"
        )
    body = end + len(b"end_header")
    body += 2 if data[body : body + 2] == b"\r\n" else 1
    lines = data[:end].decode("ascii", errors="replace").splitlines()
    fmt, elements = _ply_header(lines, source)
    offset = body
    for name, count, fields in elements:
        if not fields:
            raise CloudError(
                f"PLY element {name!r} has no properties; expected x y z ...: {source}"
            )
        dtype = np.dtype([(f, (fmt if fmt != "ascii" else "<") + t) for f, t in fields])
        if name == "vertex":
            if fmt == "ascii":
                vertices = _ascii_vertices(data[offset:], count, dtype, source)
            else:
                if len(data) < offset + count * dtype.itemsize:
                    raise CloudError(
                        f"PLY says {count} vertices but the file ends early "
                        f"({len(data) - offset} bytes of {count * dtype.itemsize}): {source}"
                    )
                vertices = np.frombuffer(data, dtype=dtype, count=count, offset=offset)
            return _cloud_from_fields(vertices, source, require_labels=require_labels)
        if fmt == "ascii":
            raise CloudError(
                f"ascii PLY with element {name!r} before 'vertex' is not supported: {source}"
            )
        offset += count * dtype.itemsize
    raise CloudError(f"expected a 'vertex' element in the PLY header, found none: {source}")


def _ply_header(
    lines: list[str], source: str
) -> tuple[str, list[tuple[str, int, list[tuple[str, str]]]]]:
    fmt = ""
    elements: list[tuple[str, int, list[tuple[str, str]]]] = []
    for line in lines[1:]:
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format" and len(words) >= 2 and words[1] in _PLY_FORMATS:
            fmt = _PLY_FORMATS[words[1]]
        elif words[0] == "element" and len(words) == 3 and words[2].isdigit():
            elements.append((words[1], int(words[2]), []))
        elif words[0] == "property" and elements and len(words) == 3 and words[1] in _PLY_TYPES:
            if any(name == words[2] for name, _ in elements[-1][2]):
                raise CloudError(
                    f"PLY element {elements[-1][0]!r} declares property {words[2]!r} twice; "
                    f"expected each once: {source}"
                )
            elements[-1][2].append((words[2], _PLY_TYPES[words[1]]))
        else:
            raise CloudError(
                f"unsupported PLY header line {line.strip()!r} (list properties?): {source}"
            )
    if not fmt:
        raise CloudError(f"expected a PLY 'format' line (ascii or binary), found none: {source}")
    return fmt, elements


def _ascii_vertices(
    body: bytes, count: int, dtype: np.dtype[np.void], source: str
) -> npt.NDArray[np.void]:
    rows = body.split(b"\n", count)[:count]
    try:
        table = np.array([r.split() for r in rows], dtype=np.float64)
    except ValueError as err:
        raise CloudError(
            f"ascii PLY rows are not {len(dtype.names or ())} numbers each: {source}"
        ) from err
    if table.shape != (count, len(dtype.names or ())):
        raise CloudError(f"ascii PLY says {count} vertices but has {len(rows)} rows: {source}")
    out = np.empty(count, dtype=dtype)
    for column, name in enumerate(dtype.names or ()):
        out[name] = table[:, column]
    return out


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
