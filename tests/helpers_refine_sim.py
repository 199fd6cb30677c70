"""A second, independent generator of labelled test clouds: the simulator's room seen through a
degraded 2-D segmentation.

The first generator (synthetic.py) samples boxes on a jittered grid and writes its errors
straight into 3-D. This one differs in all three respects:

- shapes: the simulator's procedural rooms (capture.sim: meshes of tables, chairs, sofas,
  plants, people, monitors, clutter, possibly rotated), sampled area-weighted at random like
  its `ground_truth_cloud.ply` attachment, so densities are uneven;
- coverage: only the points that some keyframe sees survive (undersides are missing);
- errors: made in 2-D, per keyframe, as a segmentation network makes them. Each object's
  rendered mask is eroded or dilated, shifted by a few pixels, sometimes dropped; each object
  has persistent missed patches and wrong-class parts (anchored on the object, painted in every
  view that sees them); random wrong-class blobs land anywhere. The labels reach 3-D by
  projecting every point into every keyframe with its true pose, a depth test against a noisy
  depth image, and a vote over keyframes (0 votes too), as the project's fusion does.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np
import numpy.typing as npt

from capture.recording import LABEL_COLORS
from capture.sim import (
    LabelledPoints,
    Renderer,
    build_scene,
    d435_rig,
    handheld_loop,
    sample_scene,
)
from process.cloud import LabelledCloud

FIRST_OBJECT = 4  # RECORDING.md: 4..10 are the network's object classes
N_LABELS = 11


@dataclass(frozen=True)
class SimErrors:
    """How strongly the 2-D segmentation is degraded (pixel sizes at 320 x 240)."""

    drop_max: float = 0.4  # per-view probability that an object's mask is missing, at most
    erode_px: int = 2  # per-object erosion up to this (dilation up to half of it)
    shift_px: int = 3  # per-view shift of each mask, up to this in x and y
    holes_per_m2: float = 2.5  # persistent missed patches per m^2 of object surface
    hole_radius_m: tuple[float, float] = (0.06, 0.14)
    wrong_per_m2: float = 1.5  # persistent wrong-class parts per m^2 of object surface
    wrong_radius_m: tuple[float, float] = (0.04, 0.08)
    blobs_per_view: float = 3.0  # random wrong-class blobs per keyframe
    depth_noise: float = 0.01  # relative depth noise of the depth test
    point_noise_m: float = 0.003  # jitter of the cloud's points


@dataclass(frozen=True)
class SimScene:
    """A labelled cloud, the truth per point, the truth cloud and gravity-up."""

    cloud: LabelledCloud  # labels as the degraded projection gives them
    truth: npt.NDArray[np.uint8]  # (N,) true label per point
    instances: npt.NDArray[np.uint16]  # (N,) true object instance per point
    gt_cloud: LabelledCloud
    up: npt.NDArray[np.float64]


@lru_cache(maxsize=4)
def _room(seed: int) -> tuple[object, Renderer]:
    scene = build_scene(seed)
    return scene, Renderer(scene)


def sim_scene(
    *,
    seed: int = 0,
    spacing_m: float = 0.012,
    keyframes: int = 24,
    width: int = 320,
    errors: SimErrors | None = None,
    structure_spacing_m: float | None = None,
) -> SimScene:
    """Return the simulator's room `seed` labelled through degraded masks from `keyframes` views.

    `spacing_m` sets the density of the objects: about 0.02 m gives ~60k object points,
    0.008 m ~500k. Floor, walls and ceiling are sampled at `structure_spacing_m` (default twice
    `spacing_m`), so that a room of 50 m^2 does not outweigh its furniture tenfold.
    """
    err = errors or SimErrors()
    scene, renderer = _room(seed)
    rng = np.random.default_rng([seed, 12])
    gt = _sample(scene, renderer, spacing_m, structure_spacing_m or 2 * spacing_m, seed)
    traj = handheld_loop(scene, frames=1200, fps=30.0, seed=seed)  # type: ignore[arg-type]
    poses = traj.world_from_camera[np.linspace(0, 1199, keyframes).astype(int)]
    k = d435_rig(width, width * 3 // 4).color
    anchors = _anchors(gt.points_m, gt.labels, gt.instances, spacing_m, err, rng)
    points = gt.points_m.astype(np.float64)
    votes = np.zeros((len(points), N_LABELS), np.float32)
    scale = width / 320
    for pose in poses:
        view = renderer.render_color(pose, intrinsics=k)
        pred = _degrade(
            view.labels, view.instances, view.depth_m, pose, k, anchors, err, scale, rng
        )
        noisy = view.depth_m * (1 + err.depth_noise * rng.standard_normal(view.depth_m.shape))
        _vote(votes, points, pose, k, pred, noisy.astype(np.float32))
    seen = votes.sum(axis=1) > 0
    labels = votes.argmax(axis=1).astype(np.uint8)[seen]
    xyz = points[seen] + rng.normal(0.0, err.point_noise_m, (int(seen.sum()), 3))
    truth = gt.labels[seen]
    cloud = LabelledCloud(xyz.astype(np.float32), gt.colors[seen], labels)
    colors = np.asarray(LABEL_COLORS, np.uint8)[truth]
    gt_cloud = LabelledCloud(gt.points_m[seen], colors, truth)
    return SimScene(cloud, truth, gt.instances[seen], gt_cloud, np.array([0.0, 0.0, 1.0]))


def _sample(
    scene: object, renderer: Renderer, spacing_m: float, structure_m: float, seed: int
) -> LabelledPoints:
    """Return the objects sampled at `spacing_m` and the room's surfaces at `structure_m`."""
    fine = sample_scene(scene, renderer=renderer, spacing_m=spacing_m, seed=seed)  # type: ignore[arg-type]
    coarse = sample_scene(scene, renderer=renderer, spacing_m=structure_m, seed=seed)  # type: ignore[arg-type]
    a, b = fine.labels >= FIRST_OBJECT, coarse.labels < FIRST_OBJECT
    return LabelledPoints(
        np.concatenate([fine.points_m[a], coarse.points_m[b]]),
        np.concatenate([fine.colors[a], coarse.colors[b]]),
        np.concatenate([fine.labels[a], coarse.labels[b]]),
        np.concatenate([fine.instances[a], coarse.instances[b]]),
    )


