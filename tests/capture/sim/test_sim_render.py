"""The renderer against known answers: planes, boxes, labels and poses."""

from __future__ import annotations

import numpy as np
import pytest
from helpers_sim import (
    SMALL_K,
    backproject,
    box_part,
    mesh_distance,
    scene_of,
    transform,
    wall_at,
)

from capture.recording.frames import Intrinsics
from capture.sim import FrameSimulator, Renderer, Scene, build_scene, d435_rig
from capture.sim.placement import PlacedPart
from capture.sim.shapes import plane_grid
from capture.sim.textures import Material
from capture.sim.trajectory import handheld_loop, look_rotation


@pytest.mark.parametrize("distance_m", [0.5, 1.0, 3.7])
def test_fronto_parallel_plane_renders_its_distance(distance_m: float) -> None:
    renderer = Renderer(scene_of([wall_at(distance_m)]))
    depth = renderer.depth_image(np.eye(4), intrinsics=SMALL_K)
    np.testing.assert_allclose(depth, distance_m, rtol=1e-6)


def test_slanted_plane_depth_matches_ray_plane_intersection() -> None:
    # The plane z = 2 + 0.5 x (camera = world): the ray (x, y, 1) t meets it at t = 2 / (1 - 0.5 x).
    tilt = np.eye(4)
    angle = np.arctan(0.5)
    tilt[:3, :3] = [
        [np.cos(angle), 0, -np.sin(angle)],
        [0, 1, 0],
        [np.sin(angle), 0, np.cos(angle)],
    ]
    tilt[2, 3] = 2.0
    plane = wall_at(0.0)
    slanted = type(plane)(plane.mesh.transformed(tilt), plane.material, 3, 1)
    depth = Renderer(scene_of([slanted])).depth_image(np.eye(4), intrinsics=SMALL_K)
    x = (np.arange(SMALL_K.width) - SMALL_K.cx) / SMALL_K.fx
    np.testing.assert_allclose(depth, np.broadcast_to(2.0 / (1 - 0.5 * x), depth.shape), rtol=1e-5)


def test_labels_and_instances_are_those_of_the_part_hit() -> None:
    parts = [
        wall_at(5.0, label=3, instance=1),
        box_part((0.4, 0.4, 0.4), (-0.5, 0.0, 2.0), label=5, instance=7),
        box_part((0.4, 0.4, 0.4), (0.5, 0.0, 2.0), label=9, instance=8),
    ]
    view = Renderer(scene_of(parts)).render_color(np.eye(4), intrinsics=SMALL_K)

    def pixel(x: float, z: float) -> tuple[int, int]:
        return round(SMALL_K.cy), round(SMALL_K.cx + SMALL_K.fx * x / z)

    assert view.instances[pixel(-0.5, 1.8)] == 7 and view.labels[pixel(-0.5, 1.8)] == 5
    assert view.instances[pixel(0.5, 1.8)] == 8 and view.labels[pixel(0.5, 1.8)] == 9
    assert view.instances[pixel(0.0, 5.0)] == 1 and view.labels[pixel(0.0, 5.0)] == 3
    np.testing.assert_allclose(view.depth_m[pixel(-0.5, 1.8)], 1.8, rtol=1e-6)


def test_label_image_agrees_with_instances_in_a_furnished_room() -> None:
    scene = build_scene(4)
    label_of = {p.instance: p.label for p in scene.parts}
    pose = handheld_loop(scene, frames=2, fps=30.0, seed=4).world_from_camera[0]
    view = Renderer(scene).render_color(pose, intrinsics=d435_rig(160, 120).color)
    expected = np.vectorize(label_of.__getitem__)(view.instances)
    np.testing.assert_array_equal(view.labels, expected)
    assert view.instances.min() > 0  # a closed room: every ray hits something


@pytest.mark.parametrize("camera", ["color", "depth"])
def test_backprojected_depth_lands_on_the_mesh(camera: str) -> None:
    # The depth camera's pose is derived here as a reader of the recording derives it (colour
    # pose and recorded extrinsics), not taken from the simulator.
    with FrameSimulator(6, width=160, height=120) as sim:
        pose = handheld_loop(sim.scene, frames=30, fps=30.0, seed=6).world_from_camera[17]
        frame = sim.render(pose)
        if camera == "color":
            k, world_from_camera, depth = sim.rig.color, pose, frame.color.depth_m
        else:
            k, depth = sim.rig.depth, frame.depth_view.depth_m
            world_from_camera = pose @ sim.rig.depth_to_color.color_from_depth
        points = transform(world_from_camera, backproject(depth, k))
        distance = mesh_distance([p.mesh for p in sim.scene.parts], points)
    assert len(points) == k.width * k.height
    assert float(np.max(distance)) < 1e-4


def test_surfaces_face_the_camera_and_are_lit() -> None:
    scene = build_scene(2)
    pose = np.eye(4)
    pose[:3, :3] = look_rotation([1.0, 0.3, -0.2])
    pose[:3, 3] = [0.0, 0.0, 1.5]
    k = Intrinsics(64, 48, 60.0, 60.0, 31.5, 23.5)
    view = Renderer(scene).render_color(pose, intrinsics=k)
    assert view.color.mean() > 60  # ambient + Lambert light, not black


def test_textures_give_orb_corners() -> None:
    import cv2

    scene = build_scene(1)
    pose = handheld_loop(scene, frames=300, fps=30.0, seed=1).world_from_camera[100]
    view = Renderer(scene).render_color(pose, intrinsics=d435_rig().color)
    gray = cv2.cvtColor(view.color, cv2.COLOR_RGB2GRAY)
    keypoints = cv2.ORB.create(nfeatures=1000).detect(gray, None)
    assert len(keypoints) >= 500


def test_bright_white_surfaces_saturate_instead_of_wrapping() -> None:
    white = Material("noise", (1.0, 1.0, 1.0), contrast=0.0)
    plane = plane_grid((-1.0, -1.0, 1.0), (0.0, 2.0, 0.0), (2.0, 0.0, 0.0), cell_m=0.05)
    scene = scene_of([PlacedPart(plane, white, 3, 1)])
    lit = Scene(0, scene.room_m, scene.parts, scene.instance_names, np.zeros((1, 3)), scene.path)
    color = Renderer(lit).render_color(np.eye(4), intrinsics=SMALL_K).color
    # Ambient 0.45 + Lambert 0.6 > 1 head-on: clipped to white, never wrapped around to dark.
    assert color[20:40, 30:50].min() >= 250


def test_depth_registered_with_the_extrinsics_matches_the_colour_depth() -> None:
    # What the processor does with an unaligned recording: depth pixels -> colour camera.
    with FrameSimulator(6) as sim:
        pose = handheld_loop(sim.scene, frames=30, fps=30.0, seed=6).world_from_camera[17]
        frame = sim.render(pose)
    kc, kd = sim.rig.color, sim.rig.depth
    points = transform(
        sim.rig.depth_to_color.color_from_depth, backproject(frame.depth_view.depth_m, kd)
    )
    u = np.rint(points[:, 0] / points[:, 2] * kc.fx + kc.cx).astype(int)
    v = np.rint(points[:, 1] / points[:, 2] * kc.fy + kc.cy).astype(int)
    inside = (u >= 0) & (u < kc.width) & (v >= 0) & (v < kc.height)
    error = np.abs(points[inside, 2] - frame.color.depth_m[v[inside], u[inside]])
    # Nearest-pixel rounding leaves ~1 mm; extrinsics applied the wrong way round leave ~6 mm.
    assert float(np.median(error)) < 0.0025
    assert float(np.mean(error < 0.01)) > 0.9
