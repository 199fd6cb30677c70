"""The piece vote: a face a label bled onto across a gap goes back to the object holding it."""

from __future__ import annotations

import dataclasses

import numpy as np
import numpy.typing as npt
import pytest
from helpers_refine import grid_patch, labelled

import process.refine.pieces as pieces
from capture.recording import Label
from process.refine import RefineConfig, refine
from process.refine.job import refinement_metrics
from process.refine.pieces import piece_vote

CHAIR, PERSON, SOFA, CLUTTER, TABLE = (
    Label.CHAIR, Label.PERSON, Label.SOFA, Label.CLUTTER, Label.TABLE,
)  # fmt: skip
STEP = 0.01

Points = npt.NDArray[np.float64]


def _box(low: tuple[float, float, float], high: tuple[float, float, float]) -> list[Points]:
    """Return the six faces of a box at STEP: -x, +x, -y, +y, -z, +z."""
    faces = []
    for axis in range(3):
        a, b = (k for k in range(3) if k != axis)
        grid = grid_patch((low[a], high[a]), (low[b], high[b]), step=STEP)
        for side in (low[axis], high[axis]):
            face = np.zeros((len(grid), 3))
            face[:, a], face[:, b], face[:, axis] = grid[:, 0], grid[:, 1], side
            faces.append(face)
    return faces


def _seated_back(
    seed: int = 0,
) -> tuple[Points, npt.NDArray[np.uint8], npt.NDArray[np.int32], npt.NDArray[np.bool_], int]:
    """A person's torso (a box 22 x 38 x 60 cm) 4 cm before a chair's back (4 cm thick).

    The chair's label bled across the gap onto the torso's whole back face, and DBSCAN's eps
    bridged it: the face is in the chair's cluster (1). Returns points, labels, clusters, the
    mask of the torso's back face and how many points the chair's back has (first).
    """
    chair = np.vstack(_box((-0.24, 0.0, 0.5), (-0.20, 0.44, 0.92)))
    torso = _box((-0.16, 0.03, 0.5), (0.06, 0.41, 1.1))
    back, rest = torso[0], np.vstack(torso[1:])
    points = np.vstack([chair, back, rest])
    points += np.random.default_rng(seed).normal(0.0, 0.002, points.shape)
    labels = np.concatenate(
        [np.full(len(chair) + len(back), CHAIR), np.full(len(rest), PERSON)]
    ).astype(np.uint8)
    clusters = np.concatenate([np.full(len(chair) + len(back), 1), np.full(len(rest), 2)]).astype(
        np.int32
    )
    is_back = np.zeros(len(points), bool)
    is_back[len(chair) : len(chair) + len(back)] = True
    return points, labels, clusters, is_back, len(chair)


def test_a_torsos_back_the_chairs_label_bled_onto_goes_back_to_the_person() -> None:
    points, labels, clusters, back, n_chair = _seated_back()
    vote = piece_vote(points, labels, clusters)
    assert back.sum() > 2000
    assert (vote.labels[back] == PERSON).mean() > 0.95
    assert (vote.labels[:n_chair] == CHAIR).all()  # the chair's back is the chair's object
    assert set(vote.relabelled.tolist()) == set(np.flatnonzero(labels != vote.labels).tolist())


def test_a_piece_that_is_its_objects_largest_stays_unless_it_lies_between_the_two() -> None:
    """The same face in a cluster of its own is an object (a cushion on a sofa's back) when
    nothing of its class lies behind it; 4 cm before the chair's back it is the torso's."""
    points, labels, clusters, back, n_chair = _seated_back()
    clusters[back] = 3
    between = piece_vote(points, labels, clusters)
    assert (between.labels[back] == PERSON).all() and (between.labels[:n_chair] == CHAIR).all()
    away = points.copy()
    away[:n_chair, 0] -= 0.1  # the chair's back 14 cm behind the face: past GAP_M
    assert (piece_vote(away, labels, clusters).labels == labels).all()
    del_chair = np.arange(len(points)) >= n_chair  # no chair at all: a cushion
    alone = piece_vote(points[del_chair], labels[del_chair], clusters[del_chair])
    assert (alone.labels == labels[del_chair]).all()


