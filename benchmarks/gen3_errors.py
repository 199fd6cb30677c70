"""Generator 3's error process: phase-I labels from the truth, written in 3-D.

The network labels objects only (structure starts unlabelled). In order: flying pixels take the
label of the surface in front of them; a few small objects get a wrong class as a whole; labels
bleed from objects onto whatever lies within `bleed_m` (floor, walls, neighbours) in patchy
stretches of their outline; small wrong-class blobs appear on objects and structure; points on
boundaries between objects flip to the neighbour's label (speckle); last, patches of 8-25 cm on
objects are missed (label 0) until `miss_rate` of the object points are.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

ERROR_NAMES = ("none", "missed patch", "bleed", "wrong-class blob", "swapped object",
               "boundary speckle", "flying pixel")  # fmt: skip
MISSED, BLEED, BLOB, SWAPPED, SPECKLE, FLYING = 1, 2, 3, 4, 5, 6
_CONFUSED = {4: 10, 5: 8, 6: 5, 7: 10, 8: 5, 9: 10, 10: 9}  # a plausible wrong class
_BLOCK_M = 0.2  # bleeding switches on and off along an outline in blocks of this size
Labels = npt.NDArray[np.uint8]
Ids = npt.NDArray[np.int32]


@dataclass(frozen=True)
class Gen3Errors:
    """Rates and sizes of the error families (shares are of the true object points)."""

    miss_rate: float = 0.25  # object points set to 0, in patches
    miss_diameter_m: tuple[float, float] = (0.08, 0.25)
    bleed_m: float = 0.05  # widest bleeding band around an object
    bleed_share: float = 0.5  # share of 20 cm blocks along outlines that bleed
    blob_rate: float = 0.02  # wrong-class blob points per object point
    blob_diameter_m: tuple[float, float] = (0.04, 0.15)
    swapped_objects: int = 1  # small objects labelled with a wrong class as a whole
    speckle: float = 0.2  # chance a point on a boundary takes its neighbour's label
    speckle_m: float = 0.02  # boundary: another object within this distance

    def __post_init__(self) -> None:
        for name in ("miss_rate", "bleed_share", "blob_rate", "speckle"):
            if not 0.0 <= getattr(self, name) <= 0.9:
                found = getattr(self, name)
                raise ValueError(f"Gen3Errors.{name} must be in 0..0.9, got {found}; pass a share")


def apply_errors(
    points: npt.NDArray[np.float64],
    truth: Labels,
    instances: npt.NDArray[np.int32],
    seen: Labels,
    cfg: Gen3Errors,
    rng: np.random.Generator,
) -> tuple[Labels, Labels]:
    """Return phase-I labels and the error family (ERROR_NAMES index) that set each one."""
    labels = np.where(truth >= 4, truth, 0).astype(np.uint8)
    family = np.zeros(len(truth), np.uint8)
    flying = instances == 0
    labels[flying] = np.where(seen[flying] >= 4, seen[flying], 0)
    family[flying & (labels > 0)] = FLYING
    tree = cKDTree(points)
    streams = rng.spawn(5)  # one per family: switching one off leaves the others' draws
    _swap(labels, family, truth, instances, cfg.swapped_objects, streams[0])
    _bleed(points, labels, family, truth, instances, cfg, streams[1])
    _blobs(tree, labels, family, truth, cfg, streams[2])
    _speckle(tree, labels, family, instances, cfg, streams[3])
    _miss(tree, labels, family, truth, instances, cfg, streams[4])
    return labels, family


def _set(
    labels: Labels, family: Labels, idx: npt.NDArray[np.intp], value: Labels | int, code: int
) -> int:
    """Give `idx` the labels `value`; mark the ones that changed with `code`; count them."""
    value = np.broadcast_to(np.asarray(value, np.uint8), idx.shape)
    changed = labels[idx] != value
    labels[idx], family[idx[changed]] = value, code
    return int(changed.sum())


def _swap(labels: Labels, family: Labels, truth: Labels, instances: npt.NDArray[np.int32],
          n: int, rng: np.random.Generator) -> None:  # fmt: skip
    """Give `n` of the smaller objects a wrong class as a whole."""
    ids, counts = np.unique(instances[truth >= 4], return_counts=True)
    small = ids[counts <= np.median(counts)] if len(ids) else ids
    for inst in rng.permutation(small)[:n]:
        idx = np.flatnonzero(instances == inst)
        _set(labels, family, idx, _CONFUSED[int(truth[idx[0]])], SWAPPED)


def _bleed(points: npt.NDArray[np.float64], labels: Labels, family: Labels, truth: Labels,
           instances: Ids, cfg: Gen3Errors, rng: np.random.Generator) -> None:  # fmt: skip
    """Spread each object's label onto other points within a band of up to `bleed_m`."""
    blocks = np.floor(points / _BLOCK_M).astype(np.int64)
    _, block = np.unique(blocks, axis=0, return_inverse=True)
    block = block.ravel()
    on = rng.random(block.max() + 1) < cfg.bleed_share
    width = cfg.bleed_m * rng.uniform(0.4, 1.0, block.max() + 1)
    source = labels.copy()
    for inst in np.unique(instances[truth >= 4]):
        own = np.flatnonzero(instances == inst)
        values, counts = np.unique(source[own], return_counts=True)
        label = values[np.argmax(counts)]
        if label < 4:
            continue
        lo, hi = points[own].min(0) - cfg.bleed_m, points[own].max(0) + cfg.bleed_m
        near = np.flatnonzero(np.all((points >= lo) & (points <= hi), 1) & (instances != inst))
        near = near[on[block[near]]]
        dist, _ = cKDTree(points[own]).query(points[near], distance_upper_bound=cfg.bleed_m)
        hit = near[dist <= width[block[near]]]
        _set(labels, family, hit[source[hit] != label], label, BLEED)


