"""Generator 3's rooms: structure (floor, walls with a door recess, ceiling) and a random layout.

Furniture stands against walls and in the middle, touching walls and each other: desks with
monitors, things and a swivel chair (often someone on it), a meeting table with chairs pushed
under it, a sofa, bookcases, plants, standing people, bins and boxes. A 5 cm occupancy grid keeps
footprints apart; chairs under tables and people on seats are placed without it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from benchmarks import gen3_shapes as sh
from benchmarks.gen3_shapes import Item, box

CEILING, FLOOR, WALL = 1, 2, 3
_CELL_M = 0.05


@dataclass(frozen=True)
class Room:
    """Interior size in metres; x along width, y along depth, z up, floor at z = 0."""

    w: float
    d: float
    h: float


def structure(room: Room, rng: np.random.Generator) -> list[Item]:
    """Return floor, ceiling and the four walls (one with a recessed door) as items."""
    w, d, h, t = room.w, room.d, room.h, 0.1
    items = [Item(FLOOR, [box((w + 0.2, d + 0.2, t), (w / 2, d / 2, -t / 2))], (w, d)),
             Item(CEILING, [box((w + 0.2, d + 0.2, t), (w / 2, d / 2, h + t / 2))], (w, d)),
             Item(WALL, [box((t, d, h), (-t / 2, d / 2, h / 2))], (t, d)),
             Item(WALL, [box((t, d, h), (w + t / 2, d / 2, h / 2))], (t, d)),
             Item(WALL, [box((w, t, h), (w / 2, d + t / 2, h / 2))], (w, t))]  # fmt: skip
    door = rng.uniform(0.6, w - 1.5)  # left edge of a 0.9 m x 2.1 m door in the y = 0 wall
    parts = [box((door, t, h), (door / 2, -t / 2, h / 2)),
             box((w - door - 0.9, t, h), ((w + door + 0.9) / 2, -t / 2, h / 2)),
             box((0.9, t, h - 2.1), (door + 0.45, -t / 2, (h + 2.1) / 2)),
             box((0.9, 0.04, 2.1), (door + 0.45, -t - 0.02, 1.05))]  # fmt: skip
    items.append(Item(WALL, parts, (w, t)))
    return items


class Layout:
    """Places items in a room, keeping their footprints apart on a 5 cm grid."""

    def __init__(self, room: Room, rng: np.random.Generator) -> None:
        self.room, self.rng = room, rng
        self.free = np.ones((int(room.w / _CELL_M), int(room.d / _CELL_M)), bool)
        self.items: list[Item] = []

    def _cells(self, item: Item, x: float, y: float, yaw: float) -> tuple[np.ndarray, bool]:
        hx, hy = item.half
        u, v = np.meshgrid(
            np.arange(-hx, hx + 1e-9, _CELL_M / 2), np.arange(-hy, hy + 1e-9, _CELL_M / 2)
        )
        c, s = np.cos(yaw), np.sin(yaw)
        px, py = x + c * u - s * v, y + s * u + c * v
        ij = np.stack([px, py], -1).reshape(-1, 2) // _CELL_M
        inside = bool(np.all((ij >= 0) & (ij < self.free.shape)))
        return ij.astype(int), inside  # fmt: skip

    def put(
        self, item: Item, x: float, y: float, yaw: float, z: float = 0.0, *, check: bool = True
    ) -> Item | None:
        """Place `item` if its footprint is free (or `check` is off); return it placed."""
        ij, inside = self._cells(item, x, y, yaw)
        if check and not (inside and self.free[ij[:, 0], ij[:, 1]].all()):
            return None
        if inside:
            self.free[ij[:, 0], ij[:, 1]] = False
        placed = item.placed(x, y, yaw, z)
        self.items.append(placed)
        return placed  # fmt: skip

    def against_wall(self, item: Item, tries: int = 40) -> tuple[float, float, float] | None:
        """Place `item` with its back (local -y) on a random wall; return (x, y, yaw)."""
        w, d, hy = self.room.w, self.room.d, item.half[1]
        for _ in range(tries):
            side = int(self.rng.integers(4))
            along = self.rng.uniform(0.0, 1.0)
            x, y, yaw = [
                (along * w, hy + 0.01, 0.0),
                (along * w, d - hy - 0.01, np.pi),
                (hy + 0.01, along * d, -np.pi / 2),
                (w - hy - 0.01, along * d, np.pi / 2),
            ][side]
            if self.put(item, x, y, yaw) is not None:
                return x, y, yaw
        return None  # fmt: skip

    def anywhere(
        self, item: Item, margin: float = 0.0, tries: int = 40
    ) -> tuple[float, float, float] | None:
        """Place `item` at a random free spot, at least `margin` from the walls."""
        for _ in range(tries):
            x = self.rng.uniform(margin, self.room.w - margin)
            y = self.rng.uniform(margin, self.room.d - margin)
            yaw = self.rng.uniform(-np.pi, np.pi)
            if self.put(item, x, y, yaw) is not None:
                return x, y, yaw
        return None  # fmt: skip


def _local(pose: tuple[float, float, float], u: float, v: float) -> tuple[float, float]:
    x, y, yaw = pose
    return x + np.cos(yaw) * u - np.sin(yaw) * v, y + np.sin(yaw) * u + np.cos(yaw) * v


def _on_top(lay: Layout, base: Item, pose: tuple[float, float, float], n: int) -> None:
    """Stand `n` small things on `base`'s top, away from its back edge."""
    for _ in range(n):
        u = lay.rng.uniform(-0.8, 0.8) * base.half[0]
        v = lay.rng.uniform(-0.5, 0.7) * base.half[1]
        lay.put(
            sh.small_thing(lay.rng),
            *_local(pose, u, v),
            lay.rng.uniform(0, 6.3),
            base.top_m,
            check=False,
        )


