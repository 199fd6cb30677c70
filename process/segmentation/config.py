"""Configuration and result types of the segmentation stage (no torch import here)."""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Final

import numpy as np
import numpy.typing as npt

from capture.recording import NUM_LABELS
from process.errors import ConfigError

BACKENDS: Final = ("torch", "onnx", "tflite", "combined")
MODELS: Final = ("auto", "simulator", "voc", "ade20k", "combined")
DEVICES: Final = ("auto", "cpu", "cuda")


@dataclass(frozen=True)
class SegmentationConfig:
    """The `[segmentation]` section: which weights, which runtime, at what resolution."""

    # auto = by the recording's device: simulated -> "simulator", real -> "combined" (models.py)
    model: str = "auto"  # or simulator | voc | ade20k | combined (the models shipped in samples/)
    weights: str = ""  # a path or "torchvision:NAME": wins over `model`; "" = `model` decides
    # torch | onnx (onnxruntime) | tflite (ai-edge-litert, .tflite weights) | combined (the
    # shipped ADE20K and VOC .tflite networks per pixel)
    backend: str = "torch"
    # A .tflite model's output class -> RECORDING.md label (0-10), one per class, for models
    # of any class count; () = by the class count: 21 PASCAL VOC, 151 ADE20K (tflite_runtime).
    class_to_label: tuple[int, ...] = ()
    device: str = "auto"  # auto = CUDA when present (torch backend)
    threads: int = 0  # CPU threads for the runtime; 0 = the runtime's default
    batch_size: int = 4  # keyframes per forward pass
    short_side_px: int = 0  # network input short side; 0 = what the checkpoint was trained at
    channels_last: bool = True  # NHWC memory format for the torch backend (faster on CPU)
    structural_to_background: bool = False  # report ceiling/floor/wall (1-3) as 0
    # A keyframe is segmented when at least this share of its depth lies in 8 cm cells that no
    # segmented keyframe has seen; the others add only geometry to the map (0: every keyframe).
    min_new_share: float = 0.1

    def __post_init__(self) -> None:
        if self.backend not in BACKENDS:
            raise ConfigError(
                f"segmentation.backend must be one of {list(BACKENDS)}, got {self.backend!r}"
            )
        if self.model not in MODELS:
            raise ConfigError(
                f"segmentation.model must be one of {list(MODELS)}, got {self.model!r}"
            )
        if any(
            isinstance(v, bool) or not isinstance(v, int) or not 0 <= v < NUM_LABELS
            for v in self.class_to_label
        ):
            raise ConfigError(
                "segmentation.class_to_label must list one label 0-10 per model class, got "
                f"{list(self.class_to_label)[:12]}"
            )
        if self.device not in DEVICES:
            raise ConfigError(
                f"segmentation.device must be one of {list(DEVICES)}, got {self.device!r}"
            )
        if not 0 <= self.threads <= 256:
            raise ConfigError(f"segmentation.threads must be in [0, 256], got {self.threads}")
        if not 1 <= self.batch_size <= 64:
            raise ConfigError(f"segmentation.batch_size must be in [1, 64], got {self.batch_size}")
        if not 0.0 <= self.min_new_share <= 1.0:
            raise ConfigError(
                f"segmentation.min_new_share must be in [0, 1], got {self.min_new_share}"
            )
        if self.short_side_px != 0 and not 32 <= self.short_side_px <= 2048:
            raise ConfigError(
                "segmentation.short_side_px must be 0 (checkpoint's) or in [32, 2048], "
                f"got {self.short_side_px}"
            )


@dataclass(frozen=True)
class Segmentation:
    """The segmentation of one colour image."""

    labels: npt.NDArray[np.uint8]  # (H, W) RECORDING.md label ids
    confidence: npt.NDArray[np.float32]  # (H, W) probability of the chosen label, in [0, 1]


def beside_odometry_threads() -> int:
    """Return the threads `process run` gives segmentation by default: all cores but one."""
    return max(1, (os.cpu_count() or 2) - 1)
