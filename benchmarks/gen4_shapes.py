"""Generator 4's meshes: primitives with their solid volumes, and furniture, people and plants.

Every object is built in its own frame (origin on the floor, x forward, z up) from Open3D
primitives, then placed by `place`. A `Part` keeps its mesh, its RECORDING.md label, its object's
instance id and, for closed primitives, the solid volume that hides other surfaces inside it (a
table leg's top inside the table top, the floor under a sofa, a seated person's thighs in a
cushion).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Final

import numpy as np
import numpy.typing as npt
import open3d as o3d

from capture.recording import OBJECT_LABELS, Label

Vec = tuple[float, float, float]
FOLIAGE_DENSITY: Final = 0.3  # leaves are sampled at this share of the object density


@dataclass(frozen=True)
class Solid:
    """A closed volume: 'box' (half extents), 'cyl' (radius, radius, half height) or 'sphere'."""

    kind: str
    local_from_world: npt.NDArray[np.float64]  # (4, 4)
    half: npt.NDArray[np.float64]  # (3,)

    def contains(self, points: npt.NDArray[np.float64], margin: float) -> npt.NDArray[np.bool_]:
        """Return which points lie inside the volume by more than `margin` metres."""
        local = points @ self.local_from_world[:3, :3].T + self.local_from_world[:3, 3]
        h = self.half - margin
        inside: npt.NDArray[np.bool_]
        if self.kind == "box":
            inside = np.all(np.abs(local) < h, axis=1)
        elif self.kind == "cyl":
            radial = local[:, 0] ** 2 + local[:, 1] ** 2 < h[0] ** 2
            inside = radial & (np.abs(local[:, 2]) < h[2])
        else:
            inside = np.einsum("ij,ij->i", local, local) < h[0] ** 2
        return inside


@dataclass(frozen=True)
class Part:
    """One primitive of one object."""

    mesh: o3d.geometry.TriangleMesh
    label: int
    instance: int
    solid: Solid | None
    color: Vec  # 0..1 RGB
    thin: bool = False  # legs, stems, poles: a network often misses them whole
    density: float = 1.0  # relative sampling density

    def moved(self, world_from_obj: npt.NDArray[np.float64]) -> Part:
        """Return the part transformed by `world_from_obj` (4x4)."""
        mesh = o3d.geometry.TriangleMesh(self.mesh)
        mesh.transform(world_from_obj)
        solid = self.solid
        if solid is not None:
            moved = np.asarray(solid.local_from_world @ np.linalg.inv(world_from_obj), np.float64)
            solid = Solid(solid.kind, moved, solid.half)
        return replace(self, mesh=mesh, solid=solid)


def pose(x: float, y: float, yaw: float = 0.0, z: float = 0.0) -> npt.NDArray[np.float64]:
    """Return world_from_obj for an object at (x, y, z) turned by `yaw` radians about z."""
    c, s = np.cos(yaw), np.sin(yaw)
    t = np.eye(4)
    t[:2, :2] = [[c, -s], [s, c]]
    t[:3, 3] = (x, y, z)
    return t


def place(parts: list[Part], world_from_obj: npt.NDArray[np.float64]) -> list[Part]:
    """Return the parts of one object moved into the world."""
    return [p.moved(world_from_obj) for p in parts]


class Kit:
    """Builds the parts of one object: one label, one instance id, one colour."""

    def __init__(self, label: int, instance: int, color: Vec) -> None:
        self.label, self.instance, self.color = label, instance, color
        self.parts: list[Part] = []

    def box(self, center: Vec, size: Vec, *, thin: bool = False, color: Vec | None = None) -> None:
        """Add an axis-aligned box (in the object frame)."""
        mesh = o3d.geometry.TriangleMesh.create_box(*size)
        mesh.translate(np.asarray(center) - np.asarray(size) / 2)
        frame = np.eye(4)
        frame[:3, 3] = -np.asarray(center)
        self._add(mesh, Solid("box", frame, np.asarray(size) / 2), thin, color)

    def cyl(self, p0: Vec, p1: Vec, radius: float, *, thin: bool = False) -> None:
        """Add a closed cylinder from p0 to p1."""
        a, b = np.asarray(p0, float), np.asarray(p1, float)
        length = float(np.linalg.norm(b - a))
        rot = _rotation_z_to(b - a)
        mesh = o3d.geometry.TriangleMesh.create_cylinder(radius, length, resolution=16)
        mesh.rotate(rot, center=(0, 0, 0))
        mesh.translate((a + b) / 2)
        world_from_local = np.eye(4)
        world_from_local[:3, :3], world_from_local[:3, 3] = rot, (a + b) / 2
        half = np.array([radius, radius, length / 2])
        local_from_world = np.asarray(np.linalg.inv(world_from_local), np.float64)
        self._add(mesh, Solid("cyl", local_from_world, half), thin, None)

    def sphere(self, center: Vec, radius: float) -> None:
        """Add a sphere."""
        mesh = o3d.geometry.TriangleMesh.create_sphere(radius, resolution=12)
        mesh.translate(center)
        frame = np.eye(4)
        frame[:3, 3] = -np.asarray(center)
        self._add(mesh, Solid("sphere", frame, np.full(3, radius)), False, None)

    def leaves(self, rng: np.random.Generator, center: Vec, radii: Vec, count: int) -> None:
        """Add `count` small flat leaves, randomly turned, scattered in an ellipsoid crown."""
        verts, tris = [], []
        for i in range(count):
            direction = rng.normal(size=3)
            offset = direction / np.linalg.norm(direction) * rng.uniform(0.3, 1.0) ** (1 / 3)
            c = np.asarray(center) + offset * np.asarray(radii)
            length, width = rng.uniform(0.03, 0.07), rng.uniform(0.012, 0.03)
            rot = _rotation_z_to(rng.normal(size=3))
            ang = np.linspace(0, 2 * np.pi, 9)[:-1]
            ring = np.stack([length * np.cos(ang), width * np.sin(ang), np.zeros(8)], 1)
            verts += [c, *(ring @ rot.T + c)]
            tris += [[9 * i, 9 * i + 1 + k, 9 * i + 1 + (k + 1) % 8] for k in range(8)]
        mesh = o3d.geometry.TriangleMesh(
            o3d.utility.Vector3dVector(np.asarray(verts)), o3d.utility.Vector3iVector(tris)
        )
        part = Part(mesh, self.label, self.instance, None, (0.2, 0.5, 0.15), False, FOLIAGE_DENSITY)
        self.parts.append(part)

    def _add(
        self, mesh: o3d.geometry.TriangleMesh, solid: Solid, thin: bool, color: Vec | None
    ) -> None:
        part = Part(mesh, self.label, self.instance, solid, color or self.color, thin)
        self.parts.append(part)


def _rotation_z_to(direction: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Return a rotation taking +z onto `direction`."""
    d = direction / np.linalg.norm(direction)
    v = np.cross([0.0, 0.0, 1.0], d)
    s, c = float(np.linalg.norm(v)), float(d[2])
    rot: npt.NDArray[np.float64] = np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    if s > 1e-9:
        vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
        rot = np.eye(3) + vx + vx @ vx * ((1 - c) / s**2)
    return rot