def _balls(tree: cKDTree, seeds: npt.NDArray[np.float64], radius: float) -> npt.NDArray[np.intp]:
    return np.asarray(tree.query_ball_point(seeds, radius), np.intp)


def _blobs(tree: cKDTree, labels: Labels, family: Labels, truth: Labels,
           cfg: Gen3Errors, rng: np.random.Generator) -> None:  # fmt: skip
    """Paint small balls of a wrong object class, on objects (70 %) and on structure."""
    objects, others = np.flatnonzero(truth >= 4), np.flatnonzero((truth >= 1) & (truth < 4))
    painted = np.zeros(len(labels), bool)
    while painted.sum() < cfg.blob_rate * len(objects) and len(objects) and len(others):
        seed = rng.choice(objects if rng.random() < 0.7 else others)
        idx = _balls(tree, tree.data[seed], rng.uniform(*cfg.blob_diameter_m) / 2)
        wrong = rng.choice([c for c in range(4, 11) if c != truth[seed]])
        idx = idx[truth[idx] != wrong]
        _set(labels, family, idx, wrong, BLOB)
        painted[idx[family[idx] == BLOB]] = True


def _speckle(tree: cKDTree, labels: Labels, family: Labels, instances: npt.NDArray[np.int32],
             cfg: Gen3Errors, rng: np.random.Generator) -> None:  # fmt: skip
    """Flip points next to another object to that object's label, with chance `speckle`."""
    n = len(labels)
    _, nbr = tree.query(tree.data, k=8, distance_upper_bound=cfg.speckle_m)
    valid = nbr < n
    other = (
        valid & (instances[np.minimum(nbr, n - 1)] != instances[:, None]) & (instances[:, None] > 0)
    )
    rows = np.flatnonzero(other.any(1) & (rng.random(n) < cfg.speckle))
    cols = np.argmax(other[rows], 1)
    source = labels.copy()
    _set(labels, family, rows, source[nbr[rows, cols]], SPECKLE)  # fmt: skip


def _miss(tree: cKDTree, labels: Labels, family: Labels, truth: Labels,
          instances: Ids, cfg: Gen3Errors, rng: np.random.Generator) -> None:  # fmt: skip
    """Unlabel patches (balls within one object) until `miss_rate` of object points are missed."""
    objects = np.flatnonzero(truth >= 4)
    missed = np.zeros(len(labels), bool)
    target, done = cfg.miss_rate * len(objects), 0
    while done < target:  # miss_rate <= 0.9: points are left
        left = objects[~missed[objects]]
        seed = left[rng.integers(len(left))]
        idx = _balls(tree, tree.data[seed], rng.uniform(*cfg.miss_diameter_m) / 2)
        idx = idx[(instances[idx] == instances[seed]) & ~missed[idx]]
        missed[idx] = True
        done += len(idx)
    idx = np.flatnonzero(missed)
    labels[idx], family[idx] = 0, MISSED
