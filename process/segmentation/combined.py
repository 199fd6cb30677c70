"""The two real-image teachers combined per pixel: the `combined` segmentation backend.

ADE20K's DeepLab knows the room's shell (ceiling, floor, wall) and much furniture; PASCAL VOC's
knows chairs, tables, monitors, people, plants and sofas cleanly but nothing else. Each network
sees the image as it works best on real rooms (measured on hand-boxed TUM fr1_rpy desks and
monitors, tests/process/segmentation/test_seg_combined.py): ADE20K letterboxed, aspect kept and
padded grey, as DeepLab's own evaluation feeds it (hand-boxed desk surfaces: 47 % table, 23 %
stretched; a smaller image, 3/4 of the input, labels near desks better still but far walls worse,
and the TUM map's table and monitor points fell from 11 % to 8 %);
VOC stretched to its square input (monitors: 43 % tv monitor, 12 % letterboxed).
Per pixel, with each network's label probabilities (its class softmax summed into RECORDING.md
labels):

- ADE20K's person, plant and sofa (which VOC knows well and ADE20K sees in paper, cables and
  shadows of real desks) count only where VOC gives the same label probability >= `support`;
  elsewhere they are removed from ADE20K's distribution (which is renormalised);
- where VOC claims an object (its top label is one, 4-10, with probability >= `min_confidence`)
  VOC's labelling wins: it is the specialist of its classes, and ADE20K's objects on real desks
  are often wrong (dark monitors as chair, cabinet, oven or dishwasher);
- where ADE20K's top label is clutter (an object of a class we have no label for) and VOC gives
  one of its own objects (4-9) a probability >= `hint`, ADE20K's clutter probability moves to
  that object: ADE20K found the object, VOC names it;
- everywhere else ADE20K's labelling stands (structure, background, or its own object).

The chosen network's whole probability vector is kept, so the Segmenter's argmax is that
network's label and its confidence that network's probability.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Final

import cv2
import numpy as np
import numpy.typing as npt
import torch
from torch.nn import functional as F  # noqa: N812 (the torch convention)

from capture.recording import OBJECT_LABELS
from process.errors import ModelError
from process.segmentation.tflite_runtime import OUTPUT_STRIDE, TfliteRuntime

MIN_CONFIDENCE: Final = 0.5
SUPPORT: Final = 0.1
HINT: Final = 0.3
NEED_SUPPORT: Final = (6, 7, 8)  # person, plant, sofa
CLUTTER: Final = 10
_FIRST_OBJECT: Final = min(OBJECT_LABELS)
_PAD: Final = 128  # mid grey: 0 after DeepLab's x / 127.5 - 1, as its own padding


def combine(
    ade: torch.Tensor,
    voc: torch.Tensor,
    *,
    min_confidence: float = MIN_CONFIDENCE,
    support: float = SUPPORT,
    hint: float = HINT,
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
    conf_v, label_v = voc.max(dim=1)
    use_voc = (label_v >= _FIRST_OBJECT) & (conf_v >= min_confidence)
    out = torch.where(use_voc[:, None], voc, ade)
    clutter = (ade.argmax(dim=1) == CLUTTER) & ~use_voc
    return _name_the_clutter(out, ade, voc, clutter, hint)


def _name_the_clutter(
    out: torch.Tensor, ade: torch.Tensor, voc: torch.Tensor, clutter: torch.Tensor, hint: float
) -> torch.Tensor:
    """Give ADE20K's clutter probability to VOC's object where VOC's is >= `hint`.

    ADE20K found an object it has no label of ours for; VOC names it.
    """
    p_obj, obj = voc[:, _FIRST_OBJECT:CLUTTER].max(dim=1)
    take = clutter & (p_obj >= hint)
    if not bool(take.any()):
        return out
    named = ade.clone()
    index = (obj + _FIRST_OBJECT)[:, None]
    named.scatter_add_(1, index, ade[:, CLUTTER : CLUTTER + 1])
    named[:, CLUTTER] = 0.0
    return torch.where(take[:, None], named, out)


def letterbox_size(width: int, height: int, side: int, fill: float = 1.0) -> tuple[int, int]:
    """Return the (width, height) an image takes inside a side x side letterbox.

    The long side spans `fill` of the box; both sides are rounded to 1 + a multiple of the
    output stride, so that the label grid's last valid row and column are the image's last.
    """
    long_px = 1 + OUTPUT_STRIDE * round((side - 1) * fill / OUTPUT_STRIDE)
    short_px = 1 + OUTPUT_STRIDE * round(
        (long_px - 1) * min(width, height) / max(width, height) / OUTPUT_STRIDE
    )
    return (long_px, short_px) if width >= height else (short_px, long_px)


def letterbox(image: npt.NDArray[np.uint8], side: int, fill: float = 1.0) -> npt.NDArray[np.uint8]:
    """Return the image resized into a side x side square (`letterbox_size`), padded grey."""
    width, height = letterbox_size(image.shape[1], image.shape[0], side, fill)
    out = np.full((side, side, 3), _PAD, np.uint8)
    shrink = width * height < image.shape[0] * image.shape[1]
    interp = cv2.INTER_AREA if shrink else cv2.INTER_LINEAR
    out[:height, :width] = cv2.resize(image, (width, height), interpolation=interp)
    return out


def unletterbox(
    probs: torch.Tensor, width: int, height: int, side: int, fill: float = 1.0
) -> torch.Tensor:
    """Return the image's part of label probabilities computed on a letterboxed image.

    `probs` is (N, L, g, g) on the corner-aligned stride grid of the side x side input; the
    result is resampled to that same g x g grid over the image alone.
    """
    fit_w, fit_h = letterbox_size(width, height, side, fill)
    rows, cols = (fit_h - 1) // OUTPUT_STRIDE + 1, (fit_w - 1) // OUTPUT_STRIDE + 1
    grid = probs.shape[2:]
    return F.interpolate(probs[:, :, :rows, :cols], size=grid, mode="bilinear", align_corners=True)


class CombinedRuntime:
    """Run the ADE20K and the VOC .tflite networks and combine their labels per pixel.

    It takes images at their own size (`fixed_input_size` None) and fits each to its network.
    """

    align_corners = True  # the label grid's corners are the image's corners
    fixed_input_size: tuple[int, int] | None = None

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
        size = self.ade20k.fixed_input_size
        if size is None or size[0] != size[1] or self.voc.fixed_input_size != size:
            raise ModelError(
                f"the two networks take different or non-square inputs ({size} and "
                f"{self.voc.fixed_input_size}); pass two 513x513 DeepLab models"
            )
        self.side = size[0]
        self.min_confidence = min_confidence

    def __call__(self, batch: npt.NDArray[np.uint8]) -> torch.Tensor:
        """Return combined label probabilities (N, L, g, g) for images (N, H, W, 3)."""
        height, width = batch.shape[1:3]
        square = (self.side, self.side)
        interp = cv2.INTER_AREA if width * height > self.side**2 else cv2.INTER_LINEAR
        stretched = np.stack([cv2.resize(im, square, interpolation=interp) for im in batch])
        boxed = np.stack([letterbox(im, self.side) for im in batch])
        ade = unletterbox(self.ade20k(boxed), width, height, self.side)
        return combine(ade, self.voc(stretched), min_confidence=self.min_confidence)