def table(k: Kit, w: float, d: float, h: float = 0.74, *, pedestal: bool = False) -> Kit:
    """A table: a 3 cm top on four legs, or on two pedestal panels (a meeting table)."""
    k.box((0, 0, h - 0.015), (d, w, 0.03))
    if pedestal:
        for y in (-w / 3, w / 3):
            k.box((0, y, (h - 0.03) / 2 - 0.005), (d * 0.5, 0.05, h - 0.02))
        return k
    for sx in (-1, 1):
        for sy in (-1, 1):
            x, y = sx * (d / 2 - 0.05), sy * (w / 2 - 0.05)
            k.box((x, y, (h - 0.03) / 2 - 0.005), (0.05, 0.05, h - 0.02), thin=True)
    return k


def chair(k: Kit, *, office: bool = False, seat_h: float = 0.46) -> Kit:
    """A chair facing +x: seat, backrest, and four legs or an office chair's pole and star."""
    k.box((0, 0, seat_h - 0.03), (0.46, 0.46, 0.06))
    k.box((-0.22, 0, seat_h + 0.25), (0.04, 0.44, 0.42))
    if office:
        k.cyl((0, 0, 0.08), (0, 0, seat_h - 0.05), 0.025, thin=True)
        for a in np.linspace(0, 2 * np.pi, 6)[:-1]:
            k.cyl((0, 0, 0.07), (0.3 * np.cos(a), 0.3 * np.sin(a), 0.04), 0.018, thin=True)
        return k
    for sx in (-1, 1):
        for sy in (-1, 1):
            k.cyl(
                (sx * 0.2, sy * 0.2, -0.01), (sx * 0.2, sy * 0.2, seat_h - 0.05), 0.014, thin=True
            )
    return k


