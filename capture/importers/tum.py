"""TUM RGB-D: rgb.txt / depth.txt associated as associate.py does, groundtruth.txt interpolated."""

from __future__ import annotations

import bisect
import logging
import re
from decimal import Decimal, InvalidOperation
from pathlib import Path
from typing import Final

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation, Slerp

from capture.errors import ImportFormatError
from capture.importers.common import _Dataset, _format_error, _Frame, _pose_matrix
from capture.recording.frames import Intrinsics

logger = logging.getLogger(__name__)

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
# The rolling-shutter readout of the Kinect v1 colour camera (TUM freiburg 1 and 2; freiburg 3
# used an Asus Xtion, the same PrimeSense design). No datasheet gives it: it is bounded by the
# 33 ms frame period, and the only literature value found is 28 ms for a *simulated* rolling-
# shutter RGB-D camera (Kerl, Stueckler, Cremers, ICCV 2015, project page). 20 ms is measured,
# not documented: on TUM fr1_rpy, ATE over the whole sequence and over three of four 120-frame
# slices is lowest at 20 ms of 0, 10, 20, 28 and 33 ms (README.md, "Rolling shutter").
TUM_COLOR_READOUT_S: Final = 0.020


def _stamp_ns(text: str, path: Path) -> int:
    """Return seconds written in decimal as exact integer nanoseconds."""
    try:
        return int(Decimal(text) * 1_000_000_000)
    except InvalidOperation as err:
        raise ImportFormatError(f"expected a stamp in seconds, found {text!r}: {path}") from err


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
        color_readout_s=TUM_COLOR_READOUT_S,
    )
