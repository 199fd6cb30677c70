"""2-D segmentation metrics: the confusion matrix and mIoU of `process.evaluate`, re-exported.

One mIoU definition is used everywhere (`process.evaluate.confusion_iou`): IoU per class present
in the prediction or the truth, mean over those classes, by default the labels 1-10.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from capture.recording import NUM_LABELS
from process import evaluate

IGNORE: int = 255  # label value excluded from training and evaluation
iou_per_label = evaluate.confusion_iou
mean_iou = evaluate.confusion_miou


def confusion_matrix(
    pred: npt.NDArray[np.integer], gt: npt.NDArray[np.integer], *, num_labels: int = NUM_LABELS
) -> npt.NDArray[np.int64]:
    """Return the (num_labels, num_labels) matrix counting [ground truth, prediction] pairs.

    Pixels whose ground truth is IGNORE or outside the label range are not counted.
    """
    return evaluate.confusion_matrix(pred, gt, n_labels=num_labels)
