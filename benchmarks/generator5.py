"""Generator 5: labelled clouds fused from per-view 2-D label images that err like a network.

Written blind to the refinement (issue 12). One of generator 4's rooms (gen4_rooms.py) is ray
cast with Open3D's RaycastingScene from a walking D435-like camera (87 x 58 degrees, 424 x 240
pixels, 0.3-4 m, depth noise sigma = 0.0015 z^2, flying pixels at depth edges). In each view a
simulated network (gen5_net.py) labels the pixels with image-space errors: bleeding outlines,
eroded thin parts, missed blobs, whole-segment confusion and speckle. Every pixel is
back-projected with its noisy depth into voxels of `voxel_m`; a voxel's point is the centroid of
its hits, its truth the majority truth of its hits (flying pixels are 0) and its phase-I label
the majority of its hits' label votes (0 wins ties). The scene is then turned to a random
orientation; `up` says where up is.

SIZES holds the voxel size per room for about 60k, 200k and 500k object points (the living room's
sofas and the meeting room's big table make those rooms twice as full); the 500k size uses the
DENSE camera (640 x 360, 100 views). Measured on seeds 0-7 (0-3 for 500k): 42k-68k object points
of 0.25M-0.64M, 187k-245k of 0.96M-1.45M, 495k-540k of 2.4M-3.7M; voxels hit once are dropped.
Phase-I object F1 (process.evaluate.label_metrics) lands at 0.65-0.82.

    python -m benchmarks.generator5 SEED [VOXEL_M | 60k | 200k | 500k]
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from typing import Final

import numpy as np
import numpy.typing as npt
import open3d as o3d
from scipy.spatial.transform import Rotation

from benchmarks import gen4_shapes as sh
from benchmarks.gen4_rooms import ROOMS, Room, build_room
from benchmarks.gen5_net import Gen5Errors, Network, View
from capture.recording import LABEL_NAMES, NUM_LABELS, OBJECT_LABELS
from process.cloud import LabelledCloud

SIZES: Final[dict[str, dict[str, float]]] = {  # voxel_m per room for about so many object points
    "60k": {"office": 0.0175, "kitchen": 0.0175, "living": 0.03, "meeting": 0.024},
    "200k": {"office": 0.0076, "kitchen": 0.0083, "living": 0.0123, "meeting": 0.0112},
    "500k": {"office": 0.0062, "kitchen": 0.0063, "living": 0.0095, "meeting": 0.0083},
}
_FOV_DEG: Final = (87.0, 58.0)
_RANGE_M: Final = (0.3, 4.0)
_EDGE_M: Final = 0.1  # a depth step this large is an edge where flying pixels appear


@dataclass(frozen=True)
class Gen5Scene:
    """A fused labelled cloud (phase-I labels), its truth and gravity-up."""

    cloud: LabelledCloud
    truth: npt.NDArray[np.uint8]  # (N,) RECORDING.md labels; 0 for background and flying pixels
    up: npt.NDArray[np.float64]  # (3,) unit vector in the cloud's frame
    room: str


@dataclass(frozen=True)
class Camera:
    """The walking depth camera."""

    views: int = 80
    width: int = 424
    height: int = 240
    noise_k: float = 0.0015  # depth noise sigma = noise_k * z^2 (metres)
    flying_rate: float = 0.1  # chance a pixel at a depth edge lands between the two surfaces

    @property
    def focal(self) -> tuple[float, float, float, float]:
        """Return fx, fy, cx, cy in pixels."""
        hfov, vfov = np.radians(_FOV_DEG) / 2
        fx, fy = self.width / 2 / np.tan(hfov), self.height / 2 / np.tan(vfov)
        return float(fx), float(fy), (self.width - 1) / 2, (self.height - 1) / 2


def gen5_scene(
    *,
    seed: int,
    voxel_m: float,
    room: str | None = None,
    camera: Camera | None = None,
    errors: Gen5Errors | None = None,
    min_hits: int = 2,
    rotate: bool = True,
) -> Gen5Scene:
    """Return one room's fused labelled cloud; `room` defaults to ROOMS[seed % 4].

    Args:
        seed: seeds the layout, the walk, the depth noise, the network and the orientation.
        voxel_m: fusion voxel size in metres (0.005-0.03; see SIZES).
        room: one of ROOMS.
        camera: views, image size and depth noise; Camera() by default.
        errors: the network's error rates; Gen5Errors() by default, Gen5Errors.none() for none.
        min_hits: voxels hit fewer times are dropped (most flying pixels and stray noise).
        rotate: turn and shift the scene to a random frame (else z is up, the floor at z = 0).

    Raises:
        ValueError: an unknown room, or a voxel size outside 3 mm-10 cm.
    """
    name = room or ROOMS[seed % len(ROOMS)]
    if name not in ROOMS or not 0.003 <= voxel_m <= 0.1:
        raise ValueError(
            f"expected a room in {ROOMS} and voxel_m in 0.003..0.1; got {name!r}, {voxel_m}"
        )
    cam = camera or Camera()
    rng_room, rng_walk, rng_depth, rng_net, rng_frame = (
        np.random.default_rng(s) for s in np.random.SeedSequence([seed, 5]).spawn(5)
    )
    built = build_room(name, rng_room)
    caster = Caster(built.parts)
    network = Network(built.parts, errors or Gen5Errors(), rng_net)
    lowest = np.min([p.mesh.get_min_bound() for p in built.parts], axis=0)
    hits = _Hits(lowest - 5.0, voxel_m)
    for pose in walk(built, caster, rng_walk, cam.views):
        view = caster.render(pose, cam)
        hits.add(view, network.predict(view, rng_net), cam, rng_depth)
    points, truth, labels, colors = hits.fuse(caster.colors, min_hits)
    up = np.array([0.0, 0.0, 1.0])
    if rotate:
        rot = Rotation.random(random_state=rng_frame)
        points, up = rot.apply(points) + rng_frame.uniform(-3, 3, 3), rot.apply(up)
    cloud = LabelledCloud(points.astype(np.float32), colors, labels)
    return Gen5Scene(cloud, truth, up, name)


DENSE: Final = Camera(views=100, width=640, height=360)  # for the 500k size


def sized_scene(seed: int, size: str) -> Gen5Scene:
    """Return the scene of `seed` at a SIZES size ("60k", "200k", "500k"; DENSE for 500k)."""
    if size not in SIZES:
        raise ValueError(f"expected a size in {tuple(SIZES)}; got {size!r}")
    room = ROOMS[seed % len(ROOMS)]
    camera = DENSE if size == "500k" else Camera()
    return gen5_scene(seed=seed, voxel_m=SIZES[size][room], camera=camera)


class Caster:
    """Ray casts a room's parts: truth label, instance, part and z-depth per pixel."""

    def __init__(self, parts: list[sh.Part]) -> None:
        self.scene = o3d.t.geometry.RaycastingScene()
        for part in parts:
            self.scene.add_triangles(
                o3d.core.Tensor.from_numpy(np.asarray(part.mesh.vertices, np.float32)),
                o3d.core.Tensor.from_numpy(np.asarray(part.mesh.triangles, np.uint32)),
            )
        self.labels = np.array([p.label for p in parts] + [0], np.uint8)  # [-1]: no hit
        self.instances = np.array([p.instance for p in parts] + [0], np.int32)
        self.colors = np.array([p.color for p in parts] + [(0, 0, 0)]) * 255.0

    def clearance(self, point: npt.NDArray[np.float64]) -> float:
        """Return the point's (3,) distance to the nearest surface."""
        query = o3d.core.Tensor.from_numpy(np.asarray(point[None], np.float32))
        return float(self.scene.compute_distance(query).numpy()[0])

    def render(self, world_from_camera: npt.NDArray[np.float64], cam: Camera) -> View:
        """Cast one ray per pixel centre (camera z = 1, so the hit distance is z-depth)."""
        fx, fy, cx, cy = cam.focal
        u, v = np.meshgrid(np.arange(cam.width), np.arange(cam.height))
        dirs = np.stack([(u - cx) / fx, (v - cy) / fy, np.ones(u.shape)], -1).reshape(-1, 3)
        rays = np.empty((len(dirs), 6), np.float32)
        rays[:, :3] = world_from_camera[:3, 3]
        rays[:, 3:] = dirs @ world_from_camera[:3, :3].T
        out = self.scene.cast_rays(o3d.core.Tensor.from_numpy(rays))
        gid = out["geometry_ids"].numpy().astype(np.int64)
        miss = gid >= len(self.labels) - 1
        part = np.where(miss, -1, gid).reshape(cam.height, cam.width).astype(np.int32)
        depth = np.where(miss, 0.0, out["t_hit"].numpy()).reshape(part.shape).astype(np.float32)
        return View(
            self.labels[part], self.instances[part], part, depth, world_from_camera, cam.focal
        )


