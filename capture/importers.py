"""Existing RGB-D datasets into recordings: TUM RGB-D, 7-Scenes, Redwood/ICL-NUIM and slambook2.

Each loader checks a dataset folder and lists its frames (file paths, stamp, ground-truth pose)
before anything is written; `import_dataset` then streams them through `RecordingWriter` into
`OUT.mcap.part` and renames that to `OUT.mcap` only once the recording is finished.

Kind "redwood" covers two layouts that share color/ + depth/ and differ in the trajectory file:
- Redwood / ICL-NUIM (Open3D's layout): color/ (or image/), depth/ (PNG, mm), trajectory.log
  (Redwood log: a line `i j n`, then the 4x4 camera-to-world of frame i), an optional Open3D
  PinholeCameraIntrinsic json, else Open3D's PrimeSense default (fx = fy = 525, 319.5, 239.5).
- slambook2 ("14 Lectures on Visual SLAM"): color/N.png, depth/N.pgm (mm), pose.txt (one line
  `tx ty tz qx qy qz qw` camera-to-world per frame), its Kinect intrinsics unless a json is present.
All these datasets ship depth registered to colour, so depth is written as aligned depth in mm.
Datasets without stamps get frame index / 30 fps.
"""

from __future__ import annotations

import bisect
import json
import logging
import re
from collections.abc import Callable
from dataclasses import dataclass, replace
from datetime import UTC, datetime
from decimal import Decimal, InvalidOperation
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Final

import cv2
import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation, Slerp

from capture.errors import ImportFormatError
from capture.frames import Intrinsics
from capture.mcap_writer import RecordingWriter

logger = logging.getLogger(__name__)

KINDS: Final = ("tum", "7scenes", "redwood")
FPS_WITHOUT_STAMPS: Final = 30.0
TUM_MAX_DIFFERENCE_NS: Final = 20_000_000  # associate.py's default --max_difference 0.02 s
TUM_DEPTH_UNITS_PER_M: Final = 5000
# TUM's calibrated colour cameras (file_formats page: "Intrinsic Camera Calibration of the Kinect").
TUM_INTRINSICS: Final = {
    "1": Intrinsics(640, 480, 517.3, 516.5, 318.6, 255.3,
                    coeffs=(0.2624, -0.9531, -0.0054, 0.0026, 1.1633)),
    "2": Intrinsics(640, 480, 520.9, 521.0, 325.1, 249.7,
                    coeffs=(0.2312, -0.7849, -0.0033, -0.0001, 0.9172)),
    "3": Intrinsics(640, 480, 535.4, 539.2, 320.1, 247.6),  # fr3 images come undistorted
}  # fmt: skip
SEVEN_SCENES_K: Final = Intrinsics(640, 480, 585.0, 585.0, 320.0, 240.0)
SEVEN_SCENES_INVALID_DEPTH: Final = 65535
PRIMESENSE_K: Final = Intrinsics(640, 480, 525.0, 525.0, 319.5, 239.5)  # Open3D PrimeSenseDefault
SLAMBOOK_K: Final = Intrinsics(640, 480, 518.0, 519.0, 325.5, 253.5)
_COLOR_SUFFIXES: Final = (".png", ".jpg", ".jpeg")
_DEPTH_SUFFIXES: Final = (".png", ".pgm")
_SEVEN_SCENES_COLOR: Final = re.compile(r"frame-(\d+)\.color\.(png|jpg)$")


@dataclass(frozen=True, slots=True)
class _Frame:
    stamp_ns: int
    color: Path
    depth: Path
    world_from_camera: npt.NDArray[np.float64] | None  # (4, 4), colour optical frame


@dataclass(frozen=True, slots=True)
class _Dataset:
    name: str
    layout: str
    intrinsics: Intrinsics
    frames: list[_Frame]
    depth_units_per_m: int = 1000
    invalid_depth: int | None = None
    dropped: int = 0  # colour frames without a depth partner


