"""Object labels spilled off their object onto the background cast no fusion vote."""

from __future__ import annotations

import numpy as np
import pytest

from capture.recording import Intrinsics
from process.fusion.bleed import spilled_labels
from process.fusion.votes import Fusion, FusionConfig

K = Intrinsics(64, 48, 50.0, 50.0, 31.5, 23.5)
WALL_M, PERSON_M = 3.0, 1.5


def _scene() -> tuple[np.ndarray, np.ndarray]:
    """Return labels and depth: a wall at 3 m, a person at 1.5 m whose label spills 2 px."""
    depth = np.full((K.height, K.width), WALL_M, np.float32)
    labels = np.full(depth.shape, 3, np.uint8)
    depth[12:36, 20:44] = PERSON_M
    labels[10:38, 18:46] = 6  # the label reaches 2 px past the silhouette, onto the wall
    return labels, depth


def test_the_spilled_rim_of_an_object_is_found_and_nothing_else() -> None:
    labels, depth = _scene()
    labels[40:, :] = 4  # a table top receding from 0.8 to 2.5 m keeps its far end
    depth[40:, :] = np.linspace(0.8, 2.5, 8)[:, None]
    depth[11, 30] = 0.0  # no depth: never an outlier
    spilled = spilled_labels(labels, depth, mad_factor=3.0, min_margin_m=0.25)
    rim = (labels == 6) & (depth == WALL_M)
    assert rim.sum() == 28 * 28 - 24 * 24 - 1
    assert (spilled == rim).all()
    assert not spilled[labels != 6].any()  # the wall, and the table's far end
    # more spill than object: the median is the wall's, so the person's pixels are the outliers
    labels[4:44, 10:54] = 6
    assert spilled_labels(labels, depth, mad_factor=3.0, min_margin_m=0.25)[12:36, 20:44].all()


@pytest.mark.parametrize(("factor", "ghost"), [(3.0, False), (0.0, True)])
def test_fusion_leaves_no_ghost_of_the_object_on_the_wall(factor: float, ghost: bool) -> None:
    labels, depth = _scene()
    fusion = Fusion(FusionConfig(pixel_stride=1, surface="voxels", spill_mad_factor=factor))
    color = np.zeros((*depth.shape, 3), np.uint8)
    confidence = np.full(depth.shape, 0.9, np.float32)
    fusion.integrate(color, depth, labels, confidence, intrinsics=K, world_from_camera=np.eye(4))
    cloud = fusion.cloud()
    on_wall = np.abs(cloud.points[:, 2] - WALL_M) < 0.05
    on_person = np.abs(cloud.points[:, 2] - PERSON_M) < 0.05
    assert (cloud.labels[on_person] == 6).all()
    assert bool((cloud.labels[on_wall] == 6).any()) == ghost
    assert (cloud.labels[on_wall] == 3).mean() > 0.8
