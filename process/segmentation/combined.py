"""The two real-image teachers combined per pixel: the `combined` segmentation backend.

ADE20K's DeepLab knows the room's shell (ceiling, floor, wall) and much furniture; PASCAL VOC's
knows chairs, tables, monitors, people, plants and sofas cleanly but nothing else. Per pixel,
with each network's label probabilities (its class softmax summed into RECORDING.md labels):

- ADE20K's person, plant and sofa (which VOC knows well and ADE20K sees in paper, cables and
  shadows of real desks) count only where VOC gives the same label probability >= `support`;
  elsewhere they are removed from ADE20K's distribution (which is renormalised);
- a network *claims an object* where its top label is an object (4-10) with probability
  >= `min_confidence`;
- where both claim one, the more probable wins; where one does, it wins;
- everywhere else ADE20K's labelling stands (structure, background, or its unsure object).

The chosen network's whole probability vector is kept, so the Segmenter's argmax is that
network's label and its confidence that network's probability.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Final

import numpy as np
import numpy.typing as npt
import torch
from torch.nn import functional as F  # noqa: N812 (the torch convention)

from capture.recording import OBJECT_LABELS
from process.errors import ModelError
from process.segmentation.tflite_runtime import TfliteRuntime

MIN_CONFIDENCE: Final = 0.5
SUPPORT: Final = 0.1
NEED_SUPPORT: Final = (6, 7, 8)  # person, plant, sofa
_FIRST_OBJECT: Final = min(OBJECT_LABELS)


def combine(
    ade: torch.Tensor,
    voc: torch.Tensor,
    *,
    min_confidence: float = MIN_CONFIDENCE,
    support: float = SUPPORT,
) -> torch.Tensor:
    """Return the per-pixel combination of two (N, L, h, w) label-probability maps.

    `voc` is resized to `ade`'s size first if they differ.
    """
    if voc.shape[2:] != ade.shape[2:]:
        voc = F.interpolate(voc, size=ade.shape[2:], mode="bilinear", align_corners=True)
    ade = ade.clone()
    for label in NEED_SUPPORT:
        ade[:, label] *= voc[:, label] >= support
    ade /= ade.sum(dim=1, keepdim=True).clamp_min(1e-12)
    conf_a, label_a = ade.max(dim=1)
    conf_v, label_v = voc.max(dim=1)
    claims_a = (label_a >= _FIRST_OBJECT) & (conf_a >= min_confidence)
    claims_v = (label_v >= _FIRST_OBJECT) & (conf_v >= min_confidence)
    use_voc = claims_v & (~claims_a | (conf_v > conf_a))
    return torch.where(use_voc[:, None], voc, ade)


class CombinedRuntime:
    """Run the ADE20K and the VOC .tflite networks and combine their labels per pixel."""

    align_corners = True  # both are TfliteRuntimes

    def __init__(
        self,
        ade20k: Path,
        voc: Path,
        *,
        threads: int = 0,
        relabel: Callable[[tuple[int, ...]], tuple[int, ...]] | None = None,
        min_confidence: float = MIN_CONFIDENCE,
    ) -> None:
        self.ade20k = TfliteRuntime(ade20k, threads=threads, relabel=relabel)
        self.voc = TfliteRuntime(voc, threads=threads, relabel=relabel)
        self.fixed_input_size = self.ade20k.fixed_input_size
        if self.voc.fixed_input_size != self.fixed_input_size:
            raise ModelError(
                f"the two networks take different inputs ({self.fixed_input_size} and "
                f"{self.voc.fixed_input_size}); pass two 513x513 DeepLab models"
            )
        self.min_confidence = min_confidence

    def __call__(self, batch: npt.NDArray[np.uint8]) -> torch.Tensor:
        """Return combined label probabilities (N, L, h, w)."""
        return combine(self.ade20k(batch), self.voc(batch), min_confidence=self.min_confidence)
