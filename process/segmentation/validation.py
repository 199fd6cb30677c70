"""Validation helpers of training: input normalisation, BatchNorm recalibration, evaluation."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import torch
from torch import nn

from process.evaluate import confusion_matrix
from process.segmentation.dataset import LabelledImages
from process.segmentation.deeplab import DeepLab
from process.segmentation.weights import IMAGENET_MEAN, IMAGENET_STD


def normalise(images: torch.Tensor) -> torch.Tensor:
    """Normalise a float batch in [0, 1] with the ImageNet mean and std our checkpoints store."""
    mean = torch.tensor(IMAGENET_MEAN).view(1, 3, 1, 1)
    std = torch.tensor(IMAGENET_STD).view(1, 3, 1, 1)
    return (images - mean) / std


def to_batch(colors: npt.NDArray[np.uint8], *, channels_last: bool = False) -> torch.Tensor:
    """Return normalised float images (N, 3, H, W) of uint8 RGB images (N, H, W, 3)."""
    x = normalise(torch.from_numpy(colors).permute(0, 3, 1, 2).float() / 255.0)
    return x.contiguous(
        memory_format=torch.channels_last if channels_last else torch.contiguous_format
    )


def set_bn_momentum(model: nn.Module, momentum: float | None) -> None:
    """Set the momentum of every BatchNorm (None: a cumulative average)."""
    for m in model.modules():
        if isinstance(m, nn.BatchNorm2d):
            m.momentum = momentum


def recalibrate_batchnorm(
    model: DeepLab,
    data: LabelledImages,
    *,
    batches: int,
    batch_size: int,
    rng: np.random.Generator,
    channels_last: bool = False,
) -> None:
    """Replace BatchNorm running statistics by their average over unaugmented training frames.

    Running averages lag behind weights that change quickly (early epochs, high learning
    rate); the evaluated network then sees stale statistics. The weights are not changed;
    the momentum is left at None (cumulative) for the caller to restore.
    """
    if batches < 1:
        return
    set_bn_momentum(model, None)
    for m in model.modules():
        if isinstance(m, nn.BatchNorm2d):
            m.reset_running_stats()
    model.train()
    with torch.no_grad():
        for _ in range(batches):
            idx = np.sort(rng.choice(len(data), size=min(batch_size, len(data)), replace=False))
            model(to_batch(data.colors[idx], channels_last=channels_last))


def evaluate(model: DeepLab, data: LabelledImages, *, batch_size: int = 8) -> npt.NDArray[np.int64]:
    """Return the confusion matrix of the model's argmax on full (unaugmented) images."""
    model.eval()
    n = model.arch.num_classes
    conf = np.zeros((n, n), np.int64)
    with torch.inference_mode():
        for start in range(0, len(data), batch_size):
            pred = model(to_batch(data.colors[start : start + batch_size])).argmax(dim=1).numpy()
            conf += confusion_matrix(pred, data.labels[start : start + batch_size], n_labels=n)
    return conf