def walk(
    room: Room, caster: Caster, rng: np.random.Generator, n: int
) -> list[npt.NDArray[np.float64]]:
    """Return `n` world_from_camera poses of someone walking round the room, looking around."""
    lo = min(1.1, room.w / 3, room.d / 3)
    hi_x, hi_y = room.w - lo, room.d - lo
    corners = np.array([[lo, lo], [hi_x, lo], [hi_x, hi_y], [lo, hi_y]])
    poses = []
    for t in np.linspace(0, 4, n, endpoint=False) + rng.uniform(0, 4 / max(n, 1)):
        a, b = corners[int(t) % 4], corners[(int(t) + 1) % 4]
        for tries in range(30):  # keep out of people, plants and shelves
            xy = a + (b - a) * (t % 1) + rng.normal(0, 0.25 / (1 + tries // 10), 2)
            eye = np.array([*xy, rng.uniform(1.2, 1.7)])
            if caster.clearance(eye) > 0.35:
                break
        to_centre = np.array([room.w / 2, room.d / 2]) - xy
        yaw = np.arctan2(to_centre[1], to_centre[0]) + rng.uniform(-1.4, 1.4)
        poses.append(_look(eye, yaw, rng.uniform(-0.75, -0.05), rng.normal(0, 0.03)))
    return poses


def _look(
    eye: npt.NDArray[np.float64], yaw: float, pitch: float, roll: float
) -> npt.NDArray[np.float64]:
    """Return world_from_camera for an optical frame (x right, y down, z forward)."""
    fwd = np.array([np.cos(yaw) * np.cos(pitch), np.sin(yaw) * np.cos(pitch), np.sin(pitch)])
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(fwd, right)
    c, s = np.cos(roll), np.sin(roll)
    pose = np.eye(4)
    pose[:3, :3] = np.stack([c * right + s * down, c * down - s * right, fwd], 1)
    pose[:3, 3] = eye
    return pose


class _Hits:
    """Every view's back-projected pixels: voxel, position, truth, label vote and part."""

    def __init__(self, origin: npt.NDArray[np.float64], voxel_m: float) -> None:
        self.origin, self.voxel_m = origin, voxel_m
        self.keys: list[npt.NDArray[np.int64]] = []
        self.points: list[npt.NDArray[np.float32]] = []
        self.truth: list[npt.NDArray[np.uint8]] = []
        self.votes: list[npt.NDArray[np.uint8]] = []
        self.parts: list[npt.NDArray[np.int32]] = []

    def add(
        self, view: View, pred: npt.NDArray[np.uint8], cam: Camera, rng: np.random.Generator
    ) -> None:
        """Add one view's pixels with noisy depth; flying pixels have truth 0."""
        depth, flying = noisy_depth(view.depth_m, cam, rng)
        keep = (depth > _RANGE_M[0]) & (depth < _RANGE_M[1]) & (view.parts >= 0)
        fx, fy, cx, cy = cam.focal
        r, u = np.nonzero(keep)
        z = depth[keep]
        local = np.stack([(u - cx) / fx * z, (r - cy) / fy * z, z], 1)
        pose = view.world_from_camera
        world = local @ pose[:3, :3].T + pose[:3, 3]
        cell = np.floor((world - self.origin) / self.voxel_m).astype(np.int64)
        self.keys.append((cell[:, 0] << 42) | (cell[:, 1] << 21) | cell[:, 2])
        self.points.append(world.astype(np.float32))
        self.truth.append(np.where(flying, 0, view.labels)[keep].astype(np.uint8))
        self.votes.append(pred[keep])
        self.parts.append(view.parts[keep])

    def fuse(
        self, part_colors: npt.NDArray[np.float64], min_hits: int
    ) -> tuple[
        npt.NDArray[np.float64], npt.NDArray[np.uint8], npt.NDArray[np.uint8], npt.NDArray[np.uint8]
    ]:
        """Return per voxel hit `min_hits` times or more: centroid, truth, label, colour.

        The truth is the majority of the hits' truths, the label the majority of their label
        votes (0 wins ties), the colour the mean of their parts' colours.
        """
        _, inverse, count = np.unique(
            np.concatenate(self.keys), return_inverse=True, return_counts=True
        )
        n = len(count)
        points = np.concatenate(self.points)
        centroid = np.stack([np.bincount(inverse, points[:, a], n) for a in range(3)], 1)
        rgb = part_colors[np.concatenate(self.parts)]
        color = np.stack([np.bincount(inverse, rgb[:, a], n) for a in range(3)], 1)
        truth = _majority(inverse, np.concatenate(self.truth), n, ties_to_zero=False)
        labels = _majority(inverse, np.concatenate(self.votes), n, ties_to_zero=True)
        keep = count >= min_hits
        colors = np.clip(color / count[:, None], 0, 255).astype(np.uint8)
        return (centroid / count[:, None])[keep], truth[keep], labels[keep], colors[keep]


def _majority(
    inverse: npt.NDArray[np.intp], values: npt.NDArray[np.uint8], n: int, *, ties_to_zero: bool
) -> npt.NDArray[np.uint8]:
    """Return the most frequent value per voxel (the lowest on ties, or 0 when `ties_to_zero`)."""
    counts = np.bincount(inverse * NUM_LABELS + values, minlength=n * NUM_LABELS)
    counts = counts.reshape(n, NUM_LABELS)
    best = counts.argmax(1)
    if ties_to_zero:
        tied = (counts == counts[np.arange(n), best][:, None]).sum(1) > 1
        best[tied] = 0
    return np.asarray(best, np.uint8)


def noisy_depth(
    depth_m: npt.NDArray[np.float32], cam: Camera, rng: np.random.Generator
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.bool_]]:
    """Return depth with sigma = k z^2 noise and flying pixels at edges, and where they flew."""
    z = depth_m.astype(np.float64)
    noisy = z + rng.normal(0.0, 1.0, z.shape) * cam.noise_k * z**2
    flying = np.zeros(z.shape, bool)
    for axis in (0, 1):  # a pixel next to a step to its lower or right neighbour
        a, b = (z[:-1], z[1:]) if axis == 0 else (z[:, :-1], z[:, 1:])
        edge = (a > 0) & (b > 0) & (np.abs(a - b) > _EDGE_M)
        pick = edge & (rng.random(edge.shape) < cam.flying_rate)
        mixed = np.minimum(a, b) + rng.uniform(0.2, 0.8, a.shape) * np.abs(a - b)
        target = noisy[:-1] if axis == 0 else noisy[:, :-1]
        target[pick] = mixed[pick]
        (flying[:-1] if axis == 0 else flying[:, :-1])[pick] = True
    return noisy, flying


def report(scene: Gen5Scene) -> None:
    """Print counts and per-class phase-I precision and recall."""
    from process.evaluate import label_metrics

    n_obj, up = int(np.isin(scene.truth, OBJECT_LABELS).sum()), np.round(scene.up, 3)
    print(f"room {scene.room}: {len(scene.cloud):,} points, {n_obj:,} on objects, up {up}")
    metrics = label_metrics(scene.cloud.labels, scene.truth)
    for label, name in enumerate(LABEL_NAMES):
        counts = [int((scene.truth == label).sum()), int((scene.cloud.labels == label).sum())]
        m = metrics.get(name) if label in OBJECT_LABELS else None
        pr = f"  P {m['precision']:.3f}  R {m['recall']:.3f}" if m else ""
        if any(counts):
            print(f"  {name:<14} truth {counts[0]:>9,}  phase I {counts[1]:>9,}{pr}")
    m = metrics["all"]
    print(f"  objects: F1 {m['f1']:.3f}  P {m['precision']:.3f}  R {m['recall']:.3f}")


def main(argv: list[str]) -> int:
    """Generate one scene and print its counts, per-class phase-I precision, recall and time."""
    start = time.perf_counter()
    try:
        seed, size = int(argv[0]) if argv else 0, argv[1] if len(argv) > 1 else "200k"
        sized = size in SIZES
        scene = sized_scene(seed, size) if sized else gen5_scene(seed=seed, voxel_m=float(size))
    except ValueError as err:
        usage = "usage: python -m benchmarks.generator5 [SEED] [VOXEL_M|60k|200k|500k]"
        print(f"{usage}: {err}", file=sys.stderr)
        return 2
    report(scene)
    print(f"  generated in {time.perf_counter() - start:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