def _chair_back_behind_a_torso() -> tuple[Points, npt.NDArray[np.uint8], npt.NDArray[np.int32],
                                           npt.NDArray[np.bool_]]:  # fmt: skip
    """A chair's back (a board 3 cm thick) 4 cm behind a torso; the person's label covers the
    board's whole front face, which DBSCAN left a cluster of its own (generator 4's kitchen).

    The face is as large as the rest of the board: the largest piece of its cluster, and more
    than RATIO times the piece it touches. Returns points, labels, clusters, the face's mask.
    """
    board = _box((-0.23, 0.0, 0.5), (-0.20, 0.44, 0.92))
    face, rest = board[1], np.vstack(board[:1] + board[2:])  # +x: toward the person
    torso = np.vstack(_box((-0.16, 0.03, 0.5), (0.06, 0.41, 1.1)))
    points = np.vstack([rest, face, torso])
    points += np.random.default_rng(3).normal(0.0, 0.002, points.shape)
    labels = np.r_[np.full(len(rest), CHAIR), np.full(len(face) + len(torso), PERSON)]
    clusters = np.r_[np.full(len(rest), 1), np.full(len(face), 3), np.full(len(torso), 2)]
    is_face = np.zeros(len(points), bool)
    is_face[len(rest) : len(rest) + len(face)] = True
    return points, labels.astype(np.uint8), clusters.astype(np.int32), is_face


