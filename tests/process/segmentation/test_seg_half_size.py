"""The bench's stability figure: a model's agreement with itself on half-size frames."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any, cast

import numpy as np

from benchmarks.seg_models import _half_size_agreement


class _ByColour:
    """Labels from the red channel: the same at any size (a perfectly stable model)."""

    def segment(self, image: np.ndarray[Any, Any]) -> SimpleNamespace:
        return SimpleNamespace(labels=(image[..., 0] > 127).astype(np.uint8) * 3)


class _ByColumnParity:
    """Labels from the column's parity: what a model sees only at full size."""

    def segment(self, image: np.ndarray[Any, Any]) -> SimpleNamespace:
        cols = np.arange(image.shape[1]) % 2
        return SimpleNamespace(labels=np.broadcast_to(cols, image.shape[:2]).astype(np.uint8))


def _image() -> np.ndarray[Any, Any]:
    image = np.zeros((48, 64, 3), np.uint8)
    image[:, 32:, 0] = 255  # right half red
    return image


def test_a_size_independent_model_agrees_with_itself() -> None:
    model = _ByColour()
    image = _image()
    labels = [model.segment(image).labels]
    assert _half_size_agreement(cast(Any, model), [image], labels) == 1.0


def test_a_model_of_fine_detail_agrees_half_the_time() -> None:
    model = _ByColumnParity()
    image = _image()
    labels = [model.segment(image).labels]
    # At half size each label covers two columns, one of which disagrees.
    assert _half_size_agreement(cast(Any, model), [image], labels) == 0.5
