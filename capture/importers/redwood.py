"""Redwood / ICL-NUIM (trajectory.log) and slambook2 (pose.txt): color/ + depth/ image folders."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Final

import numpy as np
import numpy.typing as npt

from capture.errors import ImportFormatError
from capture.importers.common import (
    _Dataset,
    _format_error,
    _Frame,
    _index_stamp_ns,
    _numbers,
    _pose_matrix,
)
from capture.recording.frames import Intrinsics

PRIMESENSE_K: Final = Intrinsics(640, 480, 525.0, 525.0, 319.5, 239.5)  # Open3D PrimeSenseDefault
SLAMBOOK_K: Final = Intrinsics(640, 480, 518.0, 519.0, 325.5, 253.5)
_COLOR_SUFFIXES: Final = (".png", ".jpg", ".jpeg")
_DEPTH_SUFFIXES: Final = (".png", ".pgm")


def _natural_images(folder: Path, suffixes: tuple[str, ...]) -> list[Path]:
    """Return the images of a folder in natural order (2.png before 10.png)."""
    files = [p for p in folder.iterdir() if p.suffix.lower() in suffixes]
    return sorted(
        files, key=lambda p: [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", p.stem)]
    )


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
