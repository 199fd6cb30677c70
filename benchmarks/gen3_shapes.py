"""Generator 3's furniture: Open3D primitive meshes grouped into labelled objects.

Each builder returns an `Item` in its own frame (origin on the floor at the footprint's centre,
front towards +y); `Item.placed` turns and moves it into the room. Labels are RECORDING.md's:
4 table, 5 chair, 6 person, 7 plant, 8 sofa, 9 tv monitor, 10 clutter.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
import open3d as o3d

Mesh = o3d.geometry.TriangleMesh
TABLE, CHAIR, PERSON, PLANT, SOFA, MONITOR, CLUTTER = 4, 5, 6, 7, 8, 9, 10


@dataclass
class Item:
    """One object: its meshes, its class, its footprint (x, y half sizes) and top height."""

    label: int
    meshes: list[Mesh]
    half: tuple[float, float]  # footprint half sizes along local x and y, metres
    top_m: float = 0.0  # height of its top surface (things can stand on it)
    leaves: list[bool] = field(default_factory=list)  # per mesh: thin foliage

    def placed(self, x: float, y: float, yaw: float, z: float = 0.0) -> Item:
        """Return the item turned by `yaw` about up and moved to (x, y, z)."""
        rot = Mesh.get_rotation_matrix_from_xyz((0.0, 0.0, yaw))
        meshes = []
        for mesh in self.meshes:
            moved = Mesh(mesh)
            moved.rotate(rot, center=(0.0, 0.0, 0.0))
            moved.translate((x, y, z))
            meshes.append(moved)
        return Item(self.label, meshes, self.half, self.top_m + z, self.leaves)


def box(size: tuple[float, float, float], center: tuple[float, float, float]) -> Mesh:
    """Return an axis-aligned box of `size` centred at `center`."""
    mesh = Mesh.create_box(*size)
    mesh.translate(np.asarray(center) - np.asarray(size) / 2)
    return mesh


def cyl(radius: float, height: float, center: tuple[float, float, float], res: int = 16) -> Mesh:
    """Return an upright cylinder centred at `center`."""
    mesh = Mesh.create_cylinder(radius, height, res, 1)
    mesh.translate(center)
    return mesh


def ball(radius: float, center: tuple[float, float, float]) -> Mesh:
    """Return a sphere."""
    mesh = Mesh.create_sphere(radius, 10)
    mesh.translate(center)
    return mesh


def rod(a: npt.ArrayLike, b: npt.ArrayLike, radius: float) -> Mesh:
    """Return a cylinder from point a to point b."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    axis = b - a
    length = float(np.linalg.norm(axis))
    mesh = Mesh.create_cylinder(radius, length, 8, 1)
    z = np.array([0.0, 0.0, 1.0])
    v, c = np.cross(z, axis / length), float(z @ axis / length)
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    rot = np.eye(3) + vx + vx @ vx / (1 + c) if c > -0.999 else np.diag([1.0, -1.0, -1.0])
    mesh.rotate(rot, center=(0.0, 0.0, 0.0))
    mesh.translate((a + b) / 2)
    return mesh


def rect_table(rng: np.random.Generator, w: float = 0.0, d: float = 0.0) -> Item:
    """Return a four-legged rectangular table (or a desk when w, d are given)."""
    w, d = w or rng.uniform(1.2, 2.0), d or rng.uniform(0.7, 1.0)
    h = rng.uniform(0.72, 0.76)
    parts = [box((w, d, 0.03), (0, 0, h - 0.015))]
    for sx in (-1, 1):
        for sy in (-1, 1):
            parts.append(
                box(
                    (0.05, 0.05, h - 0.03),
                    (sx * (w / 2 - 0.06), sy * (d / 2 - 0.06), (h - 0.03) / 2),
                )
            )
    return Item(TABLE, parts, (w / 2, d / 2), h)  # fmt: skip


def round_table(rng: np.random.Generator) -> Item:
    """Return a round table on one column."""
    r, h = rng.uniform(0.45, 0.65), rng.uniform(0.72, 0.76)
    parts = [cyl(r, 0.03, (0, 0, h - 0.015), 40), cyl(0.04, h, (0, 0, h / 2)),
             cyl(0.28, 0.03, (0, 0, 0.015), 24)]  # fmt: skip
    return Item(TABLE, parts, (r, r), h)


