"""Label metrics: per-point IoU / precision / recall / F1 (the paper's Tables 2-12) and 2-D mIoU.

The paper's "accuracy" is the intersection over union TP / (TP + FP + FN) (PAPER.md), so we
call it IoU. "all" pools the counts of the target classes (micro average): TP, FP and FN summed
over the classes, then the same ratios. A ratio whose denominator is 0 is reported as 0.0, and a
class that neither the prediction nor the truth contains is left out.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Final

import numpy as np
import numpy.typing as npt
from rich.table import Table
from scipy.spatial import cKDTree

from capture.recording import LABEL_NAMES, NUM_LABELS, OBJECT_LABELS
from process.cloud import LabelledCloud
from process.errors import StageError

Metrics = dict[str, float]  # iou, precision, recall, f1
PHASES = ("I", "II", "III")  # fused, after DBSCAN, after regrowth


def ratios(tp: int, fp: int, fn: int) -> Metrics:
    """Return IoU, precision, recall and F1 of the counts (0.0 where undefined)."""

    def div(a: int, b: int) -> float:
        return a / b if b else 0.0

    return {
        "iou": div(tp, tp + fp + fn),
        "precision": div(tp, tp + fp),
        "recall": div(tp, tp + fn),
        "f1": div(2 * tp, 2 * tp + fp + fn),
    }


def confusion_matrix(
    pred: npt.NDArray[np.integer], gt: npt.NDArray[np.integer], *, n_labels: int = NUM_LABELS
) -> npt.NDArray[np.int64]:
    """Return counts[gt, pred]; elements whose truth is outside 0..n_labels-1 are ignored."""
    if pred.shape != gt.shape:
        raise StageError(
            f"metrics need prediction and truth of one shape, got {pred.shape} and {gt.shape}"
        )
    gt64, pred64 = gt.astype(np.int64).ravel(), pred.astype(np.int64).ravel()
    valid = (gt64 >= 0) & (gt64 < n_labels) & (pred64 >= 0) & (pred64 < n_labels)
    flat = gt64[valid] * n_labels + pred64[valid]
    return np.bincount(flat, minlength=n_labels * n_labels).reshape(n_labels, n_labels)


def class_counts(cm: npt.NDArray[np.int64], label: int) -> tuple[int, int, int]:
    """Return (TP, FP, FN) of one label from a confusion matrix."""
    tp = int(cm[label, label])
    return tp, int(cm[:, label].sum()) - tp, int(cm[label, :].sum()) - tp


def metrics_from_confusion(
    cm: npt.NDArray[np.int64], *, classes: Sequence[int]
) -> dict[str, Metrics]:
    """Return {label name: metrics} for each present class and "all" pooled over them."""
    out: dict[str, Metrics] = {}
    total = np.zeros(3, np.int64)
    for label in classes:
        counts = class_counts(cm, label)
        if sum(counts) == 0:
            continue
        out[LABEL_NAMES[label]] = ratios(*counts)
        total += counts
    out["all"] = ratios(*(int(v) for v in total))
    return out


def label_metrics(
    pred_labels: npt.NDArray[np.integer],
    gt_labels: npt.NDArray[np.integer],
    *,
    classes: Sequence[int] = OBJECT_LABELS,
) -> dict[str, Metrics]:
    """Return per-class and pooled ("all") IoU, precision, recall and F1 of per-point labels."""
    return metrics_from_confusion(confusion_matrix(pred_labels, gt_labels), classes=classes)


MIOU_CLASSES: Final = tuple(range(1, NUM_LABELS))  # 0 (unlabelled) is not a class


def confusion_iou(
    cm: npt.NDArray[np.int64], *, classes: Sequence[int] = MIOU_CLASSES
) -> dict[int, float]:
    """Return the IoU of each class present in the prediction or the truth of a confusion matrix.

    The one mIoU definition of the project (pipeline metrics, training validation, benchmarks):
    IoU = TP / (TP + FP + FN) per class that occurs in the truth or the prediction, mean over
    those classes (`confusion_miou`); by default the labels 1-10.
    """
    out: dict[int, float] = {}
    for label in classes:
        if not 0 <= label < len(cm):
            continue
        counts = class_counts(cm, label)
        if sum(counts):
            out[label] = ratios(*counts)["iou"]
    return out


def confusion_miou(cm: npt.NDArray[np.int64], *, classes: Sequence[int] = MIOU_CLASSES) -> float:
    """Return the mean of `confusion_iou` (nan if no class is present)."""
    per_class = confusion_iou(cm, classes=classes)
    return float(np.mean(list(per_class.values()))) if per_class else float("nan")


def image_iou(
    pred: npt.NDArray[np.integer], gt: npt.NDArray[np.integer], *, classes: Sequence[int]
) -> dict[int, float]:
    """Return the IoU of each class present in the prediction or the truth (any shape).

    Truth values outside the label range (e.g. 255, VOC's boundary) are ignored. Pass stacked
    images to get the IoU over a whole set.
    """
    return confusion_iou(confusion_matrix(pred, gt), classes=classes)


def image_miou(
    pred: npt.NDArray[np.integer], gt: npt.NDArray[np.integer], *, classes: Sequence[int]
) -> float:
    """Return the mean IoU over the classes present in prediction or truth (nan if none is)."""
    return confusion_miou(confusion_matrix(pred, gt), classes=classes)


def match_labels(
    points: npt.NDArray[np.float32], gt_cloud: LabelledCloud, *, max_distance_m: float
) -> npt.NDArray[np.uint8]:
    """Return the truth of each point: the label of its nearest truth point, 0 if none is near.

    A predicted point with no truth point within `max_distance_m` lies where the truth has no
    surface (a flying pixel, noise), so its truth is background (0): an object label there
    counts as a false positive. Truth points that no predicted point is near are not counted:
    the metrics judge the labels of the map that was built, not its coverage.
    """
    if len(gt_cloud) == 0:
        return np.zeros(len(points), np.uint8)
    distance, nearest = cKDTree(gt_cloud.points).query(
        points, distance_upper_bound=max_distance_m, workers=-1
    )
    found = np.isfinite(distance)
    truth = np.zeros(len(points), np.uint8)
    truth[found] = gt_cloud.labels[nearest[found]]
    return truth


def cloud_phase_metrics(
    phase_clouds: Mapping[str, LabelledCloud],
    gt_cloud: LabelledCloud,
    *,
    classes: Sequence[int] | None = None,
    max_distance_m: float = 0.05,
) -> dict[str, dict[str, Metrics]]:
    """Return {phase: {label name | "all": metrics}} against a ground-truth cloud.

    Each phase cloud's points are matched to the truth by nearest neighbour (`match_labels`).
    `classes` defaults to the object labels (4-10) present in the truth.
    """
    if classes is None:
        present = set(np.unique(gt_cloud.labels).tolist())
        classes = [c for c in OBJECT_LABELS if c in present]
    truth_of: dict[int, npt.NDArray[np.uint8]] = {}  # phases usually share one points array
    out: dict[str, dict[str, Metrics]] = {}
    for phase, cloud in phase_clouds.items():
        key = id(cloud.points)
        if key not in truth_of:
            truth_of[key] = match_labels(cloud.points, gt_cloud, max_distance_m=max_distance_m)
        out[phase] = label_metrics(cloud.labels, truth_of[key], classes=classes)
    return out


def phase_table(phases: Mapping[str, Mapping[str, Metrics]], *, title: str = "") -> Table:
    """Return the per-phase metrics as one table like the paper's Tables 11 and 12."""
    table = Table(title=title or "refinement per phase (I fused, II DBSCAN, III regrowth)")
    for column in ("phase", "class", "IoU %", "precision %", "recall %", "F1"):
        table.add_column(column, justify="left" if column in ("phase", "class") else "right")
    for phase, per_class in phases.items():
        names = [n for n in per_class if n != "all"] + (["all"] if "all" in per_class else [])
        for i, name in enumerate(names):
            m = per_class[name]
            table.add_row(
                phase if i == 0 else "",
                name,
                f"{100 * m['iou']:.2f}",
                f"{100 * m['precision']:.2f}",
                f"{100 * m['recall']:.2f}",
                f"{m['f1']:.3f}",
                end_section=i == len(names) - 1,
            )
    return table
