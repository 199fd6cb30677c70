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

import logging
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import Final

import cv2
import numpy as np
import numpy.typing as npt

from capture.errors import ImportFormatError
from capture.importers.common import FPS_WITHOUT_STAMPS, _Dataset, detect_kind
from capture.importers.redwood import PRIMESENSE_K, SLAMBOOK_K, _load_redwood
from capture.importers.seven_scenes import SEVEN_SCENES_INVALID_DEPTH, SEVEN_SCENES_K, _load_7scenes
from capture.importers.tum import (
    TUM_DEPTH_UNITS_PER_M,
    TUM_INTRINSICS,
    TUM_MAX_DIFFERENCE_NS,
    _load_tum,
    associate,
)
from capture.recording.frames import Intrinsics
from capture.recording.writer import RecordingWriter, capture_record

__all__ = [
    "FPS_WITHOUT_STAMPS",
    "KINDS",
    "PRIMESENSE_K",
    "SEVEN_SCENES_INVALID_DEPTH",
    "SEVEN_SCENES_K",
    "SLAMBOOK_K",
    "TUM_DEPTH_UNITS_PER_M",
    "TUM_INTRINSICS",
    "TUM_MAX_DIFFERENCE_NS",
    "associate",
    "detect_kind",
    "import_dataset",
]

logger = logging.getLogger(__name__)

KINDS: Final = ("tum", "7scenes", "redwood")


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


# -- writing --------------------------------------------------------------------------------
def _write(dataset: _Dataset, part: Path, *, kind: str, src: Path, compression: str) -> None:
    k = dataset.intrinsics
    started = datetime.now(UTC).isoformat()
    poses = 0
    with RecordingWriter(part, compression=compression) as writer:
        device = {"name": dataset.name, "depth_scale_m": "0.001"}
        if dataset.color_readout_s is not None:
            device["rolling_shutter_readout_s"] = f"{dataset.color_readout_s:g}"
        writer.write_metadata("device", device)
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
            capture_record(
                "semreplay-capture import",
                source=str(src.resolve()),
                config={"compression": compression},
                start_time=started,
                kind=kind,
                layout=dataset.layout,
                frames_written={"color": n, "depth": n, "ground_truth_pose": poses},
                frames_dropped={"color": dataset.dropped},
            )
        )


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
