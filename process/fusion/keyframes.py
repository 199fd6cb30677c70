"""Fusion in one pass: keyframes are fused as they come and fused again if their poses move.

A loop closure moves keyframes after they were fused. Re-reading the recording to fuse them
again decodes every frame a second time; keeping the keyframes in memory grows with the
recording. Each fused keyframe is therefore written to a temporary folder instead (colour as
JPEG, depth in millimetres and labels with their confidence as PNG: ~0.3 MB each), and when the
final trajectory has moved any of them, the map is rebuilt from those files at the final poses.
They are appended to one anonymous temporary file, which the system removes when it is closed
(removing 3 files per keyframe took 0.3-0.9 s at the end of a 160-keyframe job).

The votes sample every `pixel_stride`-th pixel, so keyframes are cut to those pixels on arrival
(intrinsics scaled to match): the TSDF integrates the same rays as the votes, and storing,
loading and integrating cost a quarter at the default stride of 2.
"""

from __future__ import annotations

import os
import tempfile
from collections import deque
from collections.abc import Iterator, Mapping
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Final

import cv2
import numpy as np
import numpy.typing as npt

from capture.recording import Intrinsics
from process.cloud import LabelledCloud
from process.errors import StageError
from process.fusion.bleed import spilled_labels
from process.fusion.votes import Fusion, FusionConfig

_MOVED_ROTATION_RAD: Final = float(np.radians(0.25))
_JPEG: Final = [cv2.IMWRITE_JPEG_QUALITY, 92]
_PNG: Final = [cv2.IMWRITE_PNG_COMPRESSION, 1]
_LOAD_AHEAD: Final = 4  # keyframes decoded ahead of the one being fused again


@dataclass(frozen=True, slots=True)
class LabelledKeyframe:
    """One segmented keyframe with its depth in the colour camera."""

    keyframe_id: int
    color: npt.NDArray[np.uint8]  # (H, W, 3) RGB
    depth_m: npt.NDArray[np.float32]  # (H, W), registered to colour, 0 = none
    labels: npt.NDArray[np.uint8]  # (H, W) RECORDING.md ids
    confidence: npt.NDArray[np.float32]  # (H, W) in 0..1
    intrinsics: Intrinsics


class KeyframeFusion:
    """Fuse labelled keyframes at their poses; fuse all again when the final poses differ."""

    def __init__(self, cfg: FusionConfig) -> None:
        self.cfg = cfg
        # keyframes arrive subsampled, with their spilled labels' confidence already zeroed
        self._fusion_cfg = replace(cfg, pixel_stride=1, spill_mad_factor=0.0)
        self.fusion = Fusion(self._fusion_cfg)
        self.refused = False  # whether the map was rebuilt at the final poses
        self._fused_at: dict[int, npt.NDArray[np.float64]] = {}
        self._intrinsics: dict[int, Intrinsics] = {}
        # closed by close(), which the pipeline calls after the job or a failure
        self._file = tempfile.TemporaryFile(prefix="semreplay-keyframes-")  # noqa: SIM115
        self._end = 0  # bytes written to the file
        self._where: dict[tuple[int, str], tuple[int, int]] = {}  # (kf, part) -> offset, size

    def add(
        self, keyframe: LabelledKeyframe, *, world_from_camera: npt.NDArray[np.float64]
    ) -> None:
        """Fuse a keyframe at its current pose and keep it for a later rebuild."""
        keyframe = _without_spill(subsample(keyframe, self.cfg.pixel_stride), self.cfg)
        self._integrate(keyframe, world_from_camera)
        self._fused_at[keyframe.keyframe_id] = world_from_camera.copy()
        self._intrinsics[keyframe.keyframe_id] = keyframe.intrinsics
        self._store(keyframe)

    def cloud(self, poses: Mapping[int, npt.NDArray[np.float64]]) -> LabelledCloud:
        """Return the map at the final keyframe poses, rebuilding it if any keyframe moved."""
        if any(
            _moved(at, poses[kf], self.cfg.voxel_size_m / 2) for kf, at in self._fused_at.items()
        ):
            self.fusion = Fusion(self._fusion_cfg)
            for keyframe in self._loaded(sorted(self._fused_at)):
                self._integrate(keyframe, poses[keyframe.keyframe_id])
            self.refused = True
        return self.fusion.cloud()

    def _integrate(self, kf: LabelledKeyframe, world_from_camera: npt.NDArray[np.float64]) -> None:
        self.fusion.integrate(
            kf.color,
            kf.depth_m,
            kf.labels,
            kf.confidence,
            intrinsics=kf.intrinsics,
            world_from_camera=world_from_camera,
        )

    def close(self) -> None:
        """Remove the temporary keyframe file."""
        self._file.close()

    def _store(self, kf: LabelledKeyframe) -> None:
        depth_mm = np.clip(np.nan_to_num(kf.depth_m) * 1000.0 + 0.5, 0, 65535).astype(np.uint16)
        conf = np.clip(np.nan_to_num(kf.confidence) * 255.0 + 0.5, 0, 255).astype(np.uint8)
        label_conf = np.dstack([kf.labels, conf, np.zeros_like(conf)])
        for suffix, image, params in (
            ("color.jpg", cv2.cvtColor(kf.color, cv2.COLOR_RGB2BGR), _JPEG),
            ("depth.png", depth_mm, _PNG),
            ("labels.png", label_conf, _PNG),
        ):
            ok, data = cv2.imencode(Path(suffix).suffix, image, params)
            if not ok:
                raise StageError(f"could not encode keyframe {kf.keyframe_id}'s {suffix}")
            try:
                written = os.pwrite(self._file.fileno(), data.tobytes(), self._end)
            except OSError as err:
                written, reason = 0, err.strerror
            else:
                reason = "a short write"
            if written != data.nbytes:
                raise StageError(
                    f"could not keep keyframe {kf.keyframe_id} for the map's rebuild in"
                    f" {tempfile.gettempdir()} ({reason}); free space there or set TMPDIR"
                )
            self._where[kf.keyframe_id, suffix] = (self._end, written)
            self._end += written

    def _loaded(self, ids: list[int]) -> Iterator[LabelledKeyframe]:
        """Yield the stored keyframes in order, decoding the next ones on another thread."""
        with ThreadPoolExecutor(1, thread_name_prefix="semreplay-keyframe-load") as pool:
            ahead: deque[Future[LabelledKeyframe]] = deque()
            for kf in ids:
                ahead.append(pool.submit(self._load, kf))
                if len(ahead) > _LOAD_AHEAD:
                    yield ahead.popleft().result()
            while ahead:
                yield ahead.popleft().result()

    def _load(self, kf: int) -> LabelledKeyframe:
        def read(suffix: str, flags: int) -> npt.NDArray[np.generic]:
            offset, size = self._where[kf, suffix]
            data = np.frombuffer(os.pread(self._file.fileno(), size, offset), np.uint8)
            return np.asarray(cv2.imdecode(data, flags))

        bgr = read("color.jpg", cv2.IMREAD_COLOR)
        depth_mm = read("depth.png", cv2.IMREAD_UNCHANGED)
        label_conf = read("labels.png", cv2.IMREAD_UNCHANGED)
        return LabelledKeyframe(
            kf,
            np.ascontiguousarray(bgr[..., ::-1]).astype(np.uint8),
            depth_mm.astype(np.float32) / np.float32(1000.0),
            np.ascontiguousarray(label_conf[..., 0]).astype(np.uint8),
            label_conf[..., 1].astype(np.float32) / np.float32(255.0),
            self._intrinsics[kf],
        )