def _desk(lay: Layout) -> None:
    rng = lay.rng
    desk = sh.l_desk(rng) if rng.random() < 0.4 else sh.rect_table(rng, rng.uniform(1.2, 1.6), 0.7)
    pose = lay.against_wall(desk)
    if pose is None:
        return
    hx, hy = desk.half
    n = int(rng.integers(1, 3))
    for k in range(n):
        at = _local(pose, (k - (n - 1) / 2) * 0.62, -hy + 0.15)
        lay.put(sh.monitor(rng), *at, pose[2], desk.top_m, check=False)
    _on_top(lay, desk, pose, int(rng.integers(0, 4)))
    if rng.random() < 0.3:
        lay.put(
            sh.plant(rng, small=True),
            *_local(pose, hx * 0.8, -hy + 0.2),
            0.0,
            desk.top_m,
            check=False,
        )
    chair = sh.office_chair(rng)
    at, yaw = (
        _local(pose, rng.uniform(-0.3, 0.3), -hy + 1.06),
        pose[2] + np.pi + rng.uniform(-0.4, 0.4),
    )
    if lay.put(chair, *at, yaw) is not None and rng.random() < 0.6:
        lay.put(sh.person(rng, seat_m=chair.top_m), *at, yaw, check=False)  # fmt: skip


def _meeting(lay: Layout) -> None:
    rng = lay.rng
    table = sh.round_table(rng) if rng.random() < 0.4 else sh.rect_table(rng)
    pose = lay.anywhere(table, margin=1.2)
    if pose is None:
        return
    _on_top(lay, table, pose, int(rng.integers(1, 5)))
    hx, hy = table.half
    spots = [
        (0.0, -hy - 0.12, 0.0),
        (0.0, hy + 0.12, np.pi),
        (-hx - 0.12, 0.0, -np.pi / 2),
        (hx + 0.12, 0.0, np.pi / 2),
    ]
    for k in rng.permutation(4)[: rng.integers(2, 5)]:
        u, v, yaw = spots[k]
        chair = sh.plain_chair(rng) if rng.random() < 0.7 else sh.office_chair(rng)
        at, turn = (
            _local(pose, u + rng.uniform(-0.1, 0.1), v),
            pose[2] + yaw + rng.uniform(-0.3, 0.3),
        )
        lay.put(chair, *at, turn, check=False)
        if rng.random() < 0.35:
            lay.put(sh.person(rng, seat_m=chair.top_m), *at, turn, check=False)  # fmt: skip


def furnish(room: Room, rng: np.random.Generator) -> Layout:
    """Return a random furnished layout of `room` (objects only, labels 4..10)."""
    lay = Layout(room, rng)
    for _ in range(int(rng.integers(1, 3))):
        _desk(lay)
    _meeting(lay)
    pose = lay.against_wall(sh.sofa(rng))
    if pose is not None and rng.random() < 0.5:
        lay.put(
            sh.person(rng, seat_m=0.45),
            *_local(pose, rng.uniform(-0.4, 0.4), 0.05),
            pose[2],
            check=False,
        )
    for _ in range(int(rng.integers(1, 3))):
        lay.against_wall(sh.shelf(rng))
    for _ in range(int(rng.integers(1, 4))):
        lay.against_wall(sh.plant(rng))
    for _ in range(int(rng.integers(1, 3))):
        lay.anywhere(sh.person(rng), margin=0.6)
    for _ in range(int(rng.integers(1, 4))):
        lay.against_wall(sh.floor_clutter(rng))
    return lay  # fmt: skip


def camera_path(room: Room, free: np.ndarray, rng: np.random.Generator, n: int) -> list[np.ndarray]:
    """Return `n` world_from_camera poses (4x4) of someone walking a loop and looking around."""
    inset = min(1.0, room.w / 3, room.d / 3)
    corners = np.array(
        [
            [inset, inset],
            [room.w - inset, inset],
            [room.w - inset, room.d - inset],
            [inset, room.d - inset],
        ]
    )
    poses = []
    for t in np.linspace(0, 4, n, endpoint=False):
        a, b = corners[int(t)], corners[(int(t) + 1) % 4]
        for _ in range(20):  # not inside a standing person or a bookcase
            xy = a + (b - a) * (t % 1) + rng.normal(0, 0.2, 2)
            i, j = np.clip((xy // _CELL_M).astype(int), 0, np.array(free.shape) - 1)
            if free[i, j]:
                break
        to_centre = np.array([room.w / 2, room.d / 2]) - xy
        yaw = np.arctan2(to_centre[1], to_centre[0]) + rng.uniform(-1.0, 1.0)
        pitch = rng.uniform(-0.7, -0.1)
        poses.append(_look(np.array([*xy, rng.uniform(1.2, 1.6)]), yaw, pitch))
    return poses  # fmt: skip


def _look(eye: np.ndarray, yaw: float, pitch: float) -> np.ndarray:
    """Return world_from_camera for an optical frame (x right, y down, z forward)."""
    fwd = np.array([np.cos(yaw) * np.cos(pitch), np.sin(yaw) * np.cos(pitch), np.sin(pitch)])
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(fwd, right)
    pose = np.eye(4)
    pose[:3, :3] = np.stack([right, down, fwd], 1)
    pose[:3, 3] = eye
    return pose