def test_a_chair_backs_face_the_persons_label_covers_goes_back_to_the_chair(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    points, labels, clusters, face = _chair_back_behind_a_torso()
    assert face.sum() > 1500 and face.sum() > pieces.RATIO * (labels == CHAIR).sum()
    vote = piece_vote(points, labels, clusters)
    assert (vote.labels[face] == CHAIR).all()
    assert (vote.labels[~face] == labels[~face]).all()  # the torso stays the person's
    monkeypatch.setattr(pieces, "GAP_M", 0.03)  # the torso 4 cm away: not between the two
    assert (piece_vote(points, labels, clusters).labels[face] == PERSON).all()


def test_where_the_bleed_swapped_both_faces_both_go_back(monkeypatch: pytest.MonkeyPatch) -> None:
    """The torso's back labelled chair (in the chair's cluster) and the chair back's front face
    labelled person (a cluster of its own; generator 4's office at 200k: 2,099 and 1,838
    points). The first pass gives the torso's back to the person (a bled face); only then does
    the chair's front lie between the person and the rest of its board, and the second pass
    gives it back."""
    board = _box((-0.23, 0.0, 0.5), (-0.20, 0.44, 0.92))
    front, rest = board[1], np.vstack(board[:1] + board[2:])
    torso = _box((-0.16, 0.03, 0.5), (0.06, 0.41, 1.1))
    back, body = torso[0], np.vstack(torso[1:])
    points = np.vstack([rest, front, back, body])
    points += np.random.default_rng(4).normal(0.0, 0.002, points.shape)
    sizes = [len(rest), len(front), len(back), len(body)]
    labels = np.repeat([CHAIR, PERSON, CHAIR, PERSON], sizes).astype(np.uint8)
    clusters = np.repeat([1, 3, 1, 2], sizes).astype(np.int32)
    part = np.repeat(np.arange(4), sizes)
    truth = np.repeat([CHAIR, CHAIR, PERSON, PERSON], sizes)

    vote = piece_vote(points, labels, clusters)
    assert (vote.labels == truth).all()
    one_pass = pieces._vote

    def first_only(*args: object, between_only: bool = False) -> npt.NDArray[np.uint8]:
        return args[1] if between_only else one_pass(*args)  # type: ignore[arg-type,return-value]

    monkeypatch.setattr(pieces, "_vote", first_only)
    single = piece_vote(points, labels, clusters).labels
    assert (single[part == 2] == PERSON).all() and (single[part == 1] == PERSON).all()


def test_only_a_flat_piece_lies_between(monkeypatch: pytest.MonkeyPatch) -> None:
    """The face's least variance is its noise (2 mm): under FLAT of its total, a face; held to
    a bound below that, the same points are a body, whose sides mean nothing, and stay."""
    points, labels, clusters, face = _chair_back_behind_a_torso()
    centred = points[face] - points[face].mean(axis=0)
    variance = np.linalg.eigvalsh(centred.T @ centred)
    assert 1e-5 < variance[0] / variance.sum() < pieces.FLAT
    monkeypatch.setattr(pieces, "FLAT", 1e-5)
    assert (piece_vote(points, labels, clusters).labels[face] == PERSON).all()


def test_past_max_points_the_vote_runs_on_class_cells_with_the_same_verdict() -> None:
    """On half as many cells (1.6 cm voxels) the 4 cm gap still parts the pieces; on 1.8 cm
    ones LINK spacings bridge it and the face stays: the vote sees gaps of 2.5 cells."""
    points, labels, clusters, back, n_chair = _seated_back(seed=1)
    vote = piece_vote(points, labels, clusters, max_points=len(points) // 2)
    assert (vote.labels[back] == PERSON).mean() > 0.9
    assert (vote.labels[:n_chair] == CHAIR).all()
    coarse = piece_vote(points, labels, clusters, max_points=int(len(points) * 0.4))
    assert (coarse.labels[back] == CHAIR).all()


def _box_on_a_seat(label: int) -> tuple[Points, npt.NDArray[np.uint8], npt.NDArray[np.int32]]:
    """A box (`label`) standing on a sofa's seat; a larger box of its class 10 cm beside it is
    its cluster's largest piece (DBSCAN joined the two)."""
    seat = grid_patch((0.0, 1.2), (0.0, 0.8), z=0.45, step=STEP).astype(np.float64)
    small = np.vstack(_box((0.2, 0.2, 0.45), (0.4, 0.4, 0.6))[:4] + _box(
        (0.2, 0.2, 0.45), (0.4, 0.4, 0.6))[5:])  # fmt: skip
    large = np.vstack(_box((0.5, 0.2, 0.45), (0.9, 0.6, 0.75))[:4] + _box(
        (0.5, 0.2, 0.45), (0.9, 0.6, 0.75))[5:])  # fmt: skip
    keep = ~(
        ((seat[:, 0] > 0.2) & (seat[:, 0] < 0.4) & (seat[:, 1] > 0.2) & (seat[:, 1] < 0.4))
        | ((seat[:, 0] > 0.5) & (seat[:, 0] < 0.9) & (seat[:, 1] > 0.2) & (seat[:, 1] < 0.6))
    )
    seat = seat[keep]  # hidden under the boxes
    points = np.vstack([seat, small, large])
    points += np.random.default_rng(2).normal(0.0, 0.002, points.shape)
    labels = np.concatenate([np.full(len(seat), SOFA), np.full(len(small) + len(large), label)])
    clusters = np.concatenate([np.full(len(seat), 1), np.full(len(small) + len(large), 2)])
    return points, labels.astype(np.uint8), clusters.astype(np.int32)


def test_a_box_standing_on_a_seat_is_not_bordered_all_round(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Its contacts lie along its foot, not up its sides: it stays itself."""
    points, labels, clusters = _box_on_a_seat(CLUTTER)
    assert (piece_vote(points, labels, clusters).labels == labels).all()
    monkeypatch.setattr(pieces, "ENCLOSED", 0.0)  # the enclosure test is what keeps it
    assert (piece_vote(points, labels, clusters).labels[labels == CLUTTER] == SOFA).any()


def test_a_table_neither_takes_nor_gives_pieces() -> None:
    """A box on a desk touches only the desk; a stretch of a desk between the things on it is
    bordered by them: both stay (TUM fr1_rpy: 369 desk points would have become clutter)."""
    points, labels, clusters = _box_on_a_seat(CLUTTER)
    seat = labels == SOFA
    labels[seat] = TABLE
    assert (piece_vote(points, labels, clusters).labels == labels).all()
    torso_points, torso_labels, torso_clusters, back, _ = _seated_back()
    torso_labels[torso_labels == CHAIR] = TABLE
    vote = piece_vote(torso_points, torso_labels, torso_clusters)
    assert (vote.labels[back] == TABLE).all()


def test_refine_gives_the_torsos_back_to_the_person() -> None:
    """Through refine (planes, SOR, DBSCAN, regrowth, seams), in a room with a floor."""
    points, labels, _, back, _ = _seated_back()
    floor = grid_patch((-1.0, 1.0), (-1.0, 1.5))
    cloud = labelled(np.vstack([floor, points]), np.r_[np.full(len(floor), Label.FLOOR), labels])
    cfg = RefineConfig(plane_min_points=1500, plane_max_remaining=100)
    up = np.array([0.0, 0.0, 1.0])
    at = len(floor)
    out = refine(cloud, cfg, up=up)
    assert (out.labels_iii[at:][back] == PERSON).mean() > 0.9
    assert refinement_metrics(out, gt_cloud=None)["points"]["piece_relabelled"] > 2000
    assert len(out.seam_cloud()) >= len(out.pieces)  # shown with the seams in the .rrd
    off = refine(cloud, dataclasses.replace(cfg, piece_vote=False), up=up)
    assert (off.labels_iii[at:][back] == CHAIR).mean() > 0.9
    assert not RefineConfig.paper().piece_vote


def test_neighbours_handed_in_give_the_same_verdict_and_a_mismatch_is_not_used() -> None:
    """The seam vote's nearest neighbours of the object points (seams.SeamVote) are reused."""
    from scipy.spatial import cKDTree

    points, labels, clusters, back, _ = _seated_back()
    own = np.flatnonzero(np.isin(labels, (CHAIR, PERSON)))
    xyz = points[own].astype(np.float32).astype(np.float64)
    neighbours = cKDTree(xyz).query(xyz, pieces.NEIGHBOURS + 1)
    alone = piece_vote(points, labels, clusters)
    given = piece_vote(points, labels, clusters, neighbours=neighbours)
    assert (given.labels == alone.labels).all() and (alone.labels[back] == PERSON).mean() > 0.95
    short = (neighbours[0][:10], neighbours[1][:10])  # of other points: computed afresh
    assert (piece_vote(points, labels, clusters, neighbours=short).labels == alone.labels).all()
