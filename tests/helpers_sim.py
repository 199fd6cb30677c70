"""Helpers for the simulator's tests: tiny hand-made scenes with known geometry."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from capture.recording.frames import Intrinsics
from capture.sim.placement import LoopPath, PlacedPart
from capture.sim.scene import Scene
from capture.sim.shapes import Mesh, box, plane_grid
from capture.sim.textures import Material

GRAY = Material("noise", (0.5, 0.5, 0.5))
SMALL_K = Intrinsics(80, 60, 77.0, 77.0, 39.5, 29.5)


def scene_of(parts: list[PlacedPart]) -> Scene:
    """Return a Scene holding just these parts (a 20 m room for the bounds, one light)."""
    names = {p.instance: f"part{p.instance}" for p in parts}
    lights = np.array([[0.0, 0.0, 3.0]])
    return Scene(
        0, (20.0, 20.0, 5.0), tuple(parts), names, lights, LoopPath((0.0, 0.0), (1.0, 1.0))
    )


def wall_at(z_m: float, *, label: int = 3, instance: int = 1) -> PlacedPart:
    """Return a 40 m square plane z = z_m (world) facing -z, towards a camera at the origin."""
    mesh = plane_grid((-20.0, -20.0, z_m), (0.0, 40.0, 0.0), (40.0, 0.0, 0.0), cell_m=5.0)
    return PlacedPart(mesh, GRAY, label, instance)


def box_part(
    size: tuple[float, float, float],
    center: tuple[float, float, float],
    *,
    label: int,
    instance: int,
) -> PlacedPart:
    """Return a box part."""
    return PlacedPart(box(size, center=center), GRAY, label, instance)


def backproject(depth_m: npt.NDArray[np.float32], k: Intrinsics) -> npt.NDArray[np.float64]:
    """Return camera-frame points (N, 3) of the pixels with depth > 0."""
    v, u = np.nonzero(depth_m > 0)
    z = depth_m[v, u].astype(np.float64)
    return np.stack([(u - k.cx) / k.fx * z, (v - k.cy) / k.fy * z, z], axis=1)


def transform(
    matrix: npt.NDArray[np.float64], points: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]:
    """Return points (N, 3) moved by a 4x4 transform."""
    return np.asarray(points @ matrix[:3, :3].T + matrix[:3, 3], np.float64)


def mesh_distance(meshes: list[Mesh], points: npt.NDArray[np.float64]) -> npt.NDArray[np.float32]:
    """Return each point's distance to the nearest triangle of the meshes (Open3D)."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    for mesh in meshes:
        scene.add_triangles(
            o3d.core.Tensor.from_numpy(mesh.vertices.astype(np.float32)),
            o3d.core.Tensor.from_numpy(mesh.triangles.astype(np.uint32)),
        )
    query = o3d.core.Tensor.from_numpy(points.astype(np.float32))
    return np.asarray(scene.compute_distance(query).numpy(), np.float32)
