"""Mesh primitives (boxes, cylinders, frusta, ellipsoids) as plain vertex and triangle arrays."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import open3d as o3d


@dataclass(frozen=True, slots=True)
class Mesh:
    """A triangle mesh in some frame: vertices (N, 3) metres and triangles (M, 3) indices."""

    vertices: npt.NDArray[np.float64]  # (N, 3)
    triangles: npt.NDArray[np.int32]  # (M, 3)

    def transformed(self, matrix: npt.NDArray[np.float64]) -> Mesh:
        """Return the mesh moved by a 4x4 rigid transform."""
        return Mesh(self.vertices @ matrix[:3, :3].T + matrix[:3, 3], self.triangles)

    @property
    def bounds(self) -> npt.NDArray[np.float64]:
        """Return the axis-aligned bounds as (2, 3): min row, max row."""
        return np.stack([self.vertices.min(axis=0), self.vertices.max(axis=0)])

    def area(self) -> float:
        """Return the total surface area in square metres."""
        return float(triangle_areas(self).sum())


def _from_o3d(mesh: o3d.geometry.TriangleMesh) -> Mesh:
    return Mesh(np.asarray(mesh.vertices, np.float64), np.asarray(mesh.triangles, np.int32))


def box(size: tuple[float, float, float], *, center: tuple[float, float, float]) -> Mesh:
    """Return an axis-aligned box of `size` (x, y, z) metres centred at `center`."""
    mesh = _from_o3d(o3d.geometry.TriangleMesh.create_box(*size))
    return Mesh(mesh.vertices - np.asarray(size) / 2 + np.asarray(center), mesh.triangles)


def cylinder(
    radius: float,
    height: float,
    *,
    center: tuple[float, float, float],
    resolution: int = 16,
    top_scale: float = 1.0,
) -> Mesh:
    """Return a vertical cylinder (a frustum when `top_scale` != 1) centred at `center`."""
    mesh = _from_o3d(
        o3d.geometry.TriangleMesh.create_cylinder(radius, height, resolution=resolution, split=1)
    )
    v = mesh.vertices.copy()
    top = v[:, 2] > 0
    v[top, :2] *= top_scale
    return Mesh(v + np.asarray(center), mesh.triangles)


def ellipsoid(
    radii: tuple[float, float, float], *, center: tuple[float, float, float], resolution: int = 8
) -> Mesh:
    """Return an ellipsoid with semi-axes `radii` centred at `center`."""
    mesh = _from_o3d(o3d.geometry.TriangleMesh.create_sphere(1.0, resolution=resolution))
    return Mesh(mesh.vertices * np.asarray(radii) + np.asarray(center), mesh.triangles)


def plane_grid(
    corner: npt.ArrayLike, edge_u: npt.ArrayLike, edge_v: npt.ArrayLike, *, cell_m: float
) -> Mesh:
    """Return a parallelogram split into cells of about `cell_m`, facing cross(edge_u, edge_v)."""
    o, eu, ev = (np.asarray(a, np.float64) for a in (corner, edge_u, edge_v))
    nu = max(1, int(np.ceil(np.linalg.norm(eu) / cell_m)))
    nv = max(1, int(np.ceil(np.linalg.norm(ev) / cell_m)))
    a, b = np.meshgrid(np.linspace(0, 1, nu + 1), np.linspace(0, 1, nv + 1), indexing="ij")
    vertices = o + a.reshape(-1, 1) * eu + b.reshape(-1, 1) * ev
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    v00 = (i * (nv + 1) + j).reshape(-1)
    v10, v01, v11 = v00 + nv + 1, v00 + 1, v00 + nv + 2
    tris = np.concatenate([np.stack([v00, v10, v11], 1), np.stack([v00, v11, v01], 1)])
    return Mesh(vertices, tris.astype(np.int32))


def pose(yaw_rad: float, position: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Return the 4x4 transform of a rotation about +z by `yaw_rad` then a translation."""
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    m = np.eye(4)
    m[:2, :2] = [[c, -s], [s, c]]
    m[:3, 3] = np.asarray(position, np.float64)
    return m


def triangle_areas(mesh: Mesh) -> npt.NDArray[np.float64]:
    """Return the area of each triangle (M,) in square metres."""
    a, b, c = (mesh.vertices[mesh.triangles[:, i]] for i in range(3))
    return np.asarray(0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1), np.float64)
