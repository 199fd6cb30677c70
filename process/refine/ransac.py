"""RANSAC plane hypotheses, drawn two ways and scored together in one matrix product.

Uniform hypotheses are RANSAC's: three points anywhere (the paper's Table 5: 300 of them). Local
hypotheses are the least-squares planes of a random point's nearest neighbours, as locally
sampled RANSAC (NAPSAC, Torr et al. 2002) draws its minimal sets near each other: a plane
holding a share w of the points needs about log(0.01) / w^3 uniform draws, so with 300 a wall
of 5 % of the remaining points is found 1 time in 30 (generator 3: a 26,000-point wall was
never found), while a local draw succeeds when its point lies on the plane (about w).

Written by hand rather than calling Open3D's `segment_plane`: Open3D has no local sampling, and
it scores its hypotheses one at a time and, on several threads, each thread with its own random
stream, so its plane depended on the scheduling (we ran it on one thread, a global setting). Here
every hypothesis comes from the caller's NumPy generator and all of them are scored in (hypotheses
x points) products: on the 332k office, 20,000 sampled points and 300 + 300 hypotheses, ~25 ms per
plane against Open3D's 84 ms for its 300 plus 40 ms for the local ones. Scored preemptively
(Nister 2003: all on an even tenth of the sample, the best 64 on all of it), the planes step of
that office takes 0.46-0.58 s instead of 0.60-0.69 s, and all 58 suite clouds and TUM fr1_rpy's
refined map come out the same.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from process.refine.graph import kd_tree

_CHUNK = 64  # hypotheses scored per product: a (64 x points) float32 block, 5 MB at 20k
_PRE_POINTS = 2000  # a sample of this many points or more scores its hypotheses preemptively
_PRE_KEEP = 64  # ... and keeps this many for the whole sample


def best_plane(
    sample: npt.NDArray[np.float32],
    *,
    uniform: int,
    local: int,
    distance_m: float,
    rng: np.random.Generator,
    neighbours: int = 48,
) -> tuple[npt.NDArray[np.float64], int]:
    """Return the hypothesis (a, b, c, d; unit normal) with the most inliers in `sample`, count.

    `uniform` planes through three random points and `local` least-squares planes of a random
    point's `neighbours` nearest compete; a point within `distance_m` of a plane is its inlier.
    """
    if len(sample) < 3:
        raise ValueError(f"a plane needs 3 points, got {len(sample)}")
    hypotheses = [h for h in (uniform_planes(sample, uniform, rng), local_planes(
        sample, local, rng, neighbours=neighbours)) if len(h)]  # fmt: skip
    if not hypotheses:
        raise ValueError("best_plane needs at least one hypothesis (uniform or local)")
    models = np.concatenate(hypotheses)
    keep = np.arange(len(models))
    stride = len(sample) // _PRE_POINTS
    if stride >= 4 and len(models) > _PRE_KEEP:
        # preemptive scoring (Nister 2003): every hypothesis on about _PRE_POINTS evenly
        # spaced points of the sample, the best _PRE_KEEP of them on all of it
        rough = inlier_counts(sample[::stride], models, distance_m)
        keep = np.sort(np.argsort(-rough, kind="stable")[:_PRE_KEEP])
    counts = inlier_counts(sample, models[keep], distance_m)
    best = int(np.argmax(counts))  # the first drawn of equal counts
    return models[keep[best]], int(counts[best])


def uniform_planes(
    sample: npt.NDArray[np.float32], count: int, rng: np.random.Generator
) -> npt.NDArray[np.float64]:
    """Return up to `count` planes (H, 4) through three random points; collinear draws dropped."""
    if count <= 0:
        return np.zeros((0, 4))
    triples = sample[rng.integers(0, len(sample), (count, 3))].astype(np.float64)  # (H, 3, 3)
    normal = np.cross(triples[:, 1] - triples[:, 0], triples[:, 2] - triples[:, 0])
    norm = np.linalg.norm(normal, axis=1)
    ok = norm > 1e-12  # a repeated point or three in a line spans no plane
    normal = normal[ok] / norm[ok, None]
    offset = -np.einsum("hi,hi->h", normal, triples[ok, 0])
    return np.column_stack([normal, offset])


def local_planes(
    sample: npt.NDArray[np.float32],
    count: int,
    rng: np.random.Generator,
    *,
    neighbours: int = 48,
) -> npt.NDArray[np.float64]:
    """Return `count` planes (H, 4): least-squares planes of random points' nearest neighbours."""
    if count <= 0:
        return np.zeros((0, 4))
    k = min(neighbours, len(sample))
    seeds = rng.choice(len(sample), min(count, len(sample)), replace=False)
    _, near = kd_tree(sample).query(sample[seeds], k=k)
    local = sample[near.reshape(len(seeds), k)].astype(np.float64)  # (H, k, 3)
    centroid = local.mean(axis=1)
    centred = local - centroid[:, None, :]
    normal = np.linalg.eigh(np.einsum("hki,hkj->hij", centred, centred))[1][:, :, 0]  # (H, 3)
    offset = -np.einsum("hi,hi->h", normal, centroid)
    return np.column_stack([normal, offset])


def inlier_counts(
    points: npt.NDArray[np.float32], models: npt.NDArray[np.float64], distance_m: float
) -> npt.NDArray[np.int64]:
    """Return per plane (H, 4) the number of points within `distance_m` of it."""
    counts = np.zeros(len(models), np.int64)
    columns = np.ascontiguousarray(points.T, np.float32)  # (3, N): each plane's row is contiguous
    for start in range(0, len(models), _CHUNK):
        block = models[start : start + _CHUNK].astype(np.float32)
        distance = block[:, :3] @ columns
        distance += block[:, 3:]
        np.abs(distance, out=distance)
        counts[start : start + len(block)] = np.count_nonzero(distance <= distance_m, axis=1)
    return counts
