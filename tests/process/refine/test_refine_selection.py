"""The plateau rule for K: known object counts, tolerance windows, and a note that says why."""

from __future__ import annotations

import numpy as np
import pytest
from helpers_refine import grid_patch, labelled

from process.refine import RefineConfig, refine
from process.refine.cells import capped_cells, voxel_cells
from process.refine.dbscan import estimate_parameters
from process.refine.selection import plateau_choice


def _objects_with_specks(seed: int, n_objects: int) -> np.ndarray:
    """Return n_objects table tops (30 x 40 cm at 2 cm, 1 m apart) and 40 specks of 3 points."""
    rng = np.random.default_rng(seed)
    tops = [
        grid_patch((1.0 * i, 1.0 * i + 0.3), (0.0, 0.4), z=0.7 + 0.1 * (i % 2))
        for i in range(n_objects)
    ]
    points = np.concatenate(tops).astype(np.float64)
    points += rng.normal(0.0, 0.002, points.shape)
    centres = rng.uniform((-1.0, 1.0, 0.0), (n_objects, 3.0, 2.0), (40, 3))
    specks = centres[:, None, :] + rng.normal(0.0, 0.01, (40, 3, 3))
    return np.concatenate([points, specks.reshape(-1, 3)])


@pytest.mark.parametrize(("seed", "n_objects"), [(0, 4), (1, 6)])
def test_plateau_picks_a_k_whose_cluster_count_is_the_object_count(
    seed: int, n_objects: int
) -> None:
    points = _objects_with_specks(seed, n_objects)
    table, curves, choice = estimate_parameters(
        points, k_max=30, rule="plateau", min_size=50, tolerance=0.0
    )
    assert choice.stable and choice.rule == "plateau"
    assert choice.note.startswith("plateau K=")
    labels = table.labels(choice.k - 1, choice.min_pts)
    sizes = np.bincount(labels[labels >= 0])
    assert (sizes >= 50).sum() == n_objects
    assert curves.n_big is not None and curves.n_big[choice.k - 1] == n_objects


def test_a_tolerance_joins_counts_that_wobble_by_one() -> None:
    counts = np.array([30, 25, 11, 10, 11, 10, 11, 9, 4, 3])
    index, stable, note = plateau_choice(counts, relative=0.1)
    assert (index, stable) == (6, True)  # 10..11 for K = 3..7; 9 is more than 10 % below 10
    assert note.startswith("plateau K=3..7: 10-11 clusters")
    index, stable, _ = plateau_choice(counts, relative=0.0)
    assert stable is False  # no three equal counts in a row


def test_without_a_plateau_the_note_says_so_and_what_was_chosen() -> None:
    index, stable, note = plateau_choice(np.array([9, 7, 5, 3, 0]), relative=0.0)
    assert (index, stable) == (3, False)
    assert note.startswith("no plateau:") and "K=4" in note
    index, stable, note = plateau_choice(np.array([0, 0, 0]), relative=0.5)
    assert not stable and "no K in 1..3 gives a cluster" in note


def test_the_longest_plateau_wins_and_ties_go_to_the_later_one() -> None:
    counts = np.array([8, 8, 8, 5, 5, 5, 5, 2, 2, 2, 2])
    assert plateau_choice(counts, relative=0.0)[0] == 10
    assert plateau_choice(counts[:7], relative=0.0)[0] == 6


def test_voxel_cells_are_voxel_centroids_and_map_every_point() -> None:
    points = np.array([[0.01, 0.01, 0.0], [0.02, 0.02, 0.0], [0.05, 0.0, 0.0]], np.float32)
    cells, cell_of = voxel_cells(points, 0.03)
    assert len(cells) == 2 and cell_of[0] == cell_of[1] != cell_of[2]
    np.testing.assert_allclose(cells[cell_of[0]], [0.015, 0.015, 0.0], atol=1e-7)
    same, index = voxel_cells(points, 0.0)
    assert same is points and list(index) == [0, 1, 2]


def test_voxel_cells_match_a_row_sort_of_the_voxel_indices() -> None:
    points = (np.random.default_rng(0).normal(size=(5000, 3)) * 2).astype(np.float32)
    keys = np.floor(points / np.float32(0.1)).astype(np.int64)
    _, expected = np.unique(keys, axis=0, return_inverse=True)
    cells, cell_of = voxel_cells(points, 0.1)
    assert np.array_equal(cell_of, expected.reshape(-1))
    np.testing.assert_allclose(cells[cell_of[7]], points[cell_of == cell_of[7]].mean(0), atol=1e-5)


def test_capped_cells_grow_the_voxel_only_past_the_cap() -> None:
    points = np.random.default_rng(1).uniform(0, 1, (20000, 3)).astype(np.float32)
    cells, cell_of, voxel = capped_cells(points, 0.03, 10**6)
    assert voxel == 0.03 and np.array_equal(cell_of, voxel_cells(points, 0.03)[1])
    cells, cell_of, voxel = capped_cells(points, 0.03, 2000)
    assert voxel > 0.03 and len(cells) <= 2000 and cell_of.max() == len(cells) - 1


@pytest.mark.parametrize("step", [0.005, 0.015])
def test_missed_stripes_come_back_and_eps_is_the_same_in_metres_at_any_density(
    step: float,
) -> None:
    rng = np.random.default_rng(2)
    tops = [grid_patch((x0, x0 + 0.6), (0.0, 0.4), z=0.75, step=step) for x0 in (0.0, 1.0)]
    points = np.concatenate(tops) + rng.normal(0.0, 0.001, (sum(map(len, tops)), 3))
    stripe = np.abs(points[:, 0] % 1.0 - 0.3) < 0.02  # a 4 cm band missed across each top
    cloud = labelled(points, np.where(stripe, 0, 4))
    cfg = RefineConfig(plane_min_points=10**6)  # no planes: only clustering and regrowth
    result = refine(cloud, cfg, up=np.array([0.0, 0.0, 1.0]))
    choice = result.dbscan[4].choice
    assert choice is not None and choice.stable
    assert 0.05 <= choice.eps_m <= 0.09  # K = 1..30 over 3 cm cells, whatever the spacing
    assert (result.labels_iii[result.kept] == 4).all()  # the stripes are regrown (SOR aside)
    assert len(np.unique(result.clusters_iii)) >= 2
