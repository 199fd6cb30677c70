"""Handheld camera trajectories: a slow walk around the room's loop that returns to its start.

The camera is held at eye height and looks inwards across the room, at the furniture, with a slow
sway of yaw and pitch, a walking bob and a small handheld shake (sums of sinusoids, so the motion
is smooth at 30 fps). Long recordings walk whole laps of the loop at constant speed, as many as
fit at the walking speed (a 10-minute recording circles a 15 m loop about 20 times, as a person
scanning a room would); short ones walk out along the loop and come back on a parallel lane, so
every recording revisits its start (for loop closure) at a walking speed a person would use.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np
import numpy.typing as npt

from capture.sim.scene import Scene

SIM_EPOCH_NS: Final = 1_704_067_200_000_000_000  # 2024-01-01T00:00:00Z, the first frame's stamp
Z_UP: Final = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True, slots=True)
class Trajectory:
    """Frame stamps and the colour camera's poses."""

    stamps_ns: npt.NDArray[np.int64]  # (N,)
    world_from_camera: npt.NDArray[np.float64]  # (N, 4, 4), colour optical frame (x right, y down)


def frame_stamps_ns(frames: int, fps: float) -> npt.NDArray[np.int64]:
    """Return `frames` integer-nanosecond stamps at `fps`, starting at SIM_EPOCH_NS."""
    return SIM_EPOCH_NS + np.round(np.arange(frames) * (1e9 / fps)).astype(np.int64)


def look_rotation(forward: npt.ArrayLike, *, roll_rad: float = 0.0) -> npt.NDArray[np.float64]:
    """Return world_from_camera rotation of an optical frame looking along `forward`, z up."""
    f = np.asarray(forward, np.float64)
    f = f / np.linalg.norm(f)
    right = np.cross(f, Z_UP)
    right /= np.linalg.norm(right)
    down = np.cross(f, right)
    c, s = np.cos(roll_rad), np.sin(roll_rad)
    return np.stack([c * right + s * down, -s * right + c * down, f], axis=1)


def _rotation_vector(v: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Return the rotation matrix of a small rotation vector (Rodrigues)."""
    angle = float(np.linalg.norm(v))
    if angle < 1e-12:
        return np.eye(3)
    k = v / angle
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.asarray(np.eye(3) + np.sin(angle) * kx + (1 - np.cos(angle)) * kx @ kx, np.float64)


def _shake(
    rng: np.random.Generator, t_s: npt.NDArray[np.float64], dims: int
) -> npt.NDArray[np.float64]:
    """Return smooth unit-scale shake (N, dims): three sinusoids of 0.4-3 Hz per dimension."""
    freqs = rng.uniform(0.4, 3.0, (dims, 3))
    phases = rng.uniform(0, 2 * np.pi, (dims, 3))
    waves = np.sin(2 * np.pi * freqs[None] * t_s[:, None, None] + phases[None])
    return np.asarray(waves.sum(axis=2) / np.sqrt(1.5), np.float64)


def _arc_lookup(scene: Scene) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Return (loop points (M, 2), cumulative arc length (M,)), dense enough to interpolate.

    The superellipse's angle parameter runs fast near the axes, so positions are interpolated
    along the arc length, not along the angle.
    """
    xy = scene.path.point(np.linspace(0.0, 2 * np.pi, 100_001))
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])
    return xy, arc


def handheld_loop(
    scene: Scene, *, frames: int, fps: float, seed: int, max_speed_m_s: float = 0.5
) -> Trajectory:
    """Return a walk around the scene's loop that ends where it began."""
    rng = np.random.default_rng([seed, 7])
    t_s = np.arange(frames) / fps
    duration_s = max(frames / fps, 1e-6)
    xy, inward = _walk(scene, rng, t_s, duration_s=duration_s, max_speed_m_s=max_speed_m_s)
    eye = rng.uniform(1.35, 1.6) + 0.008 * np.sin(2 * np.pi * 1.8 * t_s)  # walking bob
    position = np.column_stack([xy, eye]) + 0.004 * _shake(rng, t_s, 3)
    forward = _look(rng, inward, 2 * np.pi * t_s / duration_s, cycles=max(1, round(duration_s / 8)))
    shake = np.deg2rad(0.5) * _shake(rng, t_s, 3)
    poses = np.tile(np.eye(4), (frames, 1, 1))
    for i in range(frames):
        poses[i, :3, :3] = look_rotation(forward[i], roll_rad=shake[i, 2]) @ _rotation_vector(
            np.array([shake[i, 0], shake[i, 1], 0.0])
        )
        poses[i, :3, 3] = position[i]
    return Trajectory(frame_stamps_ns(frames, fps), poses)


def _walk(
    scene: Scene,
    rng: np.random.Generator,
    t_s: npt.NDArray[np.float64],
    *,
    duration_s: float,
    max_speed_m_s: float,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Return floor positions (N, 2) along the loop and the inward directions (N, 2) there."""
    loop_xy, arc = _arc_lookup(scene)
    perimeter = arc[-1]
    start = rng.uniform(0, perimeter)
    direction = float(rng.choice([-1.0, 1.0]))
    phase = 2 * np.pi * t_s / duration_s
    if max_speed_m_s * duration_s >= perimeter:
        laps = int(max_speed_m_s * duration_s // perimeter)
        s, lane = laps * perimeter * t_s / duration_s, np.zeros_like(t_s)
    else:  # out along the loop on an inner lane, back on an outer one
        reach = max_speed_m_s * duration_s / 2
        lane_m = min(0.15, 0.04 * duration_s)  # sideways at most ~0.25 m/s
        s, lane = reach * (1 - np.cos(phase)) / 2, lane_m * np.sin(phase)
    along = (start + direction * s) % perimeter
    xy = np.column_stack(
        [np.interp(along, arc, loop_xy[:, 0]), np.interp(along, arc, loop_xy[:, 1])]
    )
    center = np.asarray(scene.path.center_m)
    inward = (center - xy) / np.linalg.norm(center - xy, axis=1, keepdims=True)
    return xy + lane[:, None] * inward, inward


def _look(
    rng: np.random.Generator,
    inward: npt.NDArray[np.float64],
    phase: npt.NDArray[np.float64],
    *,
    cycles: int,
) -> npt.NDArray[np.float64]:
    """Return view directions (N, 3): inwards, slightly down, with a slow periodic sway.

    The sway makes whole cycles over the recording, so the end looks where the start looked.
    """
    yaw = np.arctan2(inward[:, 1], inward[:, 0]) + rng.uniform(0.5, 0.8) * np.sin(
        cycles * phase + rng.uniform(0, 2 * np.pi)
    )
    pitch = -rng.uniform(0.15, 0.3) + 0.08 * np.sin(cycles * phase + rng.uniform(0, 2 * np.pi))
    return np.column_stack(
        [np.cos(pitch) * np.cos(yaw), np.cos(pitch) * np.sin(yaw), np.sin(pitch)]
    )