def l_desk(rng: np.random.Generator) -> Item:
    """Return an L-shaped desk on panel sides (its back along local -y)."""
    w, d, h = rng.uniform(1.4, 1.8), 0.7, 0.74
    rw = rng.uniform(0.8, 1.1)
    parts = [box((w, d, 0.03), (0, 0, h - 0.015)),
             box((0.5, rw, 0.03), (w / 2 - 0.25, d / 2 + rw / 2, h - 0.015)),
             box((0.025, d, h - 0.03), (-w / 2 + 0.02, 0, (h - 0.03) / 2)),
             box((0.5, 0.025, h - 0.03), (w / 2 - 0.25, d / 2 + rw - 0.02, (h - 0.03) / 2)),
             box((w - 0.1, 0.02, 0.4), (0, -d / 2 + 0.03, h - 0.25))]  # fmt: skip
    for part in parts:
        part.translate((0.0, -rw / 2, 0.0))  # the footprint's centre at the origin
    return Item(TABLE, parts, (w / 2, d / 2 + rw / 2), h)


def office_chair(rng: np.random.Generator) -> Item:
    """Return a swivel chair: five-star base, column, seat, back (facing +y)."""
    seat = rng.uniform(0.44, 0.5)
    parts = []
    for k in range(5):
        a = 2 * np.pi * k / 5
        tip = (0.3 * np.cos(a), 0.3 * np.sin(a))
        parts += [rod((0, 0, 0.09), (*tip, 0.07), 0.018), ball(0.025, (*tip, 0.025))]
    parts += [cyl(0.025, seat - 0.1, (0, 0, 0.09 + (seat - 0.1) / 2)),
              box((0.48, 0.46, 0.08), (0, 0, seat)),
              box((0.44, 0.05, 0.5), (0, -0.24, seat + 0.33))]  # fmt: skip
    if rng.random() < 0.6:
        for sx in (-1, 1):
            parts += [box((0.05, 0.25, 0.03), (sx * 0.26, -0.02, seat + 0.22)),
                      box((0.03, 0.03, 0.2), (sx * 0.26, -0.1, seat + 0.12))]  # fmt: skip
    return Item(CHAIR, parts, (0.32, 0.32), seat + 0.04)


def plain_chair(rng: np.random.Generator) -> Item:
    """Return a four-legged chair (facing +y)."""
    s = rng.uniform(0.42, 0.46)
    parts = [box((s, s, 0.04), (0, 0, 0.45))]
    for sx in (-1, 1):
        for sy in (-1, 1):
            parts.append(box((0.03, 0.03, 0.43), (sx * (s / 2 - 0.03), sy * (s / 2 - 0.03), 0.215)))
    parts.append(box((s, 0.03, 0.42), (0, -s / 2 + 0.015, 0.68)))
    return Item(CHAIR, parts, (s / 2, s / 2), 0.47)


def sofa(rng: np.random.Generator) -> Item:
    """Return a sofa with arms and seat cushions (back along local -y)."""
    w, d = rng.uniform(1.6, 2.2), rng.uniform(0.8, 0.95)
    parts = [box((w, d, 0.3), (0, 0, 0.15)), box((w, 0.22, 0.82), (0, -d / 2 + 0.11, 0.41))]
    parts += [box((0.2, d, 0.62), (sx * (w / 2 - 0.1), 0, 0.31)) for sx in (-1, 1)]
    n = 2 if w < 1.9 else 3
    cw = (w - 0.4) / n
    parts += [
        box((cw - 0.01, d - 0.24, 0.12), (-w / 2 + 0.2 + cw * (k + 0.5), 0.11, 0.36))
        for k in range(n)
    ]
    return Item(SOFA, parts, (w / 2, d / 2), 0.42)  # fmt: skip


def person(rng: np.random.Generator, seat_m: float = 0.0) -> Item:
    """Return a standing person, or one sitting at height `seat_m` (facing +y)."""
    s = rng.uniform(0.9, 1.08)
    hip = seat_m + 0.06 if seat_m else 0.9 * s
    parts = []
    for sx in (-0.1, 0.1):
        if seat_m:
            parts += [
                rod((sx, -0.05, hip), (sx, 0.4, hip), 0.075),
                rod((sx, 0.42, hip), (sx, 0.45, 0.05), 0.055),
            ]
        else:
            parts.append(rod((sx, 0, 0.02), (sx, 0, hip), 0.07))
        parts.append(box((0.1, 0.24, 0.07), (sx, 0.08 + (0.4 if seat_m else 0), 0.035)))
    parts += [
        box((0.38 * s, 0.22, 0.58 * s), (0, -0.03, hip + 0.29 * s)),
        cyl(0.05, 0.1, (0, -0.03, hip + 0.63 * s)),
        ball(0.11 * s, (0, -0.02, hip + 0.78 * s)),
    ]
    for sx in (-1, 1):
        sh = (sx * 0.23 * s, -0.03, hip + 0.52 * s)
        hand = (sx * 0.25 * s, 0.3, hip + 0.2) if seat_m else (sx * 0.27 * s, 0.05, hip - 0.08)
        parts.append(rod(sh, hand, 0.045))
    return Item(PERSON, parts, (0.28, 0.28), 0.0)  # fmt: skip


