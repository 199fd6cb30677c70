"""Shared pieces of the dataset loaders: frame and dataset records, kind detection, parsing."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Final

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

from capture.errors import ImportFormatError
from capture.recording.frames import Intrinsics

FPS_WITHOUT_STAMPS: Final = 30.0
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
    # the colour camera's rolling-shutter readout (s), written to the `device` record; None: unknown
    color_readout_s: float | None = None


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


# -- shared parsing -------------------------------------------------------------------------
def _pose_matrix(values: list[float]) -> npt.NDArray[np.float64]:
    """Return the 4x4 of `tx ty tz qx qy qz qw`."""
    out = np.eye(4)
    out[:3, :3] = Rotation.from_quat(values[3:7]).as_matrix()
    out[:3, 3] = values[:3]
    return out


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
