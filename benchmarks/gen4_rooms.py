"""Generator 4's rooms: an office, a kitchen with a dining table, a living room, a meeting room.

Each room is a floor, four walls (with window holes), a ceiling over part of the room, and
furniture laid out with random jitter: chairs pushed under tables, monitors on desks, bottles on
tables, people on sofas and chairs, items against walls. Background furniture (counters, shelves,
cabinets, a fridge) has truth label 0, as in the paper's label set.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from functools import partial
from typing import Final

import numpy as np
import numpy.typing as npt
import open3d as o3d

from benchmarks import gen4_shapes as sh
from capture.recording import Label

ROOMS: Final = ("office", "kitchen", "living", "meeting")
_COLORS: Final[dict[str, sh.Vec]] = {
    "table": (0.55, 0.4, 0.25),
    "chair": (0.15, 0.17, 0.22),
    "sofa": (0.35, 0.4, 0.5),
    "tv": (0.05, 0.05, 0.06),
    "plant": (0.6, 0.35, 0.2),
    "background": (0.85, 0.84, 0.8),
}


class Room:
    """The parts of one room under construction."""

    def __init__(self, rng: np.random.Generator, size: sh.Vec) -> None:
        self.rng, (self.w, self.d, self.h) = rng, size
        self.parts: list[sh.Part] = []
        self.next_instance = 1

    def add(self, kind: str, build: Callable[[sh.Kit], sh.Kit], at: npt.NDArray[np.float64]) -> int:
        """Build one object of `kind` (a LABELS key or 'background'), place it, return its id."""
        label = sh.LABELS.get(kind, Label.UNLABELLED)
        color = _COLORS.get(kind) or tuple(self.rng.uniform(0.1, 0.9, 3))
        kit = build(sh.Kit(int(label), self.next_instance, color))
        self.parts += sh.place(kit.parts, at)
        self.next_instance += 1
        return kit.instance

    def rect(self, label: int, corners: npt.NDArray[np.float64]) -> None:
        """Add a flat rectangle (4 corners in order) as one structural instance."""
        mesh = o3d.geometry.TriangleMesh(
            o3d.utility.Vector3dVector(corners), o3d.utility.Vector3iVector([[0, 1, 2], [0, 2, 3]])
        )
        grey = (0.8, 0.8, 0.78) if label != Label.FLOOR else (0.45, 0.42, 0.4)
        self.parts.append(sh.Part(mesh, label, self.next_instance, None, grey))

    def shell(self, windows: dict[int, list[tuple[float, float, float, float]]]) -> None:
        """Add floor, a partial ceiling and four walls; windows: wall index -> (u0, u1, z0, z1)."""
        w, d, h = self.w, self.d, self.h
        self.rect(Label.FLOOR, np.array([[0, 0, 0], [w, 0, 0], [w, d, 0], [0, d, 0]], float))
        self.next_instance += 1
        cw = w * self.rng.uniform(0.55, 1.0)
        self.rect(Label.CEILING, np.array([[0, 0, h], [cw, 0, h], [cw, d, h], [0, d, h]], float))
        self.next_instance += 1
        corners = [(0.0, 0.0), (w, 0.0), (w, d), (0.0, d)]
        for i in range(4):
            a, b = np.array(corners[i]), np.array(corners[(i + 1) % 4])
            for u0, u1, z0, z1 in _wall_pieces(float(np.linalg.norm(b - a)), h, windows.get(i, [])):
                p, q = (
                    a + (b - a) / np.linalg.norm(b - a) * u0,
                    a + (b - a) / np.linalg.norm(b - a) * u1,
                )
                quad = [[p[0], p[1], z0], [q[0], q[1], z0], [q[0], q[1], z1], [p[0], p[1], z1]]
                self.rect(Label.WALL, np.array(quad, float))
            self.next_instance += 1

    def jitter(self, scale: float) -> float:
        """Return a uniform offset in [-scale, scale]."""
        return float(self.rng.uniform(-scale, scale))


def _wall_pieces(
    length: float, h: float, holes: list[tuple[float, float, float, float]]
) -> list[tuple[float, float, float, float]]:
    """Split a wall (u along it, z up) into rectangles around its window holes."""
    cuts = sorted({0.0, length, *(u for hole in holes for u in hole[:2])})
    pieces = []
    for u0, u1 in itertools.pairwise(cuts):
        z_edges = [0.0]
        for hu0, hu1, z0, z1 in holes:
            if hu0 <= u0 and u1 <= hu1:
                z_edges += [z0, z1]
        z_edges.append(h)
        pieces += [(u0, u1, z_edges[i], z_edges[i + 1]) for i in range(0, len(z_edges), 2)]
    return pieces


def desk_set(room: Room, at: npt.NDArray[np.float64], *, seated: bool) -> None:
    """A desk with its back at the local origin's -x edge, a monitor, an office chair, items."""
    rng, w, d = room.rng, 1.4 + room.jitter(0.1), 0.75
    room.add("table", lambda k: sh.table(k, w, d), at @ sh.pose(d / 2, 0))
    room.add("tv", sh.monitor, at @ sh.pose(0.15, room.jitter(0.2), 0, 0.74))
    push = -0.05 if seated else rng.uniform(-0.15, 0.3)
    chair_at = at @ sh.pose(d + 0.12 - push, room.jitter(0.2), np.pi + room.jitter(0.4))
    room.add("chair", lambda k: sh.chair(k, office=True), chair_at)
    if seated:
        room.add("person", lambda k: sh.person(k, sitting=True), chair_at)
    room.add(
        "clutter",
        lambda k: sh.bottle(k, cup=bool(rng.random() < 0.5)),
        at @ sh.pose(0.5, w / 2 - 0.15, 0, 0.74),
    )


