"""Generator 3 of labelled test clouds: ray-cast rooms, a 3-D error process (issue 12).

Independent of generators 1 (benchmarks/synthetic_office.py) and 2 (tests/helpers_refine_sim.py):
furniture from Open3D primitive meshes (benchmarks/gen3_shapes.py, gen3_layout.py) is ray cast
with `open3d.t.geometry.RaycastingScene` from the poses of someone walking the room with a
D435-like camera (87 x 58 degrees, 0.3-4 m, depth noise sigma = k z^2, flying pixels at depth
edges), then averaged into voxels of `spacing_m` as a fused map would be: density falls with
range, undersides and backs are missing. The truth is the mesh each point came from; phase-I
labels come from benchmarks/gen3_errors.py (missed patches, bleeding, blobs, swapped objects,
boundary speckle, flying pixels). Structure (labels 1-3) is unlabelled (0) in phase I, as the
network labels only objects.

`python -m benchmarks.generator3 [SEED] [SPACING_M]` prints the scene's counts.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
import open3d as o3d

from benchmarks.gen3_errors import ERROR_NAMES, Gen3Errors, apply_errors
from benchmarks.gen3_layout import Room, camera_path, furnish, structure
from benchmarks.gen3_shapes import Item
from process.cloud import LabelledCloud

__all__ = ["ERROR_NAMES", "Gen3Errors", "Gen3Scene", "gen3_scene"]
_HFOV, _VFOV = np.radians(87.0), np.radians(58.0)
_MIN_M = 0.3


@dataclass(frozen=True)
class Gen3Scene:
    """A labelled cloud (phase I), the truth per point and gravity-up, like generators 1 and 2."""

    cloud: LabelledCloud  # labels = the error process's phase-I labels
    truth: npt.NDArray[np.uint8]  # (N,) true label; 0 for flying pixels
    up: npt.NDArray[np.float64]  # (3,) gravity-up in the cloud's frame
    instances: npt.NDArray[np.int32]  # (N,) true object (item) id, 0 for flying pixels
    item_labels: npt.NDArray[np.uint8]  # (items + 1,) class of each item id placed; [0] = 0
    errors: npt.NDArray[np.uint8]  # (N,) error family that set the phase-I label (ERROR_NAMES)


@dataclass
class _Hits:
    points: npt.NDArray[np.float64]  # (M, 3)
    part: npt.NDArray[np.int64]  # (M,) mesh id, -1 for a flying pixel
    seen: npt.NDArray[np.int64]  # (M,) mesh id in front (the part itself unless flying)
    parts: list[tuple[int, int, bool]] = field(default_factory=list)  # label, instance, leaf


def gen3_scene(
    *,
    seed: int = 0,
    spacing_m: float = 0.01,
    noise_1m_m: float = 0.001,
    max_range_m: float = 3.5,
    flying_rate: float = 0.1,
    views: int = 40,
    foliage_keep: float = 0.5,
    errors: Gen3Errors | None = None,
    rotate: bool = False,
) -> Gen3Scene:
    """Return a random furnished room as a fused labelled cloud with phase-I label errors.

    Args:
        seed: everything (room, layout, camera path, noise, errors) follows from it.
        spacing_m: voxel size of the fused map; 0.016 m gives ~60k object points, 0.01 m
            ~200k, 0.006 m ~500k (they vary by room).
        noise_1m_m: depth noise sigma at 1 m; it grows with the square of the depth.
        max_range_m: depth beyond this is dropped, as fusion truncates it.
        flying_rate: chance that a pixel at a depth edge (> 10 cm) becomes a flying pixel.
        views: camera poses along the walk.
        foliage_keep: share of leaf voxels kept (thin leaves rarely survive fusion).
        errors: the error process's rates and sizes; Gen3Errors() by default.
        rotate: express the cloud in a random frame (up is then not +z), as SLAM maps are.

    Raises:
        ValueError: `spacing_m` outside 3 mm..10 cm (the voxel keys hold 16,384 cells a side).
    """
    if not 0.003 <= spacing_m <= 0.1:
        raise ValueError(f"spacing_m must be 0.003..0.1 m, got {spacing_m}; pick a map voxel size")
    # a stream each for the room, the sensor, the errors and the rest: one change keeps the others
    rng, sensor, errs, misc = (
        np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(4)
    )
    room = Room(rng.uniform(4.5, 7.0), rng.uniform(4.0, 6.0), rng.uniform(2.5, 3.0))
    layout = furnish(room, rng)
    items = structure(room, rng) + layout.items
    poses = camera_path(room, layout.free, rng, views)
    hits = _raycast(items, poses, spacing_m, (noise_1m_m, max_range_m, flying_rate), sensor)
    points, part, seen = _fuse(hits, spacing_m, foliage_keep, sensor)
    table = np.array([p[:2] for p in hits.parts] + [(0, 0)], np.int64)  # row -1: flying
    truth, instances = table[part, 0].astype(np.uint8), table[part, 1].astype(np.int32)
    labels, family = apply_errors(
        points, truth, instances, table[seen, 0].astype(np.uint8), errors or Gen3Errors(), errs
    )
    up = np.array([0.0, 0.0, 1.0])
    if rotate:
        rot = _random_rotation(misc)
        points, up = points @ rot.T + misc.uniform(-3, 3, 3), rot @ up
    colors = _colors(instances, misc)
    cloud = LabelledCloud(points.astype(np.float32), colors, labels)
    placed = np.array([0] + [item.label for item in items], np.uint8)
    return Gen3Scene(cloud, truth, up, instances, placed, family)


def _raycast(
    items: list[Item],
    poses: list[npt.NDArray[np.float64]],
    spacing_m: float,
    sensor: tuple[float, float, float],
    rng: np.random.Generator,
) -> _Hits:
    """Cast a D435-like depth image from each pose; keep noisy hits within range."""
    scene = o3d.t.geometry.RaycastingScene()
    hits = _Hits(np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros(0, np.int64))
    for instance, item in enumerate(items, 1):
        for k, mesh in enumerate(item.meshes):
            leaf = bool(item.leaves[k]) if item.leaves else False
            scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
            hits.parts.append((item.label, instance, leaf))
    if len(hits.parts) >= 8191:  # _fuse packs the mesh id into 13 bits
        raise ValueError(f"at most 8,190 meshes per room, got {len(hits.parts)}; furnish less")
    step = spacing_m / 2.0  # one ray per voxel at 2 m
    width, height = int(_HFOV / step), int(_VFOV / step)
    fx, fy = width / 2 / np.tan(_HFOV / 2), height / 2 / np.tan(_VFOV / 2)
    intrinsics = o3d.core.Tensor.from_numpy(
        np.array([[fx, 0, width / 2], [0, fy, height / 2], [0, 0, 1]])
    )
    chunks = []
    for pose in poses:
        extrinsics = o3d.core.Tensor.from_numpy(np.linalg.inv(pose))
        rays = scene.create_rays_pinhole(intrinsics, extrinsics, width, height)
        answer = scene.cast_rays(rays)
        t = answer["t_hit"].numpy().astype(np.float64)
        gid = answer["geometry_ids"].numpy().astype(np.int64)
        dirs = rays.numpy()[..., 3:].astype(np.float64)
        chunks.append(_depth_image(pose, t, gid, dirs, sensor, rng))
    hits.points = np.concatenate([c[0] for c in chunks])
    hits.part = np.concatenate([c[1] for c in chunks])
    hits.seen = np.concatenate([c[2] for c in chunks])
    return hits


def _depth_image(
    pose: npt.NDArray[np.float64],
    t: npt.NDArray[np.float64],
    gid: npt.NDArray[np.int64],
    dirs: npt.NDArray[np.float64],
    sensor: tuple[float, float, float],
    rng: np.random.Generator,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Return one view's points, part ids and seen part ids (flying pixels at depth edges).

    `sensor` is (noise sigma at 1 m, maximum range, flying-pixel chance at a depth edge).
    """
    noise_1m_m, max_range_m, flying_rate = sensor
    depth = t * (dirs @ pose[:3, 2])  # along the optical axis
    valid = np.isfinite(depth) & (depth > _MIN_M) & (depth < max_range_m)
    depth = np.where(valid, depth, 0.0)
    depth = depth + rng.normal(0.0, 1.0, depth.shape) * noise_1m_m * depth**2
    part, seen = gid.copy(), gid.copy()
    right = np.zeros_like(valid)  # a mixed pixel where depth jumps by > 10 cm to the right
    jump = valid[:, :-1] & valid[:, 1:] & (np.abs(depth[:, 1:] - depth[:, :-1]) > 0.1)
    right[:, :-1] = jump & (rng.random(jump.shape) < flying_rate)
    fly = np.flatnonzero(right)
    near = np.minimum(depth.flat[fly], depth.flat[fly + 1])
    front = np.where(depth.flat[fly] <= depth.flat[fly + 1], gid.flat[fly], gid.flat[fly + 1])
    mix = rng.uniform(0.2, 0.8, len(fly))
    depth.flat[fly] = near + mix * np.abs(depth.flat[fly + 1] - depth.flat[fly])
    part.flat[fly], seen.flat[fly] = -1, front
    z = dirs @ pose[:3, 2]
    points = pose[:3, 3] + dirs * (depth / np.where(valid, z, 1.0))[..., None]
    return points[valid], part[valid], seen[valid]


