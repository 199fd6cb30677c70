"""The neighbour-graph helpers the votes share: k-NN edges and connected components."""

from __future__ import annotations

import numpy as np

from process.refine.graph import components, kd_tree, knn_edges, radius_components


def test_knn_edges_leave_out_each_point_itself() -> None:
    nb = np.array([[0, 1, 2], [1, 0, 2], [2, 1, 0]])
    dist = np.array([[0.0, 1.0, 2.0], [0.0, 1.0, 1.5], [0.0, 1.5, 2.0]])
    i, j, length = knn_edges(dist, nb)
    assert i.tolist() == [0, 0, 1, 1, 2, 2]
    assert j.tolist() == [1, 2, 0, 2, 1, 0]
    assert length.tolist() == [1.0, 2.0, 1.0, 1.5, 1.5, 2.0]


def test_components_join_chains_either_way_and_keep_lone_nodes() -> None:
    count, ids = components(6, np.array([0, 2, 4]), np.array([1, 1, 3]))
    assert count == 3  # {0, 1, 2}, {3, 4}, {5}
    assert ids[0] == ids[1] == ids[2] and ids[3] == ids[4]
    assert len({ids[0], ids[3], ids[5]}) == 3
    assert ids.dtype == np.int32
    assert components(3, np.zeros(0, np.intp), np.zeros(0, np.intp))[0] == 3


def test_components_do_not_depend_on_the_order_of_the_edges() -> None:
    """Edges given in any order, either way round, repeated or looping: the same ids, numbered
    by each component's lowest node (the refinement's steps rely on stable ids)."""
    i = np.array([7, 3, 5, 0, 3, 6, 6, 2])
    j = np.array([6, 5, 8, 2, 5, 7, 6, 0])  # 3-5 twice, 6-6 a loop
    count, ids = components(9, i, j)
    assert count == 5  # {0, 2}, {1}, {3, 5, 8}, {4}, {6, 7}
    assert ids.tolist() == [0, 1, 0, 2, 3, 2, 4, 4, 2]
    order = np.random.default_rng(0).permutation(len(i))
    assert components(9, j[order], i[order])[1].tolist() == ids.tolist()


def test_kd_tree_finds_the_neighbours_of_scipys_default_tree() -> None:
    """The fast-building tree answers every query the refinement asks exactly as SciPy's
    default (balanced, compact) tree: k-NN with and without a bound, balls, pairs."""
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(1)
    points = np.concatenate([rng.random((3000, 3)), rng.random((1000, 3)) * [1, 1, 0]])
    ours, ref = kd_tree(points), cKDTree(points)
    for kwargs in ({"k": 11}, {"k": 4, "distance_upper_bound": 0.03}):
        d, n = ours.query(points[::7], **kwargs)
        d_ref, n_ref = ref.query(points[::7], **kwargs)
        np.testing.assert_array_equal(d, d_ref)
        np.testing.assert_array_equal(n, n_ref)
    counts = ours.query_ball_point(points[::5], 0.05, return_length=True)
    np.testing.assert_array_equal(
        counts, ref.query_ball_point(points[::5], 0.05, return_length=True)
    )
    pairs = ours.query_pairs(0.02, output_type="ndarray")
    pairs_ref = ref.query_pairs(0.02, output_type="ndarray")
    assert sorted(map(tuple, pairs.tolist())) == sorted(map(tuple, pairs_ref.tolist()))


def test_class_pieces_link_one_label_within_the_spacing_bound() -> None:
    from scipy.spatial import cKDTree

    from process.refine.graph import class_pieces

    # a row of points 1 cm apart: labels 4 4 4 | 5 5 | 4 4 after a 5 cm gap
    x = np.array([0.0, 0.01, 0.02, 0.03, 0.04, 0.09, 0.10])
    xyz = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    labels = np.array([4, 4, 4, 5, 5, 4, 4], np.uint8)
    dist, nb = cKDTree(xyz).query(xyz, 3)
    i, j, count, piece = class_pieces(dist, nb, labels, 2.5)  # link: 2.5 cm
    assert count == 3
    assert piece[0] == piece[1] == piece[2] and piece[3] == piece[4] and piece[5] == piece[6]
    assert len({piece[0], piece[3], piece[5]}) == 3  # the gap of 5 cm splits the 4s
    assert (np.abs(x[i] - x[j]) < 0.025).all() and len(i) > 0  # only edges under the link
    assert ((labels[i] != labels[j]) & (np.minimum(i, j) == 2)).any()  # the 4-5 contact stays


def test_radius_components_link_points_within_the_radius_only() -> None:
    """Two rows of points 1 cm apart, 5 cm between the rows: one component each at 2 cm, one
    in all at 6 cm, every point alone at 5 mm."""
    row = np.column_stack([np.arange(0.0, 0.1, 0.01), np.zeros(10), np.zeros(10)])
    points = np.concatenate([row, row + np.array([0.0, 0.05, 0.0])])
    two = radius_components(points, 0.02)
    assert len(np.unique(two[:10])) == 1 and len(np.unique(two[10:])) == 1 and two[0] != two[10]
    assert len(np.unique(radius_components(points, 0.06))) == 1
    assert len(np.unique(radius_components(points, 0.005))) == 20
