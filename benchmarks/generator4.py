"""Generator 4: labelled clouds sampled uniformly from furnished room meshes, with phase-I errors.

Written blind to the refinement (issue 12): four room types (gen4_rooms.py) built from Open3D
meshes (gen4_shapes.py), their surfaces sampled uniformly (Open3D `sample_points_uniformly`),
surfaces hidden inside solids dropped, 3 mm Gaussian noise, then the scene turned to a random
orientation (`up` says where up is). Phase-I labels imitate a 2-D network projected into 3-D:
missed patches 8-25 cm across, missed legs and stems, labels bleeding 3-7 cm onto the floor, walls
and touching objects, small wrong-class blobs on objects and on structure, whole small objects
mislabelled. Structure is unlabelled unless `structure_labelled`.

    python -m benchmarks.generator4 SEED [OBJECT_POINTS]
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from typing import Final

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from benchmarks import gen4_shapes as sh
from benchmarks.gen4_rooms import ROOMS, build_room
from capture.recording import LABEL_NAMES, OBJECT_LABELS
from process.cloud import LabelledCloud


@dataclass(frozen=True)
class Gen4Scene:
    """A labelled cloud (phase-I labels), its truth and what made each error."""

    cloud: LabelledCloud
    truth: npt.NDArray[np.uint8]  # (N,) RECORDING.md labels
    instances: npt.NDArray[np.int32]  # (N,) object id; structure and background have theirs
    family: npt.NDArray[np.uint8]  # (N,) index into gen4_FAMILIES of a wrong label; 0 = right
    up: npt.NDArray[np.float64]  # (3,) unit vector, world frame
    room: str


def gen4_scene(
    *,
    seed: int = 0,
    object_points: int = 200_000,
    noise_m: float = 0.003,
    room: str | None = None,
    other_ratio: float = 0.65,
    structure_labelled: bool = False,
    miss_share: float = 0.25,
    tilt: bool = True,
) -> Gen4Scene:
    """Return one room's labelled cloud; `room` defaults to ROOMS[seed % 4].

    Args:
        seed: seeds the layout, the sampling, the errors and the orientation.
        object_points: points on target-class objects (labels 4-10), exactly.
        noise_m: standard deviation of the Gaussian noise per axis.
        room: one of ROOMS.
        other_ratio: structure and background points per object point.
        structure_labelled: phase I labels structure (with errors) instead of leaving it 0.
        miss_share: share of object points missed in 8-25 cm patches.
        tilt: turn the scene to a random orientation.
    """
    name = room or ROOMS[seed % len(ROOMS)]
    if name not in ROOMS or object_points < 1000:
        raise ValueError(
            f"expected a room in {ROOMS} and >= 1000 object points; got {name!r}, {object_points}"
        )
    rng = np.random.default_rng([seed, 4])
    built = build_room(name, rng)
    points, part_of = sh.sample_parts(built.parts, rng, object_points, other_ratio, built.h)
    parts = built.parts
    truth = np.array([p.label for p in parts], np.uint8)[part_of]
    instances = np.array([p.instance for p in parts], np.int32)[part_of]
    thin = np.array([p.thin for p in parts])[part_of]
    points = points + rng.normal(0.0, noise_m, points.shape)
    labels, family = phase_one(
        _Truth(points, truth, instances, thin, part_of, cKDTree(points)),
        rng,
        miss_share=miss_share,
        structure_labelled=structure_labelled,
    )
    colors = sh.part_colors(parts, part_of, rng)
    rot = Rotation.random(random_state=seed) if tilt else Rotation.identity()
    world = rot.apply(points) + (rng.uniform(-5, 5, 3) if tilt else 0.0)
    cloud = LabelledCloud(world.astype(np.float32), colors, labels)
    return Gen4Scene(cloud, truth, instances, family, rot.apply([0.0, 0.0, 1.0]), name)


FAMILIES: Final = (
    "none",
    "missed_patch",
    "missed_thin",
    "bleed",
    "blob",
    "structure_blob",
    "whole_object",
    "structure",
)
_CONFUSED: Final = {
    4: (10, 5),
    5: (8, 4, 6),
    6: (5, 8),
    7: (10, 6),
    8: (5, 6),
    9: (10,),
    10: (4, 9, 7),
}
_ON_SURFACE: Final = {0: (4, 10, 9, 8), 1: (9, 10), 2: (4, 5, 10), 3: (9, 10, 7, 6)}
_MISS_WEIGHT: Final = {4: 1.6, 5: 1.3, 6: 0.8, 7: 1.0, 8: 0.8, 9: 1.0, 10: 1.0}  # tables miss most


@dataclass(frozen=True)
class _Truth:
    """The sampled scene the errors are written on."""

    points: npt.NDArray[np.float64]  # (N, 3)
    truth: npt.NDArray[np.uint8]  # (N,)
    instances: npt.NDArray[np.int32]  # (N,)
    thin: npt.NDArray[np.bool_]  # (N,) on a leg, pole or stem
    part_of: npt.NDArray[np.intp]  # (N,)
    tree: cKDTree


def phase_one(
    t: _Truth, rng: np.random.Generator, *, miss_share: float, structure_labelled: bool
) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.uint8]]:
    """Return phase-I labels and, per wrong label, the FAMILIES index of the error that set it."""
    is_object = np.isin(t.truth, OBJECT_LABELS)
    structure = structure_labelled & (t.truth >= 1) & (t.truth <= 3)
    labels = np.where(is_object | structure, t.truth, 0).astype(np.uint8)
    family = np.zeros(len(labels), np.uint8)
    objects = [int(i) for i in np.unique(t.instances[is_object])]
    _bleed(t, objects, labels, family, rng)
    _blobs(t, np.flatnonzero(is_object), round(0.8 * len(objects)), labels, family, rng, 4)
    _blobs(t, np.flatnonzero(~is_object), round(0.3 * len(objects)), labels, family, rng, 5)
    _whole_objects(t, objects, int(is_object.sum()), labels, family, rng)
    if structure_labelled:
        _structure_errors(t, labels, family, rng)
    for part in np.unique(t.part_of[t.thin]):
        if rng.random() < 0.5:
            _set(np.flatnonzero(t.part_of == part), 0, 2, labels, family)
    _missed_patches(t, is_object, miss_share, labels, family, rng)
    family[labels == t.truth] = 0
    return labels, family


def _set(
    idx: npt.NDArray[np.intp],
    label: int,
    fam: int,
    labels: npt.NDArray[np.uint8],
    family: npt.NDArray[np.uint8],
) -> None:
    labels[idx], family[idx] = label, fam


def _bleed(
    t: _Truth,
    objects: list[int],
    labels: npt.NDArray[np.uint8],
    family: npt.NDArray[np.uint8],
    rng: np.random.Generator,
) -> None:
    """An object's label spreads 3-7 cm onto whatever lies next to it (80 % of objects)."""
    for inst in rng.permutation(objects):
        if rng.random() > 0.8:
            continue
        reach, mine = rng.uniform(0.03, 0.07), t.instances == inst
        own = t.points[mine]
        near = np.all((t.points > own.min(0) - reach) & (t.points < own.max(0) + reach), axis=1)
        cand = np.flatnonzero(near & ~mine)
        dist, _ = cKDTree(own).query(t.points[cand], distance_upper_bound=reach)
        _set(cand[dist <= reach], int(t.truth[mine][0]), 3, labels, family)