def office(room: Room) -> None:
    """Three desks with monitors and office chairs, people, plants, a shelf and a cabinet."""
    w, d, rng = room.w, room.d, room.rng
    room.shell({2: [(1.2, 2.6, 0.9, 2.1)]})
    desk_set(room, sh.pose(0.0, d * 0.28, 0), seated=True)
    desk_set(room, sh.pose(0.0, d * 0.72, 0), seated=False)
    desk_set(room, sh.pose(w * 0.6, 0.0, np.pi / 2), seated=bool(rng.random() < 0.5))
    room.add(
        "person",
        lambda k: sh.person(k, sitting=False),
        sh.pose(w * 0.55, d * 0.6, rng.uniform(0, 6)),
    )
    room.add("plant", lambda k: sh.plant(k, rng, 1.3, pot_r=0.16), sh.pose(w - 0.3, d - 0.3))
    room.add(
        "plant",
        lambda k: sh.plant(k, rng, 0.35, pot_r=0.06),
        sh.pose(0.35, d * 0.72 - 0.55, 0, 0.74),
    )
    room.add("background", lambda k: _box(k, 0.35, 1.0, 1.9), sh.pose(w - 0.165, d * 0.35))
    room.add("background", lambda k: _box(k, 0.5, 0.8, 0.75), sh.pose(w * 0.3, d - 0.24))


def kitchen(room: Room) -> None:
    """A counter with upper cabinets and a fridge, a dining table with six chairs, people."""
    w, d, rng = room.w, room.d, room.rng
    room.shell({1: [(1.0, 2.5, 1.0, 2.2)]})
    room.add("background", lambda k: _box(k, 0.6, 3.2, 0.9), sh.pose(1.9, 0.29, np.pi / 2))
    room.add("background", lambda k: _box(k, 0.35, 3.2, 0.7, z=1.5), sh.pose(1.9, 0.165, np.pi / 2))
    room.add("background", lambda k: _box(k, 0.7, 0.7, 1.8), sh.pose(4.0, 0.34))
    for i in range(int(rng.integers(3, 6))):
        room.add(
            "clutter",
            lambda k: sh.bottle(k, cup=bool(rng.random() < 0.4)),
            sh.pose(0.6 + 0.55 * i + room.jitter(0.1), 0.35 + room.jitter(0.1), 0, 0.9),
        )
    room.add("plant", lambda k: sh.plant(k, rng, 0.4, pot_r=0.07), sh.pose(3.2, 0.3, 0, 0.9))
    table_at = sh.pose(w * 0.55 + room.jitter(0.2), d * 0.65 + room.jitter(0.15), room.jitter(0.15))
    ring_of_chairs(room, table_at, (1.6, 0.9), per_side=2, office=False, seated=1)
    room.add("table", lambda k: sh.table(k, 1.6, 0.9), table_at @ sh.pose(0, 0, np.pi / 2))
    room.add("person", lambda k: sh.person(k, sitting=False), sh.pose(1.6, 0.95, -np.pi / 2))
    table_items(room, table_at, 1.2, 0.5, int(rng.integers(2, 5)))
    room.add("plant", lambda k: sh.plant(k, rng, 1.1, pot_r=0.15), sh.pose(w - 0.3, d - 0.3))


