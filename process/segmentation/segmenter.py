"""The segmentation stage: keyframe colour images in, RECORDING.md labels and confidence out."""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt
import torch
from torch.nn import functional as F  # noqa: N812 (the torch convention)

from capture.recording import STRUCTURAL_LABELS
from process.errors import ModelError, StageError
from process.segmentation.combined import CombinedRuntime
from process.segmentation.config import Segmentation, SegmentationConfig
from process.segmentation.models import (
    ADE20K_TFLITE,
    VOC_TFLITE,
    ModelChoice,
    explicit_choice,
    shipped,
)
from process.segmentation.runtimes import OnnxRuntime, Runtime, TorchRuntime, pick_device
from process.segmentation.tflite_runtime import TfliteRuntime
from process.segmentation.weights import load_checkpoint, resolve_weights

logger = logging.getLogger(__name__)


class Segmenter:
    """Segment colour images with a DeepLab network on the configured runtime.

    Usage: `Segmenter(cfg.segmentation).segment(frame.color) -> Segmentation`.
    """

    def __init__(
        self,
        cfg: SegmentationConfig,
        *,
        weights: Path | None = None,
        device: str = "auto",
        choice: ModelChoice | None = None,
    ) -> None:
        if choice is None:  # without a recording to decide, the simulator checkpoint
            default = shipped("simulator", "the default when no recording decides", cfg)
            choice = explicit_choice(cfg, weights=weights) or default
        self.choice = choice
        self.cfg = cfg = replace(cfg, backend=choice.backend)
        if cfg.threads:
            torch.set_num_threads(cfg.threads)
        self.weights_path = (
            ADE20K_TFLITE if choice.path is None else resolve_weights(str(choice.path))
        )
        self.device = (
            "cpu"
            if cfg.backend != "torch"
            else str(pick_device(device if device != "auto" else cfg.device))
        )
        self.short_side_px = 0  # 0: the runtime fixes or fits the input size
        self.checkpoint_info: dict[str, object] = {}
        self.runtime = self._make_runtime()
        logger.info("segmentation: %s on %s (%s)", choice.name, cfg.backend, self.device)

    def _make_runtime(self) -> Runtime:
        if self.cfg.class_to_label and self.cfg.backend != "tflite":
            raise ModelError(
                "segmentation.class_to_label is for .tflite models; found backend "
                f"{self.cfg.backend!r} (our checkpoints carry their own class map): "
                f"{self.choice.path or self.choice.name}"
            )
        if self.cfg.backend == "combined":
            if self.choice.path is not None:
                raise ModelError(
                    "the combined backend runs the two networks shipped in samples/; leave "
                    f"weights empty, or choose backend tflite for {self.choice.path}"
                )
            return CombinedRuntime(
                ADE20K_TFLITE, VOC_TFLITE, threads=self.cfg.threads, relabel=self._labels
            )
        if self.cfg.backend == "tflite":
            return self._tflite()
        return self._network()

    def warm_up(self, height: int = 480, width: int = 640) -> None:
        """Segment one blank image, so that one-off setup costs are not in the first keyframe."""
        self.segment(np.zeros((height, width, 3), np.uint8))

    def _tflite(self) -> Runtime:
        path = self.weights_path
        if path.suffix != ".tflite":
            raise ModelError(
                f"the tflite backend needs a .tflite model, found {path.suffix!r} (or set "
                f"segmentation.model = 'voc' or 'ade20k'): {path}"
            )
        return TfliteRuntime(
            path,
            threads=self.cfg.threads,
            class_to_label=self.cfg.class_to_label or None,
            relabel=self._labels,
        )

    def _network(self) -> Runtime:
        ckpt = load_checkpoint(self.weights_path)
        ckpt = replace(ckpt, class_to_label=self._labels(ckpt.class_to_label))
        self.short_side_px = self.cfg.short_side_px or ckpt.short_side_px
        self.checkpoint_info = dict(ckpt.info)
        if self.cfg.backend == "onnx":
            return OnnxRuntime(ckpt, threads=self.cfg.threads)
        return TorchRuntime(ckpt, device=self.device, channels_last=self.cfg.channels_last)

    def _labels(self, class_to_label: tuple[int, ...]) -> tuple[int, ...]:
        if not self.cfg.structural_to_background:
            return class_to_label
        return tuple(0 if v in STRUCTURAL_LABELS else v for v in class_to_label)

    def input_size(self, height: int, width: int) -> tuple[int, int]:
        """Return the (width, height) at which an image of this size goes through the network."""
        if self.runtime.fixed_input_size is not None:
            return self.runtime.fixed_input_size
        if not self.short_side_px:  # the runtime fits each image to its networks itself
            return width, height
        scale = self.short_side_px / min(height, width)
        return max(16, round(width * scale)), max(16, round(height * scale))

    def segment(self, color: npt.NDArray[np.uint8]) -> Segmentation:
        """Segment one (H, W, 3) uint8 RGB image."""
        return self.segment_batch([color])[0]

    def segment_batch(self, colors: Sequence[npt.NDArray[np.uint8]]) -> list[Segmentation]:
        """Segment images in batches of `batch_size` (images of equal size share a batch)."""
        for c in colors:
            if c.ndim != 3 or c.shape[2] != 3 or c.dtype != np.uint8:
                raise StageError(
                    f"segmentation expects (H, W, 3) uint8 RGB images, found {c.shape} {c.dtype}"
                )
        out: list[Segmentation] = []
        start = 0
        while start < len(colors):
            shape = colors[start].shape
            stop = start
            while (
                stop < len(colors)
                and stop - start < self.cfg.batch_size
                and colors[stop].shape == shape
            ):
                stop += 1
            out += self._run(colors[start:stop])
            start = stop
        return out

    def _run(self, colors: Sequence[npt.NDArray[np.uint8]]) -> list[Segmentation]:
        h, w = colors[0].shape[:2]
        size = self.input_size(h, w)
        shrink = size[0] * size[1] < w * h
        interp = cv2.INTER_AREA if shrink else cv2.INTER_LINEAR
        batch = np.stack(
            [c if (w, h) == size else cv2.resize(c, size, interpolation=interp) for c in colors]
        ).astype(np.uint8, copy=False)
        probs = self.runtime(batch)
        if probs.shape[2:] != (h, w):
            probs = F.interpolate(
                probs.float(),
                size=(h, w),
                mode="bilinear",
                align_corners=self.runtime.align_corners,
            )
        confidence, labels = probs.max(dim=1)
        labels_np = labels.to(torch.uint8).cpu().numpy()
        conf_np = confidence.clamp_(0.0, 1.0).float().cpu().numpy()
        return [
            Segmentation(labels=labels_np[i], confidence=conf_np[i]) for i in range(len(colors))
        ]