def _blobs(
    t: _Truth,
    pool: npt.NDArray[np.intp],
    count: int,
    labels: npt.NDArray[np.uint8],
    family: npt.NDArray[np.uint8],
    rng: np.random.Generator,
    fam: int,
) -> None:
    """Small wrong-class blobs: 3-8 cm on objects (fam 4), 5-15 cm on structure (fam 5)."""
    radii = (0.03, 0.08) if fam == 4 else (0.05, 0.15)
    for center in rng.choice(pool, count, replace=False):
        idx = np.asarray(t.tree.query_ball_point(t.points[center], rng.uniform(*radii)), np.intp)
        idx = idx[t.instances[idx] == t.instances[center]]
        truth = int(t.truth[center])
        choices = _CONFUSED.get(truth) or _ON_SURFACE[truth]
        _set(idx, int(rng.choice(choices)), fam, labels, family)


def _whole_objects(
    t: _Truth,
    objects: list[int],
    n_object: int,
    labels: npt.NDArray[np.uint8],
    family: npt.NDArray[np.uint8],
    rng: np.random.Generator,
) -> None:
    """A quarter (at least one) of the small objects (< 1.5 % of object points) change class."""
    small = [i for i in objects if (t.instances == i).sum() < 0.015 * n_object]
    count = max(1, int(rng.binomial(len(small), 0.25))) if small else 0
    for inst in rng.choice(small, count, replace=False) if small else []:
        idx = np.flatnonzero(t.instances == inst)
        _set(idx, int(rng.choice(_CONFUSED[int(t.truth[idx[0]])])), 6, labels, family)