def _fuse(
    hits: _Hits, spacing_m: float, foliage_keep: float, rng: np.random.Generator
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Average hits into voxels: per voxel, the mesh with the most hits wins (mean position)."""
    cell = np.floor((hits.points - hits.points.min(0)) / spacing_m).astype(np.int64)
    voxel = (cell[:, 0] << 28) | (cell[:, 1] << 14) | cell[:, 2]  # < 2^42
    group = voxel * 8192 + (hits.part + 1)
    keys, inverse, counts = np.unique(group, return_inverse=True, return_counts=True)
    sums = np.zeros((len(keys), 3))
    np.add.at(sums, inverse, hits.points)
    seen = np.zeros(len(keys), np.int64)
    seen[inverse] = hits.seen
    order = np.lexsort((-counts, keys // 8192))
    first = order[np.unique(keys[order] // 8192, return_index=True)[1]]
    part = keys[first] % 8192 - 1
    points = sums[first] / counts[first, None]
    leaf = np.array([p[2] for p in hits.parts] + [False])[part]
    keep = ~leaf | (rng.random(len(part)) < foliage_keep)
    return points[keep], part[keep], seen[first][keep]


def _random_rotation(rng: np.random.Generator) -> npt.NDArray[np.float64]:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def _colors(instances: npt.NDArray[np.int32], rng: np.random.Generator) -> npt.NDArray[np.uint8]:
    """Return a plain colour per object with a little shading noise."""
    palette = rng.integers(60, 220, (int(instances.max()) + 1, 3))
    shade = rng.normal(0, 8, (len(instances), 3))
    return np.clip(palette[instances] + shade, 0, 255).astype(np.uint8)


def main(argv: list[str]) -> int:
    """Generate one room and print its counts per error family; 2 on bad arguments."""
    try:
        seed = int(argv[0]) if argv else 0
        spacing = float(argv[1]) if len(argv) > 1 else 0.01
        scene = gen3_scene(seed=seed, spacing_m=spacing)
    except ValueError as err:
        print(f"usage: python -m benchmarks.generator3 [SEED] [SPACING_M]: {err}", file=sys.stderr)
        return 2
    objects = int((scene.truth >= 4).sum())
    print(f"{len(scene.cloud):,} points, {objects:,} on objects")
    for code, name in enumerate(ERROR_NAMES):
        print(f"  {name}: {int((scene.errors == code).sum()):,}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
