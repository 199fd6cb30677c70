"""Placing assemblies in a room without intersections and off the camera's walking loop."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from capture.sim.furniture import Assembly
from capture.sim.shapes import Mesh, pose
from capture.sim.textures import Material

# Parts of different objects may touch (a bottle on a table) but not overlap more than this.
TOUCH_TOLERANCE_M = 1e-4


@dataclass(frozen=True, slots=True)
class LoopPath:
    """The closed walking loop: a superellipse around the room centre, in the floor plane."""

    center_m: tuple[float, float]
    semi_axes_m: tuple[float, float]
    exponent: float = 4.0

    def point(self, theta: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """Return the (N, 2) floor points of the loop at angles theta (radians)."""
        th = np.asarray(theta, np.float64)
        c, s = np.cos(th), np.sin(th)
        e = 2.0 / self.exponent
        x = self.center_m[0] + self.semi_axes_m[0] * np.sign(c) * np.abs(c) ** e
        y = self.center_m[1] + self.semi_axes_m[1] * np.sign(s) * np.abs(s) ** e
        return np.stack([x, y], axis=-1)


@dataclass(frozen=True, slots=True)
class PlacedPart:
    """A part in world coordinates with its material, label and instance id."""

    mesh: Mesh
    material: Material
    label: int
    instance: int


@dataclass(slots=True)
class Placer:
    """Accept an assembly at a pose only if it fits the room, misses the path and all others."""

    room_m: tuple[float, float, float]  # (x, y, z) extent; the room spans +-x/2, +-y/2, 0..z
    path: LoopPath
    clearance_m: float
    parts: list[PlacedPart] = field(default_factory=list)
    names: dict[int, str] = field(default_factory=dict)
    next_instance: int = 1
    _boxes: list[npt.NDArray[np.float64]] = field(default_factory=list)
    _path_xy: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 2)))

    def __post_init__(self) -> None:
        self._path_xy = self.path.point(np.linspace(0.0, 2 * np.pi, 720))

    def reserve(self, part: PlacedPart) -> None:
        """Add a part that is placed unconditionally (room structure)."""
        self.parts.append(part)

    def place(
        self,
        assembly: Assembly,
        *,
        yaw_rad: float,
        position: npt.ArrayLike,
        on_path_ok: bool = False,
    ) -> npt.NDArray[np.float64] | None:
        """Place the assembly if it fits; return its world_from_object (4x4) or None."""
        world_from_object = pose(yaw_rad, position)
        meshes = [mesh.transformed(world_from_object) for mesh, _ in assembly.parts]
        boxes = np.stack([m.bounds for m in meshes])  # (P, 2, 3)
        if not self._fits(boxes, on_path_ok=on_path_ok):
            return None
        instance = self.next_instance
        self.next_instance += 1
        self.names[instance] = assembly.name
        for mesh, (_, mat) in zip(meshes, assembly.parts, strict=True):
            self.parts.append(PlacedPart(mesh, mat, assembly.label, instance))
        self._boxes.extend(boxes)
        return world_from_object

    def _fits(self, boxes: npt.NDArray[np.float64], *, on_path_ok: bool) -> bool:
        half = np.asarray(self.room_m[:2]) / 2 - 0.01
        lo, hi = boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0)
        if np.any(lo[:2] < -half) or np.any(hi[:2] > half) or hi[2] > self.room_m[2] - 0.05:
            return False
        if not on_path_ok and self._path_distance(lo[:2], hi[:2]) < self.clearance_m:
            return False
        if not self._boxes:
            return True
        others = np.stack(self._boxes)  # (Q, 2, 3)
        overlap = np.minimum(boxes[:, None, 1], others[None, :, 1]) - np.maximum(
            boxes[:, None, 0], others[None, :, 0]
        )  # (P, Q, 3)
        return not bool(np.any(np.all(overlap > TOUCH_TOLERANCE_M, axis=-1)))

    def _path_distance(self, lo: npt.NDArray[np.float64], hi: npt.NDArray[np.float64]) -> float:
        center, half = (lo + hi) / 2, (hi - lo) / 2
        outside = np.maximum(np.abs(self._path_xy - center) - half, 0.0)
        return float(np.linalg.norm(outside, axis=1).min())


def wall_pose(
    room_m: tuple[float, float, float], *, wall: int, along_m: float, gap_m: float, back_y_m: float
) -> tuple[float, npt.NDArray[np.float64]]:
    """Return (yaw, position) that puts an object's back (+y, at local y = back_y_m) on a wall.

    Walls are numbered 0: y = -Y/2, 1: x = +X/2, 2: y = +Y/2, 3: x = -X/2; `along_m` runs along
    the wall from its centre.
    """
    inward = np.array([[0.0, 1.0], [-1.0, 0.0], [0.0, -1.0], [1.0, 0.0]])[wall]
    tangent = np.array([-inward[1], inward[0]])
    half = np.asarray(room_m[:2]) / 2
    wall_point = -inward * half  # the wall's centre in the floor plane
    yaw = float(np.arctan2(inward[0], -inward[1]))
    xy = wall_point + inward * (gap_m + back_y_m) + tangent * along_m
    return yaw, np.array([xy[0], xy[1], 0.0])