def living(room: Room) -> None:
    """A sofa with a person on it, an armchair, a coffee table, a TV on a low cabinet, plants."""
    w, d, rng = room.w, room.d, room.rng
    room.shell({0: [(0.6, 1.8, 0.8, 2.2)], 3: [(1.5, 3.0, 0.8, 2.2)]})
    sofa_at = sh.pose(w / 2 + room.jitter(0.3), d - 0.47, -np.pi / 2)
    room.add("sofa", lambda k: sh.sofa(k, 2.1), sofa_at)
    room.add(
        "person", lambda k: sh.person(k, sitting=True, seat_h=0.52), sofa_at @ sh.pose(0.05, 0.45)
    )
    room.add("sofa", lambda k: sh.sofa(k, 1.5), sh.pose(0.47, d / 2, 0))
    room.add("chair", lambda k: _armchair(k), sh.pose(w - 0.6, d * 0.55, np.pi + room.jitter(0.3)))
    coffee_at = sh.pose(w / 2, d - 1.7, 0)
    room.add("table", lambda k: sh.table(k, 1.1, 0.6, 0.42), coffee_at)
    table_items(room, coffee_at @ sh.pose(0, 0, 0, -0.32), 0.8, 0.35, 2)
    room.add(
        "plant",
        lambda k: sh.plant(k, rng, 0.35, pot_r=0.06),
        coffee_at @ sh.pose(0.1, 0.3, 0, 0.42),
    )
    room.add("background", lambda k: _box(k, 0.45, 1.6, 0.5), sh.pose(w / 2, 0.215, np.pi / 2))
    room.add("tv", lambda k: sh.monitor(k, 1.1), sh.pose(w / 2, 0.2, np.pi / 2, 0.5))
    for x, y in ((0.3, 0.3), (w - 0.3, 0.3), (w - 0.35, d - 0.35)):
        room.add(
            "plant", lambda k: sh.plant(k, rng, rng.uniform(0.9, 1.5), pot_r=0.15), sh.pose(x, y)
        )
    room.add(
        "person",
        lambda k: sh.person(k, sitting=False, height=1.65),
        sh.pose(1.8, 1.6, rng.uniform(0, 6)),
    )
    room.add("background", lambda k: _box(k, 0.35, 1.2, 1.8), sh.pose(w - 0.165, 1.5))


def meeting(room: Room) -> None:
    """A large table with many office chairs around it, seated and standing people, a wall TV."""
    w, d, rng = room.w, room.d, room.rng
    room.shell({2: [(1.0, 2.4, 0.9, 2.2), (3.6, 5.0, 0.9, 2.2)]})
    table_at = sh.pose(w / 2 + room.jitter(0.2), d / 2 + room.jitter(0.15), room.jitter(0.05))
    room.add(
        "table", lambda k: sh.table(k, 3.6, 1.3, pedestal=True), table_at @ sh.pose(0, 0, np.pi / 2)
    )
    per_side, seated = int(rng.integers(4, 6)), int(rng.integers(2, 4))
    ring_of_chairs(room, table_at, (3.6, 1.3), per_side=per_side, office=True, seated=seated)
    table_items(room, table_at, 3.0, 0.8, int(rng.integers(4, 8)))
    room.add("tv", _wall_tv, sh.pose(0.0, d / 2, 0))
    room.add("background", lambda k: _box(k, 0.5, 2.0, 0.8), sh.pose(w * 0.6, 0.24, np.pi / 2))
    room.add("plant", lambda k: sh.plant(k, rng, 1.4, pot_r=0.17), sh.pose(w - 0.3, 0.3))
    room.add("plant", lambda k: sh.plant(k, rng, 1.2, pot_r=0.15), sh.pose(w - 0.3, d - 0.3))
    for x in (1.0, w - 1.2)[: int(rng.integers(1, 3))]:
        room.add(
            "person", lambda k: sh.person(k, sitting=False), sh.pose(x, d - 0.6, rng.uniform(0, 6))
        )