def import_dataset(kind: str, src: Path, out: Path, *, compression: str = "zstd") -> int:
    """Convert the dataset folder `src` of `kind` into the recording `out`; return frames written.

    Raises:
        ImportFormatError: `kind` is unknown or `src` does not hold a dataset of that kind.
    """
    loaders: dict[str, Callable[[Path], _Dataset]] = {
        "tum": _load_tum,
        "7scenes": _load_7scenes,
        "redwood": _load_redwood,
    }
    if kind not in loaders:
        raise ImportFormatError(
            f"unknown dataset kind {kind!r}; expected one of {', '.join(KINDS)}"
        )
    src, out = Path(src), Path(out)
    if not src.is_dir():
        raise ImportFormatError(f"expected a {kind} dataset folder, found no directory: {src}")
    dataset = loaders[kind](src)
    if not dataset.frames:
        raise ImportFormatError(f"the {kind} dataset lists no complete colour+depth frame: {src}")
    absent = next((p for f in dataset.frames for p in (f.color, f.depth) if not p.is_file()), None)
    if absent is not None:
        raise ImportFormatError(
            f"expected the image that the {kind} dataset lists, found none: {absent}"
        )
    part = out.with_suffix(".mcap.part")
    try:
        _write(dataset, part, kind=kind, src=src, compression=compression)
    except BaseException:
        part.unlink(missing_ok=True)
        raise
    part.replace(out)
    logger.info(
        "imported %d frames of %s (%s) into %s", len(dataset.frames), src, dataset.name, out
    )
    return len(dataset.frames)


def detect_kind(src: Path) -> str | None:
    """Return the dataset kind whose files `src` holds, or None."""
    names = {p.name for p in Path(src).iterdir()} if Path(src).is_dir() else set()
    if {"rgb.txt", "depth.txt"} <= names:
        return "tum"
    if any(_SEVEN_SCENES_COLOR.match(n) for n in names):
        return "7scenes"
    if "depth" in names and names & {"color", "image"}:
        return "redwood"
    return None


def _format_error(kind: str, src: Path, missing: str) -> ImportFormatError:
    names = sorted(p.name + ("/" if p.is_dir() else "") for p in src.iterdir())
    found = ", ".join(names[:8]) + (f" (+{len(names) - 8} more)" if len(names) > 8 else "")
    guess = detect_kind(src)
    hint = f"; it looks like a {guess!r} dataset" if guess and guess != kind else ""
    return ImportFormatError(
        f"not a {kind} dataset folder: missing {missing}; found {found or 'nothing'}{hint}: {src}"
    )


# -- writing --------------------------------------------------------------------------------
def _write(dataset: _Dataset, part: Path, *, kind: str, src: Path, compression: str) -> None:
    k = dataset.intrinsics
    started = datetime.now(UTC).isoformat()
    poses = 0
    with RecordingWriter(part, compression=compression) as writer:
        writer.write_metadata("device", {"name": dataset.name, "depth_scale_m": "0.001"})
        for frame in dataset.frames:
            # The importer did the association, so the depth of a pair carries the colour stamp.
            writer.write_color(_read_color(frame.color, k), stamp_ns=frame.stamp_ns, intrinsics=k)
            depth_mm = _read_depth_mm(frame.depth, dataset)
            writer.write_depth(depth_mm, stamp_ns=frame.stamp_ns, intrinsics=k, aligned=True)
            if frame.world_from_camera is not None:
                writer.write_ground_truth(
                    stamp_ns=frame.stamp_ns, world_from_camera=frame.world_from_camera
                )
                poses += 1
        n = len(dataset.frames)
        writer.finish(
            {
                "tool": "semreplay-capture import",
                "version": _version(),
                "kind": kind,
                "layout": dataset.layout,
                "source": str(src.resolve()),
                "start_time": started,
                "frames_written": {"color": n, "depth": n, "ground_truth_pose": poses},
                "frames_dropped": {"color": dataset.dropped},
            }
        )


def _version() -> str:
    try:
        return version("semreplay")
    except PackageNotFoundError:
        return "unknown"


def _read_color(path: Path, k: Intrinsics) -> npt.NDArray[np.uint8]:
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if bgr is None:
        raise ImportFormatError(f"expected a colour image, found an unreadable file: {path}")
    if bgr.shape[:2] != (k.height, k.width):
        raise ImportFormatError(
            f"expected a {k.width}x{k.height} colour image (the intrinsics' size), found "
            f"{bgr.shape[1]}x{bgr.shape[0]}; check the camera file: {path}"
        )
    return np.ascontiguousarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), dtype=np.uint8)


