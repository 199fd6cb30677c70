"""Furnish a room: a dining group in the middle, a sofa, a desk, plants, a person and clutter."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import numpy.typing as npt

from capture.recording import Label
from capture.sim import furniture as fu
from capture.sim import props
from capture.sim.placement import Placer, wall_pose

Rng = np.random.Generator
TRIES = 40
OBJECT_CLASSES = frozenset(range(Label.TABLE, Label.CLUTTER + 1))


def _try(
    placer: Placer,
    make: Callable[[], tuple[fu.Assembly, float, npt.ArrayLike]],
    *,
    on_path_ok: bool = False,
) -> tuple[fu.Assembly, npt.NDArray[np.float64]] | None:
    """Propose (assembly, yaw, position) up to TRIES times; return the first that fits."""
    for _ in range(TRIES):
        assembly, yaw, position = make()
        world_from_object = placer.place(
            assembly, yaw_rad=yaw, position=position, on_path_ok=on_path_ok
        )
        if world_from_object is not None:
            return assembly, world_from_object
    return None


def _on_wall(
    placer: Placer,
    rng: Rng,
    build: Callable[[], fu.Assembly],
    *,
    gap_m: float = 0.03,
    corner: bool = False,
    height_m: float = 0.0,
) -> tuple[fu.Assembly, npt.NDArray[np.float64]] | None:
    """Put an object with its back against a random wall (in a corner when `corner`)."""
    room = placer.room_m

    def make() -> tuple[fu.Assembly, float, npt.ArrayLike]:
        a = build()
        wall = int(rng.integers(4))
        length = room[0] if wall % 2 == 0 else room[1]
        width = float(a.bounds[1, 0] - a.bounds[0, 0])
        limit = length / 2 - width / 2 - 0.02
        along = float(rng.choice([-limit, limit]) if corner else rng.uniform(-limit, limit))
        yaw, xy = wall_pose(
            room, wall=wall, along_m=along, gap_m=gap_m, back_y_m=float(a.bounds[1, 1])
        )
        return a, yaw, xy + np.array([0.0, 0.0, height_m])

    return _try(placer, make)


def _on_top(
    placer: Placer,
    rng: Rng,
    table: tuple[fu.Assembly, npt.NDArray[np.float64]],
    build: Callable[[], fu.Assembly],
    *,
    back: bool = False,
) -> bool:
    """Put an object on a table top (at its back edge when `back`), facing the table's front."""
    assembly, world_from_table = table
    assert assembly.top_m is not None
    w, d, h = assembly.top_m
    yaw_table = float(np.arctan2(world_from_table[1, 0], world_from_table[0, 0]))

    def make() -> tuple[fu.Assembly, float, npt.ArrayLike]:
        a = build()
        r = float(np.max(np.abs(a.bounds[:, :2])))  # conservative radius in the table plane
        if w / 2 - r <= 0 or d / 2 - r <= 0:
            return a, 0.0, (1e3, 1e3, 0.0)  # does not fit; rejected by the room check
        y = d / 2 - r - 0.02 if back else rng.uniform(-(d / 2 - r), d / 2 - r)
        local = np.array([rng.uniform(-(w / 2 - r), w / 2 - r), y, h, 1.0])
        yaw = yaw_table + (rng.uniform(-0.3, 0.3) if back else rng.uniform(-np.pi, np.pi))
        return a, yaw, (world_from_table @ local)[:3]

    return _try(placer, make, on_path_ok=True) is not None


def _dining(placer: Placer, rng: Rng) -> tuple[fu.Assembly, npt.NDArray[np.float64]] | None:
    """Place a table near the middle of the room and chairs around it."""
    cx, cy = placer.path.center_m
    found = None
    for scale in (1.0, 0.8, 0.6):

        def make(scale: float = scale) -> tuple[fu.Assembly, float, npt.ArrayLike]:
            w = float(rng.uniform(1.0, 1.8)) * scale
            d = min(w, float(rng.uniform(0.7, 1.0)) * scale) if rng.random() < 0.8 else w
            a = fu.table(rng, width=w, depth=d, height=float(rng.uniform(0.72, 0.78)))
            xy = np.array([cx, cy]) + rng.uniform(-0.5, 0.5, 2)
            return a, float(rng.choice([0.0, np.pi / 2])), (*xy, 0.0)

        found = _try(placer, make)
        if found is not None:
            break
    if found is not None:
        _chairs_around(placer, rng, found)
    return found


