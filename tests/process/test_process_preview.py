"""preview.png: a known map (a floor square, a chair blob, a ceiling) seen from above."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from capture.recording import LABEL_COLORS, LABEL_NAMES
from process import preview

FLOOR, CHAIR, CEILING = (LABEL_NAMES.index(n) for n in ("floor", "chair", "ceiling"))


def _room() -> tuple[np.ndarray, np.ndarray]:  # type: ignore[type-arg]
    """A 2 m floor square at z = 0, a chair blob at (1.5, 1.5) up to 0.8 m, a ceiling at 2.5 m."""
    g = np.arange(0.0, 2.0, 0.005)
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    floor = np.c_[x, y, np.zeros_like(x)]
    rng = np.random.default_rng(0)
    chair = rng.normal([1.5, 1.5, 0.4], [0.06, 0.06, 0.2], (20_000, 3))
    ceiling = floor[::4] + np.array([0.0, 0.0, 2.5])
    points = np.concatenate([floor, chair, ceiling])
    labels = np.r_[np.full(len(floor), FLOOR), np.full(len(chair), CHAIR)]
    labels = np.r_[labels, np.full(len(ceiling), CEILING)].astype(np.uint8)
    return points, labels


def _pixel_of(x: float, y: float) -> tuple[int, int]:
    """Return (row, col) of world (x, y) in the picture of _room (extent 0..2 m in x and y)."""
    px_per_m = (preview.MAP_PX - 2 * preview.MARGIN_PX - preview.POINT_PX) / 2.0
    col = preview.MARGIN_PX + int(x * px_per_m)
    row = preview.MAP_PX - 1 - (preview.MARGIN_PX + int(y * px_per_m))
    return row, col


def test_the_top_view_shows_floor_and_chair_in_their_colours_without_the_ceiling() -> None:
    points, labels = _room()
    image = preview.render_top_view(points, labels, up=np.array([0.0, 0.0, 1.0]))
    assert image.shape == (preview.MAP_PX, preview.MAP_PX + preview.LEGEND_PX, 3)
    assert tuple(image[_pixel_of(1.5, 1.5)]) == LABEL_COLORS[CHAIR]  # the chair is above
    for corner in ((0.2, 0.2), (1.8, 0.2), (0.2, 1.8), (0.5, 1.0)):
        assert tuple(image[_pixel_of(*corner)]) == LABEL_COLORS[FLOOR], corner
    assert tuple(image[_pixel_of(1.8, 0.2)[0], 2]) == preview.BACKGROUND  # left margin
    assert not np.any(np.all(image == LABEL_COLORS[CEILING], axis=-1))


def test_the_legend_lists_labels_by_point_count_and_up_comes_from_the_floor() -> None:
    points, labels = _room()
    tilted = points @ np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], float).T  # z-up to y-down
    image = preview.render_top_view(tilted, labels, up=None)
    swatch = preview.MAP_PX + 8 + 7
    floor_row, chair_row = preview.MARGIN_PX + 7, preview.MARGIN_PX + 22 + 7
    assert tuple(image[floor_row, swatch]) == LABEL_COLORS[FLOOR]
    assert tuple(image[chair_row, swatch]) == LABEL_COLORS[CHAIR]
    assert tuple(image[preview.MARGIN_PX + 44 + 7, swatch]) == preview.BACKGROUND  # 2 labels
    chair = np.all(image[:, : preview.MAP_PX] == LABEL_COLORS[CHAIR], axis=-1).sum()
    assert 1_000 < chair < 20_000  # seen from above: a blob, not a side view's column


def test_write_preview_writes_a_small_png(tmp_path: Path) -> None:
    points, labels = _room()
    path = preview.write_preview(tmp_path / "preview.png", points, labels, up_hint=[0, 0, 1])
    assert path.stat().st_size < 200_000
    bgr = cv2.imread(str(path))
    assert bgr is not None
    assert tuple(bgr[_pixel_of(1.5, 1.5)][::-1]) == LABEL_COLORS[CHAIR]
    assert [p.name for p in tmp_path.iterdir()] == ["preview.png"]


@pytest.mark.parametrize("n", [0, 1])
def test_an_empty_or_one_point_map_still_gives_a_picture(n: int) -> None:
    image = preview.render_top_view(np.zeros((n, 3)), np.full(n, FLOOR), up=None)
    assert image.shape == (preview.MAP_PX, preview.MAP_PX + preview.LEGEND_PX, 3)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_up_is_the_floor_normal_towards_the_objects(sign: float) -> None:
    points, labels = _room()
    keep = labels != CEILING
    up = preview.up_vector(points[keep], labels[keep], hint=[0.0, 0.0, sign])
    np.testing.assert_allclose(up, [0.0, 0.0, 1.0], atol=1e-6)
    no_floor = preview.up_vector(points[:0], labels[:0], hint=[0.0, 1.0, 0.0])
    np.testing.assert_allclose(no_floor, [0.0, 1.0, 0.0])