def _read_depth_mm(path: Path, dataset: _Dataset) -> npt.NDArray[np.uint16]:
    raw = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    k = dataset.intrinsics
    if raw is None or raw.dtype != np.uint16 or raw.ndim != 2:
        found = "an unreadable file" if raw is None else f"{raw.dtype} {raw.shape}"
        raise ImportFormatError(
            f"expected a 16-bit single-channel depth image, found {found}: {path}"
        )
    if raw.shape != (k.height, k.width):
        raise ImportFormatError(
            f"expected depth registered to colour ({k.width}x{k.height}), found "
            f"{raw.shape[1]}x{raw.shape[0]}: {path}"
        )
    if dataset.invalid_depth is not None:
        raw = np.where(raw == dataset.invalid_depth, 0, raw)
    if dataset.depth_units_per_m == 1000:
        return np.ascontiguousarray(raw, dtype=np.uint16)
    # Integer round-half-up to mm, so that e.g. TUM's 5000 units/m convert without float error.
    units = dataset.depth_units_per_m
    mm = (raw.astype(np.uint64) * 1000 + units // 2) // units
    return np.clip(mm, 0, 65535).astype(np.uint16)


# -- shared parsing -------------------------------------------------------------------------
def _pose_matrix(values: list[float]) -> npt.NDArray[np.float64]:
    """Return the 4x4 of `tx ty tz qx qy qz qw`."""
    out = np.eye(4)
    out[:3, :3] = Rotation.from_quat(values[3:7]).as_matrix()
    out[:3, 3] = values[:3]
    return out


def _stamp_ns(text: str, path: Path) -> int:
    """Return seconds written in decimal as exact integer nanoseconds."""
    try:
        return int(Decimal(text) * 1_000_000_000)
    except InvalidOperation as err:
        raise ImportFormatError(f"expected a stamp in seconds, found {text!r}: {path}") from err


def _index_stamp_ns(index: int) -> int:
    return round(index * 1_000_000_000 / FPS_WITHOUT_STAMPS)


def _numbers(path: Path, columns: int) -> list[list[float]]:
    """Return the rows of `columns` numbers of a text file ('#' starts a comment)."""
    rows = []
    for line in path.read_text().splitlines():
        fields = line.replace(",", " ").split()
        if not fields or fields[0].startswith("#"):
            continue
        if len(fields) < columns:
            raise ImportFormatError(f"expected {columns} numbers per line, found {line!r}: {path}")
        try:
            rows.append([float(f) for f in fields[:columns]])
        except ValueError as err:
            raise ImportFormatError(f"expected numbers, found {line!r}: {path}") from err
    return rows


def _natural_images(folder: Path, suffixes: tuple[str, ...]) -> list[Path]:
    """Return the images of a folder in natural order (2.png before 10.png)."""
    files = [p for p in folder.iterdir() if p.suffix.lower() in suffixes]
    return sorted(
        files, key=lambda p: [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", p.stem)]
    )


# -- TUM RGB-D ------------------------------------------------------------------------------
def _read_tum_list(path: Path) -> list[tuple[int, list[str]]]:
    """Return (stamp_ns, other fields) per line of a TUM list, as associate.py reads it."""
    rows = []
    for line in path.read_text().splitlines():
        fields = line.replace(",", " ").replace("\t", " ").split()
        if fields and not fields[0].startswith("#"):
            rows.append((_stamp_ns(fields[0], path), fields[1:]))
    return rows


def associate(
    first_ns: list[int], second_ns: list[int], *, max_difference_ns: int = TUM_MAX_DIFFERENCE_NS
) -> list[tuple[int, int]]:
    """Pair stamps as TUM's associate.py: closest first, each used once, |a - b| < max."""
    second = sorted(second_ns)
    candidates = []
    for a in first_ns:
        lo = bisect.bisect_right(second, a - max_difference_ns)
        hi = bisect.bisect_left(second, a + max_difference_ns)
        candidates += [(abs(a - b), a, b) for b in second[lo:hi]]
    used_a: set[int] = set()
    used_b: set[int] = set()
    matches = []
    for _, a, b in sorted(candidates):
        if a not in used_a and b not in used_b:
            used_a.add(a)
            used_b.add(b)
            matches.append((a, b))
    return sorted(matches)


class _Trajectory:
    """Ground-truth poses by stamp: slerp between neighbours, else the nearest, in tolerance."""

    def __init__(self, rows: list[tuple[int, list[str]]], *, path: Path, tolerance_ns: int) -> None:
        rows = sorted(rows, key=lambda r: r[0])
        try:
            values = np.array(
                [[float(v) for v in fields[:7]] for _, fields in rows], dtype=np.float64
            )
        except ValueError as err:
            raise ImportFormatError(f"expected 'stamp tx ty tz qx qy qz qw' lines: {path}") from err
        if values.size and values.shape[1] != 7:
            raise ImportFormatError(f"expected 'stamp tx ty tz qx qy qz qw' lines: {path}")
        self.stamps_ns = [stamp for stamp, _ in rows]
        self.values = values.reshape(-1, 7)  # (N, 7) tx ty tz qx qy qz qw
        self.tolerance_ns = tolerance_ns

    def at(self, stamp_ns: int) -> npt.NDArray[np.float64] | None:
        """Return world_from_camera at a stamp, or None when no pose lies within tolerance."""
        s = self.stamps_ns
        i = bisect.bisect_left(s, stamp_ns)
        if i < len(s) and s[i] == stamp_ns:
            return _pose_matrix(list(self.values[i]))
        near = [
            j for j in (i - 1, i) if 0 <= j < len(s) and abs(s[j] - stamp_ns) < self.tolerance_ns
        ]
        if len(near) == 1:
            return _pose_matrix(list(self.values[near[0]]))
        if not near:
            return None
        lo, hi = near
        alpha = (stamp_ns - s[lo]) / (s[hi] - s[lo])
        out = np.eye(4)
        rotations = Rotation.from_quat(self.values[[lo, hi], 3:7])
        out[:3, :3] = Slerp([0.0, 1.0], rotations)(alpha).as_matrix()
        out[:3, 3] = (1.0 - alpha) * self.values[lo, :3] + alpha * self.values[hi, :3]
        return out


def _load_tum(src: Path) -> _Dataset:
    missing = [n for n in ("rgb.txt", "depth.txt") if not (src / n).is_file()]
    if missing:
        raise _format_error("tum", src, " and ".join(missing))
    rgb, depth = _read_tum_list(src / "rgb.txt"), _read_tum_list(src / "depth.txt")
    for name, rows in (("rgb.txt", rgb), ("depth.txt", depth)):
        if any(not fields for _, fields in rows):
            raise ImportFormatError(f"expected 'stamp filename' lines in {name}: {src / name}")
    rgb_files, depth_files = dict(rgb), dict(depth)
    gt_path = src / "groundtruth.txt"
    trajectory = (
        _Trajectory(_read_tum_list(gt_path), path=gt_path, tolerance_ns=TUM_MAX_DIFFERENCE_NS)
        if gt_path.is_file()
        else None
    )
    frames = []
    for a, b in associate(list(rgb_files), list(depth_files)):
        pose = trajectory.at(a) if trajectory else None
        frames.append(_Frame(a, src / rgb_files[a][0], src / depth_files[b][0], pose))
    match = re.search(r"freiburg([123])", src.resolve().name)
    camera = match.group(1) if match else "1"
    if match is None:
        logger.info("no freiburg1/2/3 in the folder name; using the freiburg1 intrinsics: %s", src)
    return _Dataset(
        name=f"TUM RGB-D freiburg{camera}",
        layout="tum",
        intrinsics=TUM_INTRINSICS[camera],
        frames=frames,
        depth_units_per_m=TUM_DEPTH_UNITS_PER_M,
        dropped=len(rgb_files) - len(frames),
    )


# -- 7-Scenes -------------------------------------------------------------------------------
def _load_7scenes(src: Path) -> _Dataset:
    colors = sorted(
        (int(m.group(1)), p) for p in src.iterdir() if (m := _SEVEN_SCENES_COLOR.match(p.name))
    )
    if not colors:
        raise _format_error("7scenes", src, "frame-XXXXXX.color.png|jpg (pass one seq-NN folder)")
    frames = []
    for number, color in colors:
        stem = src / f"frame-{number:06d}"
        depth = stem.with_name(stem.name + ".depth.png")
        if not depth.is_file():
            raise _format_error("7scenes", src, f"{depth.name} beside {color.name}")
        pose = stem.with_name(stem.name + ".pose.txt")
        frames.append(_Frame(_index_stamp_ns(number), color, depth, _read_matrix(pose)))
    k_paths = [d / "camera-intrinsics.txt" for d in (src, src.parent)]
    k_path = next((p for p in k_paths if p.is_file()), None)
    return _Dataset(
        name="7-Scenes",
        layout="7scenes",
        intrinsics=_intrinsics_3x3(k_path) if k_path else SEVEN_SCENES_K,
        frames=frames,
        invalid_depth=SEVEN_SCENES_INVALID_DEPTH,
    )


def _read_matrix(path: Path) -> npt.NDArray[np.float64] | None:
    """Return a 4x4 text matrix, or None when the file is absent or holds an invalid (inf) pose."""
    if not path.is_file():
        return None
    values = np.array(_numbers(path, 4), dtype=np.float64)
    if values.shape != (4, 4):
        raise ImportFormatError(f"expected a 4x4 matrix, found shape {values.shape}: {path}")
    return values if np.isfinite(values).all() else None


def _intrinsics_3x3(path: Path) -> Intrinsics:
    """Return 7-Scenes' 640x480 camera with the matrix K of a text file."""
    K = np.array(_numbers(path, 3), dtype=np.float64)
    if K.shape != (3, 3):
        raise ImportFormatError(f"expected a 3x3 camera matrix, found shape {K.shape}: {path}")
    fx, fy, cx, cy = (float(v) for v in (K[0, 0], K[1, 1], K[0, 2], K[1, 2]))
    return replace(SEVEN_SCENES_K, fx=fx, fy=fy, cx=cx, cy=cy)


# -- Redwood / ICL-NUIM and slambook2 ---------------------------------------------------------
def _load_redwood(src: Path) -> _Dataset:
    color_dir = next((src / n for n in ("color", "image") if (src / n).is_dir()), None)
    trajectory = next(
        (src / n for n in ("trajectory.log", "pose.txt") if (src / n).is_file()), None
    )
    if color_dir is None or not (src / "depth").is_dir() or trajectory is None:
        missing = [
            name
            for name, ok in (
                ("color/", color_dir),
                ("depth/", (src / "depth").is_dir()),
                ("trajectory.log (or pose.txt)", trajectory),
            )
            if not ok
        ]
        raise _format_error("redwood", src, " and ".join(missing))
    colors = _natural_images(color_dir, _COLOR_SUFFIXES)
    depths = _natural_images(src / "depth", _DEPTH_SUFFIXES)
    if len(colors) != len(depths):
        raise ImportFormatError(
            f"expected as many depth as colour images, found {len(colors)} in "
            f"{color_dir.name}/ and {len(depths)} in depth/: {src}"
        )
    slambook = trajectory.name == "pose.txt"
    poses = (
        _slambook_poses(trajectory, len(colors))
        if slambook
        else _redwood_log(trajectory, len(colors))
    )
    frames = [
        _Frame(_index_stamp_ns(i), c, d, poses.get(i))
        for i, (c, d) in enumerate(zip(colors, depths, strict=True))
    ]
    default = SLAMBOOK_K if slambook else PRIMESENSE_K
    return _Dataset(
        name="slambook2 RGB-D" if slambook else "Redwood/ICL-NUIM",
        layout="slambook2" if slambook else "redwood",
        intrinsics=_camera_json(src) or default,
        frames=frames,
    )


def _redwood_log(path: Path, frames: int) -> dict[int, npt.NDArray[np.float64]]:
    """Return camera-to-world by frame index from a Redwood .log (`i j n` then four rows)."""
    lines = [line.split() for line in path.read_text().splitlines() if line.strip()]
    if len(lines) % 5 or any(
        len(lines[b]) != 3 or len(row) != 4
        for b in range(0, len(lines), 5)
        for row in lines[b + 1 : b + 5]
    ):
        raise ImportFormatError(
            f"expected blocks of a line 'i j n' and four rows of 4 numbers: {path}"
        )
    poses = {}
    for b in range(0, len(lines), 5):
        index = int(lines[b][0])
        if not 0 <= index < frames:
            raise ImportFormatError(
                f"expected poses of frames 0..{frames - 1}, found one for frame {index}: {path}"
            )
        poses[index] = np.array(lines[b + 1 : b + 5], dtype=np.float64)
    return poses


def _slambook_poses(path: Path, frames: int) -> dict[int, npt.NDArray[np.float64]]:
    """Return camera-to-world by frame index from slambook2's pose.txt (`tx ty tz qx qy qz qw`)."""
    rows = _numbers(path, 7)
    if len(rows) != frames:
        raise ImportFormatError(
            f"expected one pose per frame ({frames}), found {len(rows)}: {path}"
        )
    return {i: _pose_matrix(row) for i, row in enumerate(rows)}


def _camera_json(src: Path) -> Intrinsics | None:
    """Return the intrinsics of the folder's Open3D camera json (column-major K), if it has one."""
    cameras = []
    for path in sorted(src.glob("*.json")):
        try:
            data = json.loads(path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError):
            continue
        if isinstance(data, dict) and "intrinsic_matrix" in data:
            cameras.append((path, data))
    if len(cameras) > 1:
        raise ImportFormatError(
            f"expected one camera json, found {[p.name for p, _ in cameras]}; keep one: {src}"
        )
    if not cameras:
        return None
    path, data = cameras[0]
    try:
        K = np.array(data["intrinsic_matrix"], dtype=np.float64).reshape(3, 3).T  # column-major
        fx, fy, cx, cy = (float(v) for v in (K[0, 0], K[1, 1], K[0, 2], K[1, 2]))
        return Intrinsics(int(data["width"]), int(data["height"]), fx, fy, cx, cy)
    except (KeyError, ValueError, TypeError) as err:
        raise ImportFormatError(
            f"expected an Open3D camera json (width, height, 9-number intrinsic_matrix), "
            f"found {err!r}: {path}"
        ) from err