def ring_of_chairs(
    room: Room,
    table_at: npt.NDArray[np.float64],
    size: tuple[float, float],
    *,
    per_side: int,
    office: bool,
    seated: int,
) -> None:
    """Chairs facing a table (long side along local x), some pushed under, `seated` occupied."""
    (length, width), poses = size, []
    for side in (-1, 1):
        for i in range(per_side):
            x = -length / 2 + (i + 0.5) * length / per_side + room.jitter(0.08)
            y = side * (width / 2 + 0.15 - room.rng.uniform(-0.25, 0.3))
            poses.append(table_at @ sh.pose(x, y, -side * np.pi / 2 + room.jitter(0.3)))
    for side in (-1, 1):
        yaw = np.pi if side > 0 else 0.0
        poses.append(table_at @ sh.pose(side * (length / 2 + 0.3), room.jitter(0.1), yaw))
    occupied = room.rng.choice(len(poses), seated, replace=False)
    for i, at in enumerate(poses):
        if i in occupied:  # pulled out to sit on
            side = -1 if i < per_side else 1
            at = at if i >= 2 * per_side else _pulled(at, table_at, side, width)
            room.add("person", lambda k: sh.person(k, sitting=True), at)
        room.add("chair", lambda k: sh.chair(k, office=office), at)


def _pulled(
    at: npt.NDArray[np.float64], table_at: npt.NDArray[np.float64], side: int, width: float
) -> npt.NDArray[np.float64]:
    """Return a side chair's pose moved to 0.3 m from the table's edge."""
    local = np.linalg.inv(table_at) @ at
    local[1, 3] = side * (width / 2 + 0.3)
    return np.asarray(table_at @ local)


def table_items(
    room: Room, table_at: npt.NDArray[np.float64], sx: float, sy: float, n: int
) -> None:
    """Bottles and cups standing on a table top of height 0.74 (the table's frame)."""
    for _ in range(n):
        cup = bool(room.rng.random() < 0.4)
        at = table_at @ sh.pose(room.jitter(sx / 2), room.jitter(sy / 2), 0, 0.74)
        room.add("clutter", partial(sh.bottle, cup=cup), at)


def _box(k: sh.Kit, depth: float, width: float, height: float, *, z: float = 0.0) -> sh.Kit:
    k.box((0, 0, z + (height - 0.01) / 2), (depth, width, height + 0.01))
    return k


def _armchair(k: sh.Kit) -> sh.Kit:
    k.box((0, 0, 0.22), (0.75, 0.75, 0.44))
    k.box((-0.3, 0, 0.6), (0.15, 0.75, 0.4))
    for y in (-0.32, 0.32):
        k.box((0.05, y, 0.55), (0.6, 0.12, 0.2))
    return k


def _wall_tv(k: sh.Kit) -> sh.Kit:
    k.box((0.03, 0, 1.4), (0.05, 1.3, 0.75))
    return k


def build_room(name: str, rng: np.random.Generator) -> Room:
    """Return the parts of room `name` (one of ROOMS) laid out with `rng`."""
    sizes = {
        "office": (5.0, 4.0),
        "kitchen": (6.0, 4.5),
        "living": (6.0, 5.0),
        "meeting": (7.0, 5.0),
    }
    w, d = sizes[name]
    room = Room(
        rng, (w + rng.uniform(-0.3, 0.3), d + rng.uniform(-0.2, 0.2), rng.uniform(2.5, 2.9))
    )
    {"office": office, "kitchen": kitchen, "living": living, "meeting": meeting}[name](room)
    return room