def subsample(kf: LabelledKeyframe, stride: int) -> LabelledKeyframe:
    """Return the keyframe at every `stride`-th pixel (pixel (u, v) is (stride u, stride v))."""
    if stride == 1:
        return kf
    k = kf.intrinsics
    if (k.height, k.width) != kf.depth_m.shape[:2]:
        raise StageError(
            f"fusion expects keyframes of {k.width}x{k.height} (the colour camera), got "
            f"{kf.depth_m.shape[1]}x{kf.depth_m.shape[0]}; register depth to colour first"
        )
    cut = (slice(None, None, stride), slice(None, None, stride))
    depth = np.ascontiguousarray(kf.depth_m[cut])
    intrinsics = replace(
        k,
        width=depth.shape[1],
        height=depth.shape[0],
        fx=k.fx / stride,
        fy=k.fy / stride,
        cx=k.cx / stride,
        cy=k.cy / stride,
    )
    return LabelledKeyframe(
        kf.keyframe_id,
        np.ascontiguousarray(kf.color[cut]),
        depth,
        np.ascontiguousarray(kf.labels[cut]),
        np.ascontiguousarray(kf.confidence[cut]),
        intrinsics,
    )


def _without_spill(kf: LabelledKeyframe, cfg: FusionConfig) -> LabelledKeyframe:
    """Return the keyframe with no confidence where its labels spilled (`bleed.py`).

    Fusion would zero those votes itself; doing it once here keeps a rebuild from finding the
    spill of every keyframe again (an eighth of its time on TUM fr1_rpy).
    """
    if cfg.spill_mad_factor <= 0:
        return kf
    spilled = spilled_labels(
        kf.labels, kf.depth_m, mad_factor=cfg.spill_mad_factor, min_margin_m=cfg.spill_min_margin_m
    )
    if not spilled.any():
        return kf
    return replace(kf, confidence=np.where(spilled, np.float32(0.0), kf.confidence))


def _moved(a: npt.NDArray[np.float64], b: npt.NDArray[np.float64], tolerance_m: float) -> bool:
    """Return whether two poses differ by more than tolerance_m or a quarter of a degree."""
    if float(np.linalg.norm(a[:3, 3] - b[:3, 3])) > tolerance_m:
        return True
    cos = (float(np.trace(a[:3, :3].T @ b[:3, :3])) - 1.0) / 2.0
    return float(np.arccos(np.clip(cos, -1.0, 1.0))) > _MOVED_ROTATION_RAD
