"""Tabletop objects: a clutter group left 0 on a table's top becomes an object; nothing else."""

from __future__ import annotations

import numpy as np
from helpers_refine import grid_patch

from process.refine.tabletop import tabletop_objects

UP = np.array([0.0, 0.0, 1.0])


def _box(x: float, y: float, z0: float, layers: int) -> np.ndarray:
    """Return a 10 x 10 cm box of stacked 2 cm grids standing at (x, y) from height z0."""
    return np.concatenate(
        [grid_patch((x, x + 0.1), (y, y + 0.1), z=z0 + 0.02 * i) for i in range(layers)]
    )


def test_a_clutter_box_on_a_table_top_becomes_an_object_the_rest_stays_0() -> None:
    top = grid_patch((0.0, 1.2), (0.0, 0.6), z=0.75)
    on_top = _box(0.5, 0.2, 0.77, 3)  # 75 points of clutter on the desk
    small = _box(0.9, 0.2, 0.77, 1)  # 25 points: fewer than min_points
    floating = _box(0.5, 0.2, 1.2, 3)  # above the desk, beyond r1 of its top
    beside = _box(2.0, 0.2, 0.77, 3)  # at desk height, not over the desk
    plant = _box(0.2, 0.2, 0.77, 3)  # a plant-labelled blob on the desk
    points = np.concatenate([top, on_top, small, floating, beside, plant])
    n = len(top)
    labels = np.r_[np.full(n, 4), np.zeros(len(points) - n)].astype(np.uint8)
    clusters = np.where(labels == 4, 7, 0).astype(np.int32)
    prior = np.r_[np.full(n, 4), np.full(len(points) - n - len(plant), 10), np.full(75, 7)]
    new_labels, new_clusters, found = tabletop_objects(
        points, labels, clusters, prior.astype(np.uint8), r1_m={4: 0.1, 7: 0.1, 10: 0.1},
        up=UP, min_points=30, first_id=8,
    )  # fmt: skip
    box = np.arange(n, n + len(on_top))
    assert found.tolist() == box.tolist()
    assert (new_labels[box] == 10).all() and (new_clusters[box] == 8).all()
    assert (new_labels[n + len(on_top) :] == 0).all()  # too small, floating, beside, plant
    assert (new_labels[:n] == 4).all() and (new_clusters[:n] == 7).all()


def test_a_box_on_a_table_whose_labels_bled_onto_a_cup_is_found() -> None:
    """Table labels on a cup's rim 11 cm over the top do not lift the top the box stands on."""
    top = grid_patch((0.0, 1.2), (0.0, 0.6), z=0.75)
    rim = grid_patch((0.1, 0.2), (0.1, 0.2), z=0.86)  # in the table's cluster
    on_top = _box(0.5, 0.2, 0.77, 3)
    points = np.concatenate([top, rim, on_top])
    n = len(top) + len(rim)
    labels = np.r_[np.full(n, 4), np.zeros(len(on_top))].astype(np.uint8)
    clusters = np.where(labels == 4, 7, 0).astype(np.int32)
    prior = np.r_[np.full(n, 4), np.full(len(on_top), 10)].astype(np.uint8)
    new_labels, _, found = tabletop_objects(
        points, labels, clusters, prior, r1_m={4: 0.1, 10: 0.1}, up=UP, min_points=30, first_id=8
    )
    assert found.tolist() == list(range(n, len(points)))
    assert (new_labels[n:] == 10).all()


def test_without_a_table_nothing_is_found() -> None:
    points = _box(0.5, 0.2, 0.77, 3)
    zeros = np.zeros(len(points), np.uint8)
    labels, clusters, found = tabletop_objects(
        points, zeros, zeros.astype(np.int32), np.full(len(points), 10, np.uint8),
        r1_m={10: 0.1}, up=UP, min_points=30, first_id=1,
    )  # fmt: skip
    assert len(found) == 0 and (labels == 0).all() and (clusters == 0).all()
