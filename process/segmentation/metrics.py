"""2-D segmentation metrics: confusion matrix, IoU per label, mean IoU over labels present."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from capture.recording import NUM_LABELS
from process import evaluate

IGNORE: int = 255  # label value excluded from training and evaluation


def confusion_matrix(
    pred: npt.NDArray[np.integer], gt: npt.NDArray[np.integer], *, num_labels: int = NUM_LABELS
) -> npt.NDArray[np.int64]:
    """Return the (num_labels, num_labels) matrix counting [ground truth, prediction] pairs.

    Pixels whose ground truth is IGNORE or outside the label range are not counted.
    """
    return evaluate.confusion_matrix(pred, gt, n_labels=num_labels)


def iou_per_label(confusion: npt.NDArray[np.int64]) -> dict[int, float]:
    """Return TP / (TP + FP + FN) for every label that occurs in the ground truth."""
    tp = np.diag(confusion).astype(np.float64)
    gt_count = confusion.sum(axis=1)
    union = gt_count + confusion.sum(axis=0) - tp
    return {int(k): float(tp[k] / union[k]) for k in np.flatnonzero(gt_count)}


def mean_iou(confusion: npt.NDArray[np.int64]) -> float:
    """Return the mean IoU over the labels present in the ground truth (NaN if none)."""
    ious = iou_per_label(confusion)
    return float(np.mean(list(ious.values()))) if ious else float("nan")
