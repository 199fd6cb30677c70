"""Microsoft 7-Scenes: one seq-NN folder of frame-XXXXXX.{color.png,depth.png,pose.txt}."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Final

import numpy as np
import numpy.typing as npt

from capture.errors import ImportFormatError
from capture.importers.common import (
    _SEVEN_SCENES_COLOR,
    _Dataset,
    _format_error,
    _Frame,
    _index_stamp_ns,
    _numbers,
)
from capture.recording.frames import Intrinsics

SEVEN_SCENES_K: Final = Intrinsics(640, 480, 585.0, 585.0, 320.0, 240.0)
SEVEN_SCENES_INVALID_DEPTH: Final = 65535


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
