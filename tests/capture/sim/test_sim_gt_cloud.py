"""The ground-truth cloud: points on the surfaces, with their part's label, instance and colour."""

from __future__ import annotations

import numpy as np
from helpers_sim import mesh_distance

from capture.sim import Renderer, build_scene, ply_bytes, read_ply, sample_scene
from capture.sim.gt_cloud import MIN_POINTS_PER_PART


def test_points_lie_on_the_surfaces_with_the_labels_of_their_parts() -> None:
    scene = build_scene(8)
    cloud = sample_scene(scene, renderer=Renderer(scene), spacing_m=0.05, seed=8)
    label_of = {p.instance: p.label for p in scene.parts}
    np.testing.assert_array_equal(cloud.labels, [label_of[int(i)] for i in cloud.instances])
    pick = np.random.default_rng(0).choice(len(cloud.labels), 5000, replace=False)
    for instance in np.unique(cloud.instances[pick]):
        mine = pick[cloud.instances[pick] == instance]
        meshes = [p.mesh for p in scene.parts if p.instance == instance]
        assert float(mesh_distance(meshes, cloud.points_m[mine].astype(np.float64)).max()) < 1e-4


def test_density_follows_the_spacing_and_small_parts_are_kept() -> None:
    scene = build_scene(8)
    renderer = Renderer(scene)
    coarse = sample_scene(scene, renderer=renderer, spacing_m=0.1, seed=1)
    fine = sample_scene(scene, renderer=renderer, spacing_m=0.05, seed=1)
    floor_coarse = np.sum(coarse.labels == 2)
    floor_fine = np.sum(fine.labels == 2)
    assert 3.8 < floor_fine / floor_coarse < 4.2  # a quarter of the area per point
    area = scene.room_m[0] * scene.room_m[1]
    assert abs(floor_fine - area / 0.05**2) / (area / 0.05**2) < 0.05
    assert min(np.bincount(coarse.instances)[np.unique(coarse.instances)]) >= MIN_POINTS_PER_PART


def test_ply_round_trip_keeps_every_field() -> None:
    scene = build_scene(8)
    cloud = sample_scene(scene, renderer=Renderer(scene), spacing_m=0.2, seed=2)
    data = read_ply(ply_bytes(cloud))
    np.testing.assert_array_equal(np.stack([data["x"], data["y"], data["z"]], 1), cloud.points_m)
    np.testing.assert_array_equal(
        np.stack([data["red"], data["green"], data["blue"]], 1), cloud.colors
    )
    np.testing.assert_array_equal(data["label"], cloud.labels)
    np.testing.assert_array_equal(data["instance"], cloud.instances)
