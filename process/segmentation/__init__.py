"""2-D semantic segmentation: DeepLabV3+ on MobileNetV3, its weights, runtimes and training.

Importing this package is cheap: torch is imported only when `Segmenter`, `train` or the model
modules are first used, so `semreplay-process --help` stays fast.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from process.segmentation.config import BACKENDS, DEVICES, Segmentation, SegmentationConfig

if TYPE_CHECKING:
    from process.segmentation.segmenter import Segmenter
    from process.segmentation.train import TrainConfig, TrainResult, train

__all__ = [
    "BACKENDS",
    "DEVICES",
    "Segmentation",
    "SegmentationConfig",
    "Segmenter",
    "TrainConfig",
    "TrainResult",
    "train",
]

_LAZY = {
    "Segmenter": "process.segmentation.segmenter",
    "train": "process.segmentation.train",
    "TrainConfig": "process.segmentation.train",
    "TrainResult": "process.segmentation.train",
}


def __getattr__(name: str) -> Any:
    """Import the torch-backed names on first use."""
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