@dataclass(frozen=True)
class _Anchors:
    """Persistent per-object errors: 3-D centres, radii, the instance and the painted label."""

    centre: npt.NDArray[np.float64]  # (A, 3)
    radius: npt.NDArray[np.float64]  # (A,)
    instance: npt.NDArray[np.int64]  # (A,) the object the patch lies on
    label: npt.NDArray[np.uint8]  # (A,) 0 = missed patch, else the wrong class
    drop: dict[int, float]  # instance -> per-view drop probability
    erode: dict[int, int]  # instance -> erosion (< 0: dilation) in px at 320 wide


def _anchors(
    pts: npt.NDArray[np.float32],
    labels: npt.NDArray[np.uint8],
    instances: npt.NDArray[np.uint16],
    spacing_m: float,
    err: SimErrors,
    rng: np.random.Generator,
) -> _Anchors:
    objects = np.flatnonzero(labels >= FIRST_OBJECT)
    area = len(objects) * spacing_m**2  # one point per spacing^2 of surface
    n_holes = rng.poisson(area * err.holes_per_m2)
    n_wrong = rng.poisson(area * err.wrong_per_m2)
    seeds = rng.choice(objects, n_holes + n_wrong)
    radius = np.r_[
        rng.uniform(*err.hole_radius_m, n_holes), rng.uniform(*err.wrong_radius_m, n_wrong)
    ]
    wrong = np.array([_other(int(labels[s]), rng) for s in seeds[n_holes:]], np.uint8).reshape(-1)
    ids = [int(i) for i in np.unique(instances[objects])]
    drop = {i: float(err.drop_max * rng.beta(1.0, 3.0)) for i in ids}
    erode = {i: int(rng.integers(-err.erode_px // 2, err.erode_px + 1)) for i in ids}
    return _Anchors(
        pts[seeds].astype(np.float64),
        radius,
        instances[seeds].astype(np.int64),
        np.r_[np.zeros(n_holes, np.uint8), wrong],
        drop,
        erode,
    )


def _other(label: int, rng: np.random.Generator) -> int:
    return int(rng.choice([c for c in range(FIRST_OBJECT, N_LABELS) if c != label]))


def _degrade(
    labels: npt.NDArray[np.uint8],
    instances: npt.NDArray[np.uint16],
    depth: npt.NDArray[np.float32],
    pose: npt.NDArray[np.float64],
    k: object,
    anchors: _Anchors,
    err: SimErrors,
    scale: float,
    rng: np.random.Generator,
) -> npt.NDArray[np.uint8]:
    """Return the label image a mediocre network would give for this view."""
    out = np.zeros_like(labels)
    objects = [int(i) for i in np.unique(instances[labels >= FIRST_OBJECT])]
    mean_depth = {i: float(depth[instances == i].mean()) for i in objects}
    for inst in sorted(objects, key=lambda i: -mean_depth[i]):  # far first, near paints over
        if rng.random() < anchors.drop.get(inst, 0.0):
            continue
        mask = (instances == inst).astype(np.uint8)
        label = int(labels[instances == inst][0])
        mask = _patches(mask, inst, pose, k, depth, anchors, label, out)
        e = round(anchors.erode.get(inst, 0) * scale + rng.integers(-1, 2))
        if e != 0:
            kernel = np.ones((2 * abs(e) + 1,) * 2, np.uint8)
            mask = cv2.erode(mask, kernel) if e > 0 else cv2.dilate(mask, kernel)
        s = max(1, round(err.shift_px * scale))
        mask = np.roll(mask, tuple(int(v) for v in rng.integers(-s, s + 1, 2)), axis=(0, 1))
        out[mask > 0] = label
        out[mask == 2] = 0  # a missed patch painted by `_patches`
        for wrong in range(FIRST_OBJECT, N_LABELS):
            out[mask == 10 + wrong] = wrong
    for _ in range(rng.poisson(err.blobs_per_view)):  # random wrong-class blobs
        centre = (int(rng.integers(labels.shape[1])), int(rng.integers(labels.shape[0])))
        axes = tuple(int(v) for v in rng.integers(3, 12, 2) * scale)
        cv2.ellipse(
            out, centre, axes, float(rng.uniform(0, 180)), 0, 360, int(rng.integers(4, 11)), -1
        )
    return out


def _patches(
    mask: npt.NDArray[np.uint8],
    inst: int,
    pose: npt.NDArray[np.float64],
    k: object,
    depth: npt.NDArray[np.float32],
    anchors: _Anchors,
    label: int,
    out: npt.NDArray[np.uint8],
) -> npt.NDArray[np.uint8]:
    """Paint the object's persistent patches into its mask: 2 = missed, 10 + c = class c."""
    mine = np.flatnonzero(anchors.instance == inst)
    if len(mine) == 0:
        return mask
    uv, z = _project(anchors.centre[mine], pose, k)
    h, w = mask.shape
    inside = (z > 0.1) & (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
    fx = float(k.fx)  # type: ignore[attr-defined]
    patch = np.zeros_like(mask)
    for a, (u, v), zz in zip(mine[inside], uv[inside], z[inside], strict=True):
        if abs(depth[int(v), int(u)] - zz) > 0.1:  # hidden in this view
            continue
        r = max(1, round(anchors.radius[a] * fx / zz))
        value = 2 if anchors.label[a] == 0 else 10 + int(anchors.label[a])
        cv2.circle(patch, (int(u), int(v)), r, value, -1)
    return np.where((mask > 0) & (patch > 0), patch, mask).astype(np.uint8)


def _project(
    world: npt.NDArray[np.float64], pose: npt.NDArray[np.float64], k: object
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    cam = (world - pose[:3, 3]) @ pose[:3, :3]
    z = cam[:, 2]
    safe = np.where(z > 1e-6, z, 1e-6)
    u = cam[:, 0] / safe * k.fx + k.cx  # type: ignore[attr-defined]
    v = cam[:, 1] / safe * k.fy + k.cy  # type: ignore[attr-defined]
    return np.column_stack([u + 0.5, v + 0.5]), z


def _vote(
    votes: npt.NDArray[np.float32],
    points: npt.NDArray[np.float64],
    pose: npt.NDArray[np.float64],
    k: object,
    pred: npt.NDArray[np.uint8],
    depth: npt.NDArray[np.float32],
) -> None:
    """Add one keyframe's label to every point it sees (depth test against the noisy depth)."""
    uv, z = _project(points, pose, k)
    h, w = pred.shape
    ok = (z > 0.1) & (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
    idx = np.flatnonzero(ok)
    u, v = uv[idx, 0].astype(int), uv[idx, 1].astype(int)
    seen = np.abs(depth[v, u] - z[idx]) <= 0.02 + 0.01 * z[idx]
    idx, u, v = idx[seen], u[seen], v[seen]
    np.add.at(votes, (idx, pred[v, u].astype(np.intp)), 1.0)


@dataclass(frozen=True)
class SimFusedMap:
    """A map fused from degraded keyframes as `process run` fuses them, and its truth."""

    cloud: LabelledCloud  # the fused map (phase I)
    truth: npt.NDArray[np.uint8]  # (N,) label of the nearest ground-truth point (0 beyond 5 cm)
    up: npt.NDArray[np.float64]  # the hint the pipeline passes: the first camera's up


MILD = SimErrors(drop_max=0.15, holes_per_m2=1.0, wrong_per_m2=0.8, blobs_per_view=1.5)


def sim_fused_map(
    *, seed: int = 0, keyframes: int = 12, width: int = 320, errors: SimErrors = MILD
) -> SimFusedMap:
    """Return the simulator's room `seed` fused (TSDF, process.fusion) from degraded keyframes.

    A network that labels structure too: floor, wall and ceiling pixels keep their true label
    wherever no object mask (right or wrong) was painted; objects are degraded as in
    `sim_scene`. Depth is noisy (1 % relative); poses are the true ones.
    """
    from process.evaluate import match_labels
    from process.fusion.votes import Fusion, FusionConfig

    scene, renderer = _room(seed)
    rng = np.random.default_rng([seed, 13])
    gt = _sample(scene, renderer, 0.015, 0.03, seed)
    traj = handheld_loop(scene, frames=1200, fps=30.0, seed=seed)  # type: ignore[arg-type]
    poses = traj.world_from_camera[np.linspace(0, 1199, keyframes).astype(int)]
    k = d435_rig(width, width * 3 // 4).color
    anchors = _anchors(gt.points_m, gt.labels, gt.instances, 0.015, errors, rng)
    fusion = Fusion(FusionConfig())
    for pose in poses:
        view = renderer.render_color(pose, intrinsics=k)
        pred = _degrade(
            view.labels, view.instances, view.depth_m, pose, k, anchors, errors, width / 320, rng
        )
        structure = (pred == 0) & (view.labels > 0) & (view.labels < FIRST_OBJECT)
        pred[structure] = view.labels[structure]
        depth = view.depth_m * (1 + errors.depth_noise * rng.standard_normal(view.depth_m.shape))
        fusion.integrate(
            view.color,
            np.nan_to_num(depth).astype(np.float32),
            pred,
            np.full(pred.shape, 0.9, np.float32),
            intrinsics=k,
            world_from_camera=pose,
        )
    cloud = fusion.cloud()
    colors = np.asarray(LABEL_COLORS, np.uint8)[gt.labels]
    truth = match_labels(
        cloud.points, LabelledCloud(gt.points_m, colors, gt.labels), max_distance_m=0.05
    )
    return SimFusedMap(cloud, truth, -poses[0][:3, 1])
