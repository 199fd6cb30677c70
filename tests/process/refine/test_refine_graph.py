"""The neighbour-graph helpers the votes share: k-NN edges and connected components."""

from __future__ import annotations

import numpy as np

from process.refine.graph import components, knn_edges


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