def sofa(k: Kit, w: float = 2.0) -> Kit:
    """A sofa facing +x: base, back, two arms and seat cushions."""
    k.box((0, 0, 0.2), (0.9, w, 0.42))
    k.box((-0.35, 0, 0.55), (0.2, w, 0.7))
    for y in (-w / 2 + 0.1, w / 2 - 0.1):
        k.box((0.05, y, 0.5), (0.8, 0.2, 0.24))
    n = 2 if w < 1.7 else 3
    for i in range(n):
        y = -w / 2 + 0.2 + (i + 0.5) * (w - 0.4) / n
        k.box((0.1, y, 0.46), (0.6, (w - 0.4) / n - 0.02, 0.12))
    return k


def person(k: Kit, *, sitting: bool, seat_h: float = 0.46, height: float = 1.75) -> Kit:
    """A person facing +x, standing at the origin or sitting on a seat of height `seat_h`."""
    s = height / 1.75
    hip = seat_h + 0.08 if sitting else 0.86 * s
    for y in (-0.1, 0.1):
        if sitting:
            k.cyl((-0.05, y, hip), (0.4, y, hip), 0.075)
            k.cyl((0.4, y, hip), (0.45, y, 0.0), 0.055)
        else:
            k.cyl((0, y, -0.01), (0, y, hip), 0.07)
    top = hip + 0.6 * s
    k.box((-0.05, 0, (hip + top) / 2), (0.22, 0.38, top - hip))
    for y in (-0.23, 0.23):
        hand = (0.3, y * 0.8, hip + 0.12) if sitting else (0.05, y * 1.1, hip - 0.05)
        k.cyl((-0.05, y, top - 0.05), hand, 0.045)
    k.cyl((-0.05, 0, top - 0.02), (-0.05, 0, top + 0.08), 0.05)
    k.sphere((-0.04, 0, top + 0.17), 0.11)
    return k


def plant(k: Kit, rng: np.random.Generator, height: float, *, pot_r: float) -> Kit:
    """A potted plant: pot, stem and a sparse crown of small leaves."""
    pot_h = pot_r * 1.8
    k.cyl((0, 0, -0.01), (0, 0, pot_h), pot_r)
    k.cyl((0, 0, pot_h), (0, 0, height * 0.75), max(0.006, pot_r * 0.1), thin=True)
    crown = height - pot_h
    radii = (crown * 0.45, crown * 0.45, crown * 0.4)
    k.leaves(rng, (0, 0, pot_h + crown * 0.6), radii, int(rng.integers(40, 90) * crown / 0.5 + 15))
    return k


def monitor(k: Kit, w: float = 0.55) -> Kit:
    """A monitor facing +x standing on its base plate (origin on the surface below)."""
    k.box((0, 0, 0.005), (0.18, 0.22, 0.012))
    k.box((-0.03, 0, 0.1), (0.03, 0.06, 0.2))
    k.box((0, 0, 0.12 + w * 0.3), (0.025, w, w * 0.6))
    return k


def bottle(k: Kit, *, cup: bool = False) -> Kit:
    """A bottle (body and neck) or a cup standing on a surface."""
    if cup:
        k.cyl((0, 0, -0.002), (0, 0, 0.1), 0.04)
        return k
    k.cyl((0, 0, -0.002), (0, 0, 0.2), 0.035)
    k.cyl((0, 0, 0.2), (0, 0, 0.28), 0.014)
    return k


