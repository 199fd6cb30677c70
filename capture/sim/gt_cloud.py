"""The scene's dense labelled point cloud, for 3-D metrics: the `ground_truth_cloud.ply` attachment.

File format (binary little-endian PLY, one `vertex` element):
`x y z` float (metres, world frame), `red green blue` uchar (the rendered surface colour),
`label` uchar (RECORDING.md ids), `instance` ushort (uint16, the ids of /ground_truth/instances).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np
import numpy.typing as npt

from capture.recording import GT_CLOUD_ATTACHMENT, ply
from capture.sim.render import Renderer
from capture.sim.scene import Scene
from capture.sim.shapes import triangle_areas

PLY_DTYPE: Final = np.dtype(
    [
        ("x", "<f4"),
        ("y", "<f4"),
        ("z", "<f4"),
        ("red", "u1"),
        ("green", "u1"),
        ("blue", "u1"),
        ("label", "u1"),
        ("instance", "<u2"),
    ]
)
MIN_POINTS_PER_PART: Final = 20


@dataclass(frozen=True, slots=True)
class LabelledPoints:
    """Points on the scene's surfaces with colour, label and instance."""

    points_m: npt.NDArray[np.float32]  # (N, 3) world
    colors: npt.NDArray[np.uint8]  # (N, 3) RGB
    labels: npt.NDArray[np.uint8]  # (N,)
    instances: npt.NDArray[np.uint16]  # (N,)


def sample_scene(
    scene: Scene, *, renderer: Renderer, spacing_m: float = 0.02, seed: int = 0
) -> LabelledPoints:
    """Sample every part's surface uniformly at about one point per spacing_m^2.

    Hand-written area-weighted sampling (rather than Open3D's) so the cloud depends only on `seed`.
    Points of the room's slightly oversized walls that fall outside the room are dropped.
    """
    rng = np.random.default_rng([seed, 13])
    offsets = renderer.triangle_offsets
    rows, bary, labels, instances = [], [], [], []
    for index, part in enumerate(scene.parts):
        areas = triangle_areas(part.mesh)
        count = max(MIN_POINTS_PER_PART, round(areas.sum() / spacing_m**2))
        local = rng.choice(len(areas), size=count, p=areas / areas.sum())
        square = rng.random((count, 2))
        flip = square.sum(axis=1) > 1  # fold the unit square onto the triangle
        square[flip] = 1 - square[flip]
        rows.append(offsets[index] + local.astype(np.uint32))
        bary.append(square.astype(np.float32))
        labels.append(np.full(count, part.label, np.uint8))
        instances.append(np.full(count, part.instance, np.uint16))
    triangle = np.concatenate(rows)
    uv = np.concatenate(bary).astype(np.float32)
    points = _points(scene, triangle, uv)
    inside = np.all(np.abs(points[:, :2]) <= np.asarray(scene.room_m[:2]) / 2 + 1e-5, axis=1)
    inside &= (points[:, 2] >= -1e-5) & (points[:, 2] <= scene.room_m[2] + 1e-5)
    colors = renderer.surface_color(triangle, barycentric=uv)
    return LabelledPoints(
        points[inside].astype(np.float32),
        colors[inside],
        np.concatenate(labels)[inside],
        np.concatenate(instances)[inside],
    )


def _points(
    scene: Scene,
    triangle: npt.NDArray[np.uint32],
    uv: npt.NDArray[np.float32],
) -> npt.NDArray[np.float64]:
    """Return the world points of barycentric (u, v) on triangle rows (parts in scene order)."""
    vertices = np.concatenate([p.mesh.vertices[p.mesh.triangles] for p in scene.parts])  # (T, 3, 3)
    tri = vertices[triangle]
    u, v = uv[:, :1].astype(np.float64), uv[:, 1:].astype(np.float64)
    return np.asarray((1 - u - v) * tri[:, 0] + u * tri[:, 1] + v * tri[:, 2], np.float64)


def ply_bytes(cloud: LabelledPoints) -> bytes:
    """Encode the cloud as binary little-endian PLY (see the module docstring for the fields)."""
    data = np.empty(len(cloud.labels), PLY_DTYPE)
    data["x"], data["y"], data["z"] = cloud.points_m.T
    data["red"], data["green"], data["blue"] = cloud.colors.T
    data["label"], data["instance"] = cloud.labels, cloud.instances
    return ply.encode(data, comment="semreplay simulated ground truth")


def read_ply(data: bytes) -> npt.NDArray[np.void]:
    """Decode PLY bytes written by `ply_bytes` into a structured array of PLY_DTYPE."""
    return ply.decode(data, source=GT_CLOUD_ATTACHMENT).astype(PLY_DTYPE)