def plant(rng: np.random.Generator, small: bool = False) -> Item:
    """Return a potted plant: pot, thin stems, sparse clusters of small flat leaves."""
    r = rng.uniform(0.07, 0.1) if small else rng.uniform(0.12, 0.2)
    ph = r * rng.uniform(1.2, 2.0)
    parts = [cyl(r, ph, (0, 0, ph / 2), 24)]
    leaves = [False]
    top = (rng.uniform(0.25, 0.4) if small else rng.uniform(0.6, 1.5)) + ph
    for _ in range(rng.integers(3, 8)):
        tip = np.array([*rng.normal(0, 0.12 if small else 0.25, 2), top * rng.uniform(0.6, 1)])
        parts.append(rod((0, 0, ph), tip, 0.004))
        leaves.append(False)
        for _ in range(rng.integers(4, 10)):
            at = tip + rng.normal(0, 0.06, 3) - (0, 0, rng.uniform(0, 0.25))
            leaf = box((rng.uniform(0.05, 0.1), rng.uniform(0.025, 0.045), 0.003), (0, 0, 0))
            leaf.rotate(Mesh.get_rotation_matrix_from_xyz(rng.uniform(-1.2, 1.2, 3)), (0, 0, 0))
            leaf.translate(at)
            parts.append(leaf)
            leaves.append(True)
    return Item(PLANT, parts, (r, r), 0.0, leaves)


def monitor(rng: np.random.Generator) -> Item:
    """Return a flat screen on a neck and foot (facing +y)."""
    w, h = rng.uniform(0.5, 0.65), rng.uniform(0.3, 0.4)
    parts = [box((w, 0.03, h), (0, 0, 0.12 + h / 2)), box((0.05, 0.03, 0.16), (0, -0.04, 0.08)),
             box((0.22, 0.18, 0.015), (0, -0.02, 0.0075))]  # fmt: skip
    return Item(MONITOR, parts, (w / 2, 0.1), 0.0)


def shelf(rng: np.random.Generator) -> Item:
    """Return a bookcase (back along local -y) with books on its shelves."""
    w, d, h = rng.uniform(0.8, 1.2), rng.uniform(0.3, 0.4), rng.uniform(1.2, 2.0)
    parts = [box((0.02, d, h), (sx * (w / 2 - 0.01), 0, h / 2)) for sx in (-1, 1)]
    parts.append(box((w, 0.01, h), (0, -d / 2 + 0.005, h / 2)))
    levels = np.linspace(0.05, h - 0.01, int(h / 0.35) + 1)
    for z in levels:
        parts.append(box((w - 0.04, d, 0.02), (0, 0, z)))
        x = -w / 2 + 0.03
        while z < h - 0.2 and x < w / 2 - 0.1 and rng.random() < 0.9:
            bw = rng.uniform(0.02, 0.06)
            bh = rng.uniform(0.15, 0.26)
            parts.append(box((bw, d * 0.8, bh), (x + bw / 2, 0.02, z + 0.01 + bh / 2)))
            x += bw + rng.uniform(0, 0.05)
    return Item(CLUTTER, parts, (w / 2, d / 2), h)


def small_thing(rng: np.random.Generator) -> Item:
    """Return a bottle, a cup, a book pile or a box (clutter) to stand on something."""
    kind = rng.integers(4)
    if kind == 0:
        r, h = rng.uniform(0.03, 0.045), rng.uniform(0.2, 0.32)
        return Item(
            CLUTTER,
            [cyl(r, h * 0.7, (0, 0, h * 0.35)), cyl(r * 0.4, h * 0.3, (0, 0, h * 0.85))],
            (r, r),
        )
    if kind == 1:
        return Item(CLUTTER, [cyl(0.04, 0.1, (0, 0, 0.05))], (0.04, 0.04))
    w, d, h = rng.uniform(0.15, 0.35), rng.uniform(0.15, 0.3), rng.uniform(0.05, 0.2)
    return Item(CLUTTER, [box((w, d, h), (0, 0, h / 2))], (w / 2, d / 2), h)  # fmt: skip


def floor_clutter(rng: np.random.Generator) -> Item:
    """Return a waste bin or a cardboard box for the floor."""
    if rng.random() < 0.5:
        r, h = rng.uniform(0.13, 0.18), rng.uniform(0.3, 0.4)
        return Item(CLUTTER, [cyl(r, h, (0, 0, h / 2), 24)], (r, r))
    w, d, h = rng.uniform(0.3, 0.6), rng.uniform(0.3, 0.5), rng.uniform(0.25, 0.5)
    return Item(CLUTTER, [box((w, d, h), (0, 0, h / 2))], (w / 2, d / 2), h)
