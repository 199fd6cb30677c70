"""Labels from a teacher network for recordings without ground truth (distillation).

`semreplay-process train real.mcap sim_*.mcap --teacher combined`: frames of recordings that
carry `/ground_truth/labels` (simulated rooms) train on them; frames of the others (real
recordings) train on the teacher's labels, its unsure pixels (probability < `min_confidence`)
left out of the loss. Agreement with the teacher on held-out real frames is what such a
student can be judged by: agreement, not accuracy.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Final

import numpy as np
import numpy.typing as npt

from process.errors import ConfigError
from process.segmentation.config import SegmentationConfig
from process.segmentation.dataset import IGNORE
from process.segmentation.models import SHIPPED, shipped

TEACHERS: Final = tuple(name for name in SHIPPED if name != "simulator")
MIN_CONFIDENCE: Final = 0.5

Teacher = Callable[[npt.NDArray[np.uint8]], npt.NDArray[np.uint8]]


def make_teacher(name: str, *, threads: int = 0, min_confidence: float = MIN_CONFIDENCE) -> Teacher:
    """Return a function colour image -> teacher labels (IGNORE where the teacher is unsure)."""
    if name not in TEACHERS:
        raise ConfigError(f"--teacher must be one of {list(TEACHERS)}, got {name!r}")
    from process.segmentation.segmenter import Segmenter

    cfg = SegmentationConfig(threads=threads)
    seg = Segmenter(cfg, choice=shipped(name, "distillation teacher", cfg), device="cpu")

    def labels(color: npt.NDArray[np.uint8]) -> npt.NDArray[np.uint8]:
        out = seg.segment(color)
        return np.where(out.confidence >= min_confidence, out.labels, IGNORE).astype(np.uint8)

    return labels