def _chairs_around(
    placer: Placer, rng: Rng, table: tuple[fu.Assembly, npt.NDArray[np.float64]]
) -> None:
    """Place one or two chairs on each side of a table, facing it."""
    assembly, world_from_table = table
    assert assembly.top_m is not None
    w, d, _ = assembly.top_m
    for side in range(4):  # 0: -y, 1: +x, 2: +y, 3: -x
        span = w if side % 2 == 0 else d
        count = int(rng.integers(1, 3)) if span > 1.1 else 1
        for k in range(count):
            offset = ((k + 0.5) / count - 0.5) * span
            gap = float(rng.uniform(0.3, 0.42))
            sign = -1.0 if side in (0, 3) else 1.0
            local = (
                (offset, sign * (d / 2 + gap)) if side % 2 == 0 else (sign * (w / 2 + gap), offset)
            )
            xy = (world_from_table @ np.array([*local, 0.0, 1.0]))[:3]
            to_table = world_from_table[:2, 3] - xy[:2]
            yaw = float(np.arctan2(to_table[0], -to_table[1]) + rng.uniform(-0.15, 0.15))
            placer.place(fu.chair(rng), yaw_rad=yaw, position=xy)


def _desk(placer: Placer, rng: Rng) -> None:
    """Place a desk against a wall with a monitor, a keyboard and a chair in front."""
    desk = _on_wall(
        placer,
        rng,
        lambda: fu.table(
            rng,
            width=float(rng.uniform(1.1, 1.6)),
            depth=float(rng.uniform(0.6, 0.75)),
            height=0.74,
        ),
    )
    if desk is None:
        return
    _on_top(placer, rng, desk, lambda: fu.monitor(rng), back=True)
    _on_top(placer, rng, desk, lambda: props.keyboard(rng))
    assembly, world_from_desk = desk
    assert assembly.top_m is not None
    yaw = float(np.arctan2(world_from_desk[1, 0], world_from_desk[0, 0]) + np.pi)
    for tuck in (0.3, 0.2, 0.1, 0.0):  # push the chair under the desk as far as it goes
        local = np.array([rng.uniform(-0.2, 0.2), -assembly.top_m[1] / 2 - 0.25 + tuck, 0.0, 1.0])
        if (
            placer.place(fu.chair(rng), yaw_rad=yaw, position=(world_from_desk @ local)[:3])
            is not None
        ):
            break


def _free(placer: Placer, rng: Rng, build: Callable[[], fu.Assembly]) -> bool:
    """Place an object anywhere on the floor that is free."""
    half = np.asarray(placer.room_m[:2]) / 2

    def make() -> tuple[fu.Assembly, float, npt.ArrayLike]:
        return build(), float(rng.uniform(-np.pi, np.pi)), (*rng.uniform(-half, half), 0.0)

    return _try(placer, make) is not None


def _clutter(rng: Rng) -> fu.Assembly:
    maker = (props.bottle, props.cup, props.books, props.bottle)[int(rng.integers(4))]
    return maker(rng)


def furnish(placer: Placer, rng: Rng) -> bool:
    """Furnish the room; return whether every object class got at least one object."""
    dining = _dining(placer, rng)
    if dining is not None:
        for _ in range(int(rng.integers(2, 6))):
            _on_top(placer, rng, dining, lambda: _clutter(rng))
    _on_wall(placer, rng, lambda: fu.sofa(rng))
    _desk(placer, rng)
    tv_z = float(rng.uniform(0.9, 1.3))
    _on_wall(placer, rng, lambda: fu.wall_tv(rng), gap_m=0.02, height_m=tv_z)
    for _ in range(int(rng.integers(1, 4))):
        _on_wall(placer, rng, lambda: fu.plant(rng, tall=bool(rng.random() < 0.6)), corner=True)
    _free(placer, rng, lambda: fu.plant(rng, tall=True))
    _free(placer, rng, lambda: props.person(rng))
    for _ in range(int(rng.integers(2, 5))):
        _free(placer, rng, lambda: (props.carton if rng.random() < 0.5 else props.waste_bin)(rng))
    for _ in range(int(rng.integers(0, 3))):
        _on_wall(placer, rng, lambda: fu.chair(rng), gap_m=0.05)
    return {p.label for p in placer.parts}.issuperset(OBJECT_CLASSES)
