"""Distillation: recordings without ground-truth labels train on a teacher's labels."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest

from process.errors import ConfigError, StageError
from process.segmentation.dataset import IGNORE, load_labelled
from process.segmentation.distill import make_teacher


def _left_table_right_unsure(color: npt.NDArray[np.uint8]) -> npt.NDArray[np.uint8]:
    labels = np.full(color.shape[:2], 4, np.uint8)
    labels[:, color.shape[1] // 2 :] = IGNORE
    return labels


def test_frames_without_ground_truth_take_the_teachers_labels(recording: Path) -> None:
    with pytest.raises(StageError, match="or --teacher"):
        load_labelled([recording], short_side_px=96)
    data = load_labelled(
        [recording], short_side_px=96, teacher=_left_table_right_unsure, teacher_every_nth=2
    )
    assert len(data) == 3  # frames 0, 2, 4 of 5
    assert data.colors.shape == (3, 96, 128, 3)
    assert set(np.unique(data.labels[:, :, :64])) == {4}
    assert set(np.unique(data.labels[:, :, 64:])) == {IGNORE}


def test_ground_truth_wins_over_the_teacher(sim_recording: Path) -> None:
    data = load_labelled(
        [sim_recording], short_side_px=96, every_nth=10, teacher=_left_table_right_unsure
    )
    assert len(data) == 3 and len(np.unique(data.labels)) > 3  # the room's labels, not 4


def test_teachers_are_the_real_image_models() -> None:
    with pytest.raises(ConfigError, match="--teacher must be one of"):
        make_teacher("simulator")
    pytest.importorskip("ai_edge_litert")
    teacher = make_teacher("voc", threads=1, min_confidence=1.01)  # nothing is sure enough
    labels = teacher(np.zeros((48, 64, 3), np.uint8))
    assert labels.shape == (48, 64) and set(np.unique(labels)) == {IGNORE}
