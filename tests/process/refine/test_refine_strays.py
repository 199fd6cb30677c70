"""Strays rejoining their class's object after regrowth (process/refine/outliers.py)."""

from __future__ import annotations

import dataclasses

import numpy as np

from capture.recording import Label
from process.cloud import LabelledCloud
from process.refine import RefineConfig, refine
from process.refine.job import refinement_metrics
from process.refine.outliers import rejoin_strays


def _plant(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A pot's wall every 5 mm (0.15 m across, 0.25 m high); 100 leaves of 4 points around its
    top, each leaf 1 cm across, 5-7 cm from the next: sparse foliage."""
    angle, z = np.meshgrid(np.linspace(0, 2 * np.pi, 95, endpoint=False), np.arange(0, 0.25, 0.005))
    pot = np.column_stack([0.075 * np.cos(angle.ravel()), 0.075 * np.sin(angle.ravel()), z.ravel()])
    direction = rng.normal(size=(100, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    centres = direction * rng.uniform(0.1, 0.35, (100, 1)) + [0.0, 0.0, 0.45]
    leaves = np.repeat(centres, 4, axis=0) + rng.uniform(-0.005, 0.005, (400, 3))
    return pot.astype(np.float32), leaves.astype(np.float32)


def test_a_sprig_of_strays_rejoins_its_plant_in_waves_and_lone_points_stay_out() -> None:
    stem = np.column_stack([np.zeros(51), np.zeros(51), np.linspace(0, 0.5, 51)])  # 1 cm
    sprig = np.repeat(np.arange(1, 6) * 0.08, 2)  # 5 leaves of 2 points 8 cm apart
    sprig = np.column_stack([sprig, np.tile([0.0, 0.01], 5), np.full(10, 0.5)])
    speck = np.array([[2.0, 0.0, 0.5], [2.01, 0.0, 0.5]])  # a leaf far from any plant
    lone = np.array([[0.06, 0.06, 0.25]])  # a lone plant label 8 cm from the stem: a flying pixel
    chair = np.column_stack([np.full(51, -0.5), np.zeros(51), np.linspace(0, 0.5, 51)])
    chair_stray = np.array([[-0.45, 0.0, 0.25], [-0.45, 0.01, 0.25]])  # chair speckle: stays
    points = np.concatenate([stem, sprig, speck, lone, chair, chair_stray]).astype(np.float32)
    network = np.array([Label.PLANT] * 64 + [Label.CHAIR] * 53, np.uint8)
    labels = np.zeros(len(points), np.uint8)
    clusters = np.zeros(len(points), np.int32)
    labels[:51], clusters[:51] = Label.PLANT, 1
    labels[64:115], clusters[64:115] = Label.CHAIR, 2
    strays = np.concatenate([np.arange(51, 64), [115, 116]])
    r1 = {int(Label.PLANT): 0.1, int(Label.CHAIR): 0.1}
    joined = rejoin_strays(points, strays, network, labels, clusters, r1)
    assert joined.tolist() == list(range(51, 61))  # the sprig, one wave per leaf
    assert (labels[51:61] == Label.PLANT).all() and (clusters[51:61] == 1).all()
    assert (labels[61:64] == 0).all()  # far from any plant; alone
    assert (labels[115:] == 0).all()  # only plants' strays


def test_sparse_foliage_that_sor_removes_comes_back_as_plant() -> None:
    rng = np.random.default_rng(0)
    pot, leaves = _plant(rng)
    floor = np.column_stack(
        [rng.uniform(-1.5, 1.5, 20_000), rng.uniform(-1.5, 1.5, 20_000), np.zeros(20_000)]
    )
    points = np.concatenate([floor, pot, leaves]).astype(np.float32)
    labels = np.zeros(len(points), np.uint8)
    labels[len(floor) :] = Label.PLANT
    cloud = LabelledCloud(points, np.zeros((len(points), 3), np.uint8), labels)
    leaf = np.arange(len(floor) + len(pot), len(points))
    cfg = RefineConfig()
    without = refine(cloud, dataclasses.replace(cfg, rejoin_strays=False), up=np.array([0, 0, 1.0]))
    out = refine(cloud, cfg, up=np.array([0, 0, 1.0]))
    lost = without.labels_iii[leaf] != Label.PLANT
    assert lost.mean() > 0.5  # SOR and DBSCAN take the leaves for noise (86 %) ...
    assert (out.labels_iii[leaf] == Label.PLANT).mean() > 0.75  # ... and most come back (81 %)
    assert out.kept[leaf].mean() > 0.75  # SOR's among them stay in the refined map
    points_section = refinement_metrics(out, gt_cloud=None)["points"]
    assert points_section["strays_rejoined"] == len(out.strays) >= 0.5 * len(leaf)


def test_strays_with_no_plant_to_join_or_no_plant_eps_join_nothing() -> None:
    points = np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [5.0, 5.0, 5.0]], np.float32)
    network = np.full(3, Label.PLANT, np.uint8)
    labels, clusters = np.zeros(3, np.uint8), np.zeros(3, np.int32)
    strays = np.arange(3)
    assert len(rejoin_strays(points, strays, network, labels, clusters, {7: 0.1})) == 0  # no host
    labels[2], clusters[2] = Label.PLANT, 1
    assert len(rejoin_strays(points, strays[:2], network, labels, clusters, {})) == 0  # no eps
    assert (labels[:2] == 0).all()


def test_a_crown_beyond_r1_joins_the_pot_under_it_with_its_stem_and_flank_strays_stay() -> None:
    """A pot whose stem the network missed; its crown 0.3 m higher, leaves of 2 points 5 cm
    apart: beyond r1 of the pot, within r1 of each other; the unlabelled stem between. Under a
    second plant's branch, over its plan box but below its top, strays beyond r1 of it (flying
    pixels at its silhouette); a crown over nothing; three plant labels high over the pot, in
    groups of 2 and 1."""
    rng = np.random.default_rng(1)
    pot = np.column_stack([rng.uniform(-0.08, 0.08, (300, 2)), rng.uniform(0, 0.25, 300)])
    grid = np.stack(np.meshgrid(*[np.arange(-0.15, 0.16, 0.05)] * 2), -1).reshape(-1, 2)
    crown = np.column_stack([grid, rng.uniform(0.55, 0.6, len(grid))])
    crown = np.repeat(crown, 2, axis=0) + [0.0, 0.008, 0.0] * np.tile([[0], [1]], (len(grid), 1))
    stem = np.column_stack([np.zeros(30), np.zeros(30), np.linspace(0.26, 0.55, 30)])
    plant = np.column_stack([rng.uniform(1.9, 2.1, (400, 2)), rng.uniform(0, 0.25, 400)])
    branch = np.column_stack(
        [rng.uniform(1.9, 2.3, 200), rng.uniform(1.9, 2.1, 200), rng.uniform(0.7, 0.8, 200)]
    )
    plant = np.concatenate([plant, branch])  # a pot and a branch out to x = 2.3 at 0.7-0.8 m
    flank = np.column_stack([np.full(20, 2.25), np.linspace(1.9, 2.1, 20), np.full(20, 0.4)])
    flank = np.repeat(flank, 2, axis=0) + [0.0, 0.0, 0.008] * np.tile([[0], [1]], (20, 1))
    lost = np.column_stack([np.full(10, 5.0), np.linspace(0, 0.2, 10), np.full(10, 0.8)])
    lost = np.repeat(lost, 2, axis=0) + [0.008, 0.0, 0.0] * np.tile([[0], [1]], (10, 1))
    specks = np.array([[0.0, 0.05, 1.2], [0.01, 0.05, 1.2], [0.05, -0.05, 1.4]])  # < crown_min
    parts = [pot, crown, stem, plant, flank, lost, specks]
    points = np.concatenate(parts).astype(np.float32)
    start = np.cumsum([0] + [len(p) for p in parts])
    network = np.full(len(points), Label.PLANT, np.uint8)
    network[start[2] : start[3]] = 0  # the stem: missed
    labels, clusters = np.zeros(len(points), np.uint8), np.zeros(len(points), np.int32)
    labels[: start[1]], clusters[: start[1]] = Label.PLANT, 1
    labels[start[3] : start[4]], clusters[start[3] : start[4]] = Label.PLANT, 2
    strays = np.concatenate([np.arange(start[1], start[3]), np.arange(start[4], start[7])])
    r1, up = {int(Label.PLANT): 0.1}, np.array([0.0, 0.0, 1.0])
    unaided = rejoin_strays(points, strays, network, labels.copy(), clusters.copy(), r1)
    assert len(unaided) == 0  # without up: more than r1 from any plant point, as before
    joined = rejoin_strays(points, strays, network, labels, clusters, r1, up=up, crown_min=5)
    assert joined.tolist() == list(range(start[1], start[3]))  # the crown and the stem only
    assert (clusters[start[1] : start[3]] == 1).all()  # into its pot's cluster
    assert (labels[start[4] :] == 0).all()  # the flank's strays, the far crown, the specks


def test_leaves_seen_behind_a_wall_stay_out_of_the_plant_in_front_of_it() -> None:
    """The plant stands 15 cm before a wall; what the network calls plant more than
    `wall_keep_out_m` behind the wall plane (through a window, a mirror, depth noise) is no
    foliage of it: neither SOR's outliers there nor DBSCAN's leftovers rejoin it."""
    rng = np.random.default_rng(0)
    pot, leaves = _plant(rng)
    floor = np.column_stack(
        [rng.uniform(-2.5, 0.25, 20_000), rng.uniform(-1.5, 1.5, 20_000), np.zeros(20_000)]
    )
    y, z = np.meshgrid(np.arange(-1.5, 1.5, 0.02), np.arange(0.0, 2.5, 0.02))
    wall = np.column_stack([np.full(y.size, 0.25), y.ravel(), z.ravel()])  # the plane x = 0.25
    shift = np.array([0.1, 0.0, 0.0], np.float32)
    points = np.concatenate([floor, wall, pot + shift, leaves + shift]).astype(np.float32)
    labels = np.zeros(len(points), np.uint8)
    labels[len(floor) + len(wall) :] = Label.PLANT
    cloud = LabelledCloud(points, np.zeros((len(points), 3), np.uint8), labels)
    leaf = np.arange(len(points) - len(leaves), len(points))
    behind = leaf[points[leaf, 0] > 0.25 + 0.03 + 0.005]
    front = leaf[points[leaf, 0] < 0.25 - 0.03]
    assert len(behind) >= 40 and len(front) >= 200
    cfg = RefineConfig()
    out = refine(cloud, cfg, up=np.array([0, 0, 1.0]))
    assert not np.isin(behind, out.strays).any()
    assert (out.labels_iii[behind] != Label.PLANT).all()
    assert (out.labels_iii[front] == Label.PLANT).mean() > 0.75  # the plant's own come back
    blind = refine(cloud, dataclasses.replace(cfg, wall_keep_out_m=0.0), up=np.array([0, 0, 1.0]))
    assert (blind.labels_iii[behind] == Label.PLANT).mean() > 0.5  # without the wall test
