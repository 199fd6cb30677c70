"""Training frames out of recordings with `/ground_truth/labels`, and their augmentation."""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt
import torch

from capture.recording import NUM_LABELS, RecordingError, RecordingReader
from process.errors import StageError

logger = logging.getLogger(__name__)

IGNORE: int = 255  # label value excluded from training and evaluation


@dataclass(frozen=True)
class LabelledImages:
    """Colour images and their label images, all of one size."""

    colors: npt.NDArray[np.uint8]  # (N, H, W, 3) RGB
    labels: npt.NDArray[np.uint8]  # (N, H, W) RECORDING.md ids, IGNORE = not evaluated
    # Per recording: which frames were read (provenance; evaluation frames must lie outside)
    sources: tuple[FrameSpan, ...] = ()

    def __len__(self) -> int:
        return len(self.colors)


@dataclass(frozen=True)
class FrameSpan:
    """The frames one recording gave: file name, first and last stamp, count, how labelled."""

    recording: str
    first_stamp_ns: int
    last_stamp_ns: int
    frames: int
    taught: bool  # labelled by a teacher network, not by ground truth


def load_labelled(
    recordings: Sequence[Path],
    *,
    short_side_px: int,
    every_nth: int = 1,
    teacher: Callable[[npt.NDArray[np.uint8]], npt.NDArray[np.uint8]] | None = None,
    teacher_every_nth: int = 1,
) -> LabelledImages:
    """Read every `every_nth` frame with ground-truth labels, resized to the given short side.

    With a `teacher` (colour -> labels), recordings without ground-truth labels give every
    `teacher_every_nth` frame labelled by it (distillation).
    """
    colors: list[npt.NDArray[np.uint8]] = []
    labels: list[npt.NDArray[np.uint8]] = []
    sources: list[FrameSpan] = []
    for path in recordings:
        stamps: list[int] = []
        with RecordingReader(Path(path)) as rec:
            taught = teacher is not None and not rec.has_ground_truth_labels
            if not rec.has_ground_truth_labels and not taught:
                raise StageError(
                    "training needs /ground_truth/labels (or --teacher); this recording has "
                    f"topics {sorted(rec.topics)}: {path}"
                )
            step = teacher_every_nth if taught else every_nth
            for frame in rec.frames():
                gt = frame.ground_truth
                if frame.index % step:
                    continue
                if teacher is not None and taught:
                    truth = teacher(frame.color)
                elif gt is None or gt.labels is None:
                    continue
                else:
                    truth = gt.labels
                color, label = _resize_pair(frame.color, truth, short_side_px)
                colors.append(color)
                labels.append(label)
                stamps.append(frame.stamp_ns)
            if stamps:
                span = FrameSpan(Path(path).name, min(stamps), max(stamps), len(stamps), taught)
                sources.append(span)
    if not colors:
        raise RecordingError(f"no frame with ground-truth labels in {[str(p) for p in recordings]}")
    sizes = {c.shape for c in colors}
    if len(sizes) > 1:
        raise StageError(
            f"training recordings must share one image size after resizing, found {sorted(sizes)}"
        )
    logger.info("loaded %d labelled frames from %d recordings", len(colors), len(recordings))
    return LabelledImages(np.stack(colors), np.stack(labels), tuple(sources))


def _resize_pair(
    color: npt.NDArray[np.uint8], label: npt.NDArray[np.uint8], short_side_px: int
) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.uint8]]:
    h, w = label.shape
    scale = short_side_px / min(h, w)
    size = (round(w * scale), round(h * scale))
    label = np.where(label < NUM_LABELS, label, IGNORE).astype(np.uint8)
    if size == (w, h):
        return color, label
    return (
        _u8(cv2.resize(color, size, interpolation=cv2.INTER_AREA)),
        _u8(cv2.resize(label, size, interpolation=cv2.INTER_NEAREST)),
    )


def _u8(image: npt.NDArray[np.generic]) -> npt.NDArray[np.uint8]:
    return np.asarray(image, dtype=np.uint8)


def class_weights(labels: npt.NDArray[np.uint8], *, power: float = 0.5) -> torch.Tensor:
    """Return median-frequency class weights (Eigen & Fergus 2015) softened by `power`."""
    counts = np.bincount(labels[labels != IGNORE].ravel(), minlength=NUM_LABELS).astype(np.float64)
    freq = counts / max(counts.sum(), 1.0)
    present = freq > 0
    weights = np.ones(NUM_LABELS)
    weights[present] = (np.median(freq[present]) / freq[present]) ** power
    return torch.tensor(np.clip(weights, 0.1, 10.0), dtype=torch.float32)


def augment_pair(
    color: npt.NDArray[np.uint8],
    label: npt.NDArray[np.uint8],
    *,
    crop_hw: tuple[int, int],
    scale_range: tuple[float, float],
    rng: np.random.Generator,
) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.uint8]]:
    """Randomly rescale, crop (padding with IGNORE) and flip an image and its labels."""
    s = float(rng.uniform(*scale_range))
    h, w = label.shape
    size = (max(1, round(w * s)), max(1, round(h * s)))
    color = _u8(cv2.resize(color, size, interpolation=cv2.INTER_LINEAR))
    label = _u8(cv2.resize(label, size, interpolation=cv2.INTER_NEAREST))
    ch, cw = crop_hw
    pad_h, pad_w = max(0, ch - size[1]), max(0, cw - size[0])
    if pad_h or pad_w:
        border = cv2.BORDER_CONSTANT
        color = _u8(cv2.copyMakeBorder(color, 0, pad_h, 0, pad_w, border, value=(0, 0, 0)))
        label = _u8(cv2.copyMakeBorder(label, 0, pad_h, 0, pad_w, border, value=IGNORE))
    y = int(rng.integers(0, label.shape[0] - ch + 1))
    x = int(rng.integers(0, label.shape[1] - cw + 1))
    color, label = color[y : y + ch, x : x + cw], label[y : y + ch, x : x + cw]
    if rng.random() < 0.5:
        color, label = color[:, ::-1], label[:, ::-1]
    return np.ascontiguousarray(color), np.ascontiguousarray(label)


def color_jitter(
    images: torch.Tensor, *, strength: float, generator: torch.Generator
) -> torch.Tensor:
    """Jitter brightness, contrast, saturation, white balance of a batch (N, 3, H, W) in [0, 1]."""
    n = images.shape[0]

    def factor(shape: tuple[int, ...]) -> torch.Tensor:
        return 1.0 + strength * (2.0 * torch.rand(shape, generator=generator) - 1.0)

    x = images * factor((n, 1, 1, 1))  # brightness
    mean = x.mean(dim=(1, 2, 3), keepdim=True)
    x = (x - mean) * factor((n, 1, 1, 1)) + mean  # contrast
    gray = x.mean(dim=1, keepdim=True)
    x = (x - gray) * factor((n, 1, 1, 1)) + gray  # saturation
    x = x * factor((n, 3, 1, 1)) ** 0.5  # white balance, half strength
    return x.clamp(0.0, 1.0)
