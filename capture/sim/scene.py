"""A procedural, seedable indoor room with furniture: the simulator's exact ground truth."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np
import numpy.typing as npt

from capture.recording import Label
from capture.sim import palette as pal
from capture.sim.layout import furnish
from capture.sim.placement import LoopPath, PlacedPart, Placer
from capture.sim.shapes import plane_grid

STRUCTURE_NAMES: Final = {1: "floor", 2: "ceiling", 3: "wall", 4: "wall", 5: "wall", 6: "wall"}
PATH_CLEARANCE_M: Final = 0.5  # free space each side of the walking loop
ATTEMPTS: Final = 20
GRID_CELL_M: Final = 0.5  # room surfaces are split so lighting interpolates smoothly


@dataclass(frozen=True, slots=True)
class Scene:
    """A furnished room in world coordinates (metres, z up, floor at z = 0, room centred on 0)."""

    seed: int
    room_m: tuple[float, float, float]  # extent along x, y, z
    parts: tuple[PlacedPart, ...]
    instance_names: dict[int, str]  # instance id -> object name ("chair", "wall", ...)
    lights_m: npt.NDArray[np.float64]  # (L, 3) point lights under the ceiling
    path: LoopPath  # the camera's walking loop, kept free of furniture
    ambient: float = 0.45  # light reaching every surface
    diffuse: float = 0.6  # Lambert light of the point lights, summed
    tint: tuple[float, float, float] = (1.0, 1.0, 1.0)  # colour of the light (white balance)

    @property
    def labels(self) -> set[int]:
        """Return the set of label ids present in the scene."""
        return {p.label for p in self.parts}


def _structure(room: tuple[float, float, float], rng: np.random.Generator) -> list[PlacedPart]:
    """Return floor, ceiling and four walls, each slightly oversized so no ray leaks at corners."""
    x, y, z = room[0] / 2, room[1] / 2, room[2]
    e = 0.02
    floor_kind = ("planks", "tiles", "speckle")[int(rng.integers(3))]
    floor = pal.material(
        rng, floor_kind, (*pal.WOODS, (0.6, 0.6, 0.58)), texel_m=0.005, contrast=0.5
    )
    ceiling = pal.material(
        rng,
        ("panels", "noise")[int(rng.integers(2))],
        ((0.93, 0.93, 0.92),),
        texel_m=0.0047,
        contrast=0.25,
    )
    wall = pal.material(
        rng, ("noise", "stripes")[int(rng.integers(2))], pal.PAINTS, texel_m=0.008, contrast=0.3
    )
    xe, ye, ze = 2 * (x + e), 2 * (y + e), z + 2 * e
    grid = [  # (corner, edge_u, edge_v): cross(edge_u, edge_v) points into the room
        ((-x - e, -y - e, 0), (xe, 0, 0), (0, ye, 0)),  # floor, +z
        ((-x - e, -y - e, z), (0, ye, 0), (xe, 0, 0)),  # ceiling, -z
        ((-x - e, -y, -e), (0, 0, ze), (xe, 0, 0)),  # wall y = -Y/2, +y
        ((x, -y - e, -e), (0, 0, ze), (0, ye, 0)),  # wall x = +X/2, -x
        ((-x - e, y, -e), (xe, 0, 0), (0, 0, ze)),  # wall y = +Y/2, -y
        ((-x, -y - e, -e), (0, ye, 0), (0, 0, ze)),  # wall x = -X/2, +x
    ]
    kinds = [(floor, Label.FLOOR), (ceiling, Label.CEILING)] + [(wall, Label.WALL)] * 4
    return [
        PlacedPart(plane_grid(*g, cell_m=GRID_CELL_M), mat, label, instance)
        for instance, (g, (mat, label)) in enumerate(zip(grid, kinds, strict=True), start=1)
    ]


def _attempt(seed: int, attempt: int) -> tuple[Scene, bool]:
    rng = np.random.default_rng([seed, attempt])
    room = (
        float(rng.uniform(5.8, 8.0)),
        float(rng.uniform(5.8, 8.0)),
        float(rng.uniform(2.5, 3.0)),
    )
    margin = float(rng.uniform(1.45, 1.8))
    path = LoopPath((0.0, 0.0), (room[0] / 2 - margin, room[1] / 2 - margin))
    placer = Placer(room, path, PATH_CLEARANCE_M, next_instance=7)
    for part in _structure(room, rng):
        placer.reserve(part)
    complete = furnish(placer, rng)
    names = {**STRUCTURE_NAMES, **placer.names}
    lights = np.array([[*rng.uniform(-0.25, 0.25, 2) * room[:2], room[2] - 0.1] for _ in range(2)])
    light = np.random.default_rng([seed, attempt, 99])  # apart, so layouts do not depend on it
    ambient, diffuse = float(light.uniform(0.35, 0.55)), float(light.uniform(0.45, 0.7))
    warmth = float(light.uniform(-1.0, 1.0))  # warm (yellowish) to cool (bluish) light
    tint = (1.0 + 0.06 * warmth, 1.0, 1.0 - 0.1 * warmth)
    scene = Scene(seed, room, tuple(placer.parts), names, lights, path, ambient, diffuse, tint)
    return scene, complete


def build_scene(seed: int) -> Scene:
    """Return the furnished room of a seed; every object class (labels 4-10) is present.

    Raises:
        RuntimeError: no layout with every class was found (a bug in the layout rules).
    """
    for attempt in range(ATTEMPTS):
        scene, complete = _attempt(seed, attempt)
        if complete:
            return scene
    raise RuntimeError(f"no complete room layout for seed {seed} in {ATTEMPTS} attempts")
