"""Label metrics against hand-computed counts, and the nearest-neighbour cloud matching."""

from __future__ import annotations

import numpy as np
import pytest
from rich.console import Console

from process.cloud import LabelledCloud
from process.errors import StageError
from process.evaluate import (
    cloud_phase_metrics,
    image_iou,
    image_miou,
    label_metrics,
    phase_table,
    ratios,
)


def test_per_class_and_pooled_metrics_equal_the_hand_computed_ones() -> None:
    pred = np.array([4, 4, 5, 0, 5, 4])
    gt = np.array([4, 5, 5, 5, 0, 4])
    m = label_metrics(pred, gt, classes=(4, 5, 7))
    # table: TP 2 (0, 5), FP 1 (1), FN 0
    assert m["table"] == pytest.approx({"iou": 2 / 3, "precision": 2 / 3, "recall": 1.0, "f1": 0.8})
    # chair: TP 1 (2), FP 1 (4), FN 2 (1, 3)
    assert m["chair"] == pytest.approx(
        {"iou": 1 / 4, "precision": 1 / 2, "recall": 1 / 3, "f1": 0.4}
    )
    # all: TP 3, FP 2, FN 2
    assert m["all"] == pytest.approx({"iou": 3 / 7, "precision": 3 / 5, "recall": 3 / 5, "f1": 0.6})
    assert "plant" not in m  # in neither prediction nor truth


def test_iou_is_the_papers_accuracy() -> None:
    m = ratios(8910, 1090, 43874)  # precision 89.10 %, recall 16.88 % (paper Table 7, table)
    assert m["precision"] == pytest.approx(0.8910, abs=1e-4)
    assert m["recall"] == pytest.approx(0.1688, abs=1e-4)
    assert m["iou"] == pytest.approx(0.1654, abs=1e-4)  # the printed accuracy, 16.54 %


def test_empty_counts_give_zero_not_an_error() -> None:
    assert ratios(0, 0, 0) == {"iou": 0.0, "precision": 0.0, "recall": 0.0, "f1": 0.0}
    m = label_metrics(np.zeros(4, np.uint8), np.zeros(4, np.uint8), classes=(4,))
    assert m == {"all": {"iou": 0.0, "precision": 0.0, "recall": 0.0, "f1": 0.0}}


def test_image_miou_ignores_absent_classes_and_the_void_label() -> None:
    pred = np.array([[0, 4], [4, 9]])
    gt = np.array([[0, 4], [255, 5]])  # 255 (VOC boundary) is ignored
    assert image_iou(pred, gt, classes=range(11)) == {0: 1.0, 4: 1.0, 5: 0.0, 9: 0.0}
    assert image_miou(pred, gt, classes=range(11)) == pytest.approx(0.5)
    assert np.isnan(image_miou(pred, gt, classes=(7,)))
    with pytest.raises(StageError, match="one shape"):
        image_miou(pred, gt[:1], classes=(4,))


def _cloud(points: list[list[float]], labels: list[int]) -> LabelledCloud:
    n = len(points)
    return LabelledCloud(
        np.array(points, np.float32), np.zeros((n, 3), np.uint8), np.array(labels, np.uint8)
    )


def test_cloud_metrics_match_by_nearest_truth_and_count_unmatched_points_as_background() -> None:
    truth = _cloud([[0, 0, 0], [1, 0, 0], [2, 0, 0]], [4, 5, 0])
    near = [[0.01, 0.0, 0.0], [1.01, 0.0, 0.0], [2.01, 0.0, 0.0], [5.0, 0.0, 0.0]]  # last: no truth
    phases = {"I": _cloud(near, [4, 4, 0, 4]), "III": _cloud(near, [4, 5, 0, 0])}
    m = cloud_phase_metrics(phases, truth, max_distance_m=0.05)
    # phase I: table TP 1, FP 2 (the chair point and the unmatched one); chair FN 1
    assert m["I"]["table"] == pytest.approx(
        {"iou": 1 / 3, "precision": 1 / 3, "recall": 1.0, "f1": 0.5}
    )
    assert m["I"]["chair"]["recall"] == 0.0
    assert m["III"]["all"] == pytest.approx(
        {"iou": 1.0, "precision": 1.0, "recall": 1.0, "f1": 1.0}
    )


def test_phase_table_renders_every_phase_and_class() -> None:
    m = {"I": {"table": ratios(1, 1, 0), "all": ratios(1, 1, 0)}, "III": {"all": ratios(2, 0, 0)}}
    console = Console(width=120, record=True)
    console.print(phase_table(m))
    text = console.export_text()
    assert "table" in text and "50.00" in text and "100.00" in text and "III" in text