def _structure_errors(
    t: _Truth,
    labels: npt.NDArray[np.uint8],
    family: npt.NDArray[np.uint8],
    rng: np.random.Generator,
) -> None:
    """Floor within 5 cm of a wall reads wall, wall near the ceiling ceiling; 20-50 cm holes."""
    for lower, upper in ((2, 3), (3, 1)):
        dist, _ = cKDTree(t.points[t.truth == upper]).query(
            t.points[t.truth == lower], distance_upper_bound=0.05
        )
        idx = np.flatnonzero(t.truth == lower)[dist <= 0.05]
        _set(idx[labels[idx] == lower], upper, 7, labels, family)
    structure = np.flatnonzero((t.truth >= 1) & (t.truth <= 3))
    for center in rng.choice(structure, 15, replace=False):
        idx = np.asarray(t.tree.query_ball_point(t.points[center], rng.uniform(0.2, 0.5)), np.intp)
        idx = idx[t.instances[idx] == t.instances[center]]
        _set(idx, 0, 7, labels, family)


def _missed_patches(
    t: _Truth,
    is_object: npt.NDArray[np.bool_],
    share: float,
    labels: npt.NDArray[np.uint8],
    family: npt.NDArray[np.uint8],
    rng: np.random.Generator,
) -> None:
    """Object points missed in patches 8-25 cm across until `share` of them are (tables most)."""
    pool = np.flatnonzero(is_object)
    weight = np.array([_MISS_WEIGHT[int(c)] for c in t.truth[pool]])
    target = share * len(pool)
    patches = 0
    while (missed := int((family[pool] == 1).sum())) < target:
        p = weight * (family[pool] != 1)
        per_patch = missed / patches if missed else len(pool) / 2000
        batch = max(1, min(50, int((target - missed) / (2 * per_patch))))
        patches += batch
        for center in rng.choice(pool, batch, replace=False, p=p / p.sum()):
            idx = np.asarray(
                t.tree.query_ball_point(t.points[center], rng.uniform(0.04, 0.125)), np.intp
            )
            _set(idx[t.instances[idx] == t.instances[center]], 0, 1, labels, family)


def _report(scene: Gen4Scene) -> None:
    """Print counts per class and per error family."""
    print(f"room {scene.room}: {len(scene.cloud)} points, up {np.round(scene.up, 3)}")
    for label in np.unique(scene.truth):
        n_truth = int((scene.truth == label).sum())
        n_label = int((scene.cloud.labels == label).sum())
        print(f"  {LABEL_NAMES[label]:<14} truth {n_truth:>8}  phase I {n_label:>8}")
    for i, name in enumerate(FAMILIES[1:], start=1):
        print(f"  error {name:<16} {int((scene.family == i).sum()):>8} points")


def main(argv: list[str]) -> int:
    """Generate one cloud, print its counts and the refinement's phase F1, defaults and paper()."""
    import time

    from process.evaluate import label_metrics
    from process.refine import RefineConfig, refine

    try:
        seed = int(argv[0]) if argv else 0
        object_points = int(argv[1]) if len(argv) > 1 else 200_000
        scene = gen4_scene(seed=seed, object_points=object_points)
    except ValueError as err:
        print(
            f"usage: python -m benchmarks.generator4 [SEED] [OBJECT_POINTS]: {err}", file=sys.stderr
        )
        return 2
    _report(scene)
    for name, config in (("defaults", RefineConfig()), ("paper()", RefineConfig.paper())):
        start = time.perf_counter()
        result = refine(scene.cloud, config, up=scene.up)
        seconds = time.perf_counter() - start
        row = []
        for phase, cloud in result.phase_clouds().items():
            m = label_metrics(cloud.labels, scene.truth)["all"]
            row.append(f"{phase} F1 {m['f1']:.3f} (P {m['precision']:.3f} R {m['recall']:.3f})")
        print(f"{name:<9} {'  '.join(row)}  refine {seconds:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