OVERSAMPLE: Final = 1.6  # sample more, drop hidden surfaces, then subsample to the exact count


LABELS: Final = {
    "table": Label.TABLE,
    "chair": Label.CHAIR,
    "person": Label.PERSON,
    "plant": Label.PLANT,
    "sofa": Label.SOFA,
    "tv": Label.TV_MONITOR,
    "clutter": Label.CLUTTER,
}


def sample_parts(
    parts: list[Part],
    rng: np.random.Generator,
    object_points: int,
    other_ratio: float,
    h: float,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.intp]]:
    """Sample every part uniformly, drop hidden points, subsample to the exact counts.

    Returns the points and the index of the part each lies on. Object parts (labels 4-10) give
    exactly `object_points` points; structure (labels 1-3) and background furniture (label 0)
    share `other_ratio` times that at one density. `parts[0]` must be the floor.
    """
    area = np.array([p.mesh.get_surface_area() * p.density for p in parts])
    is_object = np.array([p.label in OBJECT_LABELS for p in parts])
    quota = {True: object_points, False: round(other_ratio * object_points)}
    per_m2 = np.where(
        is_object, *(OVERSAMPLE * quota[k] / area[is_object == k].sum() for k in (True, False))
    )
    chunks, owners = [], []
    for i, part in enumerate(parts):
        n = int(rng.poisson(area[i] * per_m2[i]))
        if n == 0:
            continue
        o3d.utility.random.seed(int(rng.integers(2**31)))
        chunks.append(np.asarray(part.mesh.sample_points_uniformly(n).points))
        owners.append(np.full(n, i))
    points, part_of = np.concatenate(chunks), np.concatenate(owners)
    keep = _visible(points, part_of, parts, h)
    for k, want in quota.items():
        idx = np.flatnonzero(keep & (is_object[part_of] == k))
        if len(idx) > want:
            keep[rng.choice(idx, len(idx) - want, replace=False)] = False
    return points[keep], part_of[keep]


def _visible(
    points: npt.NDArray[np.float64], part_of: npt.NDArray[np.intp], parts: list[Part], h: float
) -> npt.NDArray[np.bool_]:
    """Return which points are neither inside another part's solid nor outside the room."""
    keep = (points[:, 2] > -0.003) & (points[:, 2] < h + 0.003)
    floor = points[part_of == 0]
    # a face pressed against the floor or a wall (a sofa's back, a cabinet's bottom) is never
    # seen by a camera: only structure lies on the room's boundary
    on_boundary = points[:, 2] < 0.003
    for axis in (0, 1):  # walls stand at the extremes of the floor's x and y
        low, high = floor[:, axis].min(), floor[:, axis].max()
        keep &= (points[:, axis] > low - 0.003) & (points[:, axis] < high + 0.003)
        on_boundary |= (points[:, axis] < low + 0.003) | (points[:, axis] > high - 0.003)
    structure = np.array([Label.CEILING <= p.label <= Label.WALL for p in parts])
    keep &= ~on_boundary | structure[part_of]
    order = np.argsort(points[:, 0])
    xs = points[order, 0]
    for i, part in enumerate(parts):
        if part.solid is None:
            continue
        box = part.mesh.get_axis_aligned_bounding_box()
        a, b = np.searchsorted(xs, [box.min_bound[0], box.max_bound[0]])
        cand = order[a:b]
        cand = cand[
            np.all((points[cand] >= box.min_bound) & (points[cand] <= box.max_bound), axis=1)
        ]
        cand = cand[part_of[cand] != i]
        keep[cand[part.solid.contains(points[cand], 0.002)]] = False
    return keep


def part_colors(
    parts: list[Part], part_of: npt.NDArray[np.intp], rng: np.random.Generator
) -> npt.NDArray[np.uint8]:
    """Each part's colour with a little per-point variation."""
    base = np.array([p.color for p in parts])[part_of] * 255
    return np.clip(base + rng.normal(0, 8, base.shape), 0, 255).astype(np.uint8)
