"""A labelled indoor cloud with the errors of 2-D label transfer, for tests and benchmarks.

Surfaces are sampled on a jittered grid (like the centroids of a voxel map); objects carry
their true label. The transferred labels then get the three error modes of projecting 2-D
segmentation into 3-D: missed patches (label 0), boundary bleed (an object's label on the floor,
the wall and the furniture around it), and stray blobs (small wrong-class specks, flying pixels
at depth edges).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from capture.recording import LABEL_COLORS
from process.cloud import LabelledCloud

TABLE, CHAIR, PERSON, PLANT, SOFA, TV, CLUTTER = 4, 5, 6, 7, 8, 9, 10
FLOOR, WALL = 2, 3
Box = tuple[float, float, float, float, float, float]  # x0 y0 z0 x1 y1 z1
_MISSED_PER_M2 = 11.2  # missed patches per m^2 of object surface
_STRAY_PER_M2 = 1.6  # wrong-class blobs per m^2 of object and furniture surface


@dataclass(frozen=True)
class SyntheticScene:
    """A cloud with transferred (erroneous) labels, the truth per point, and the truth cloud."""

    cloud: LabelledCloud  # labels as 2-D label transfer gives them
    truth: npt.NDArray[np.uint8]  # (N,) true label per point; 0 for flying pixels
    gt_cloud: LabelledCloud  # the surface points with their true labels
    up: npt.NDArray[np.float64]  # (3,) gravity-up


class _Sampler:
    """Collects surface samples at one spacing, with their true labels and object ids."""

    def __init__(self, rng: np.random.Generator, spacing_m: float) -> None:
        self.rng, self.s = rng, spacing_m
        self.parts: list[tuple[npt.NDArray[np.float64], int, int]] = []
        self.n_objects = 0

    def rect(
        self, origin: npt.ArrayLike, u: npt.ArrayLike, v: npt.ArrayLike, label: int, obj: int
    ) -> None:
        """Add the rectangle origin + a u + b v, a, b in [0, 1]."""
        o, du, dv = (np.asarray(x, np.float64) for x in (origin, u, v))
        nu = max(1, round(np.linalg.norm(du) / self.s))
        nv = max(1, round(np.linalg.norm(dv) / self.s))
        a, b = np.meshgrid((np.arange(nu) + 0.5) / nu, (np.arange(nv) + 0.5) / nv)
        jitter = self.rng.uniform(-0.15, 0.15, (2, a.size))
        pts = (
            o + np.outer(a.ravel() + jitter[0] / nu, du) + np.outer(b.ravel() + jitter[1] / nv, dv)
        )
        normal = np.cross(du, dv)
        normal /= np.linalg.norm(normal)
        pts += np.outer(self.rng.normal(0.0, 0.002, len(pts)), normal)  # depth noise
        self.parts.append((pts, label, obj))

    def box(self, box: Box, label: int, *, bottom: bool = False) -> int:
        """Add the faces of an axis-aligned box (no bottom face unless asked); return its id."""
        x0, y0, z0, x1, y1, z1 = box
        obj = self._new()
        dx, dy, dz = (x1 - x0, 0, 0), (0, y1 - y0, 0), (0, 0, z1 - z0)
        self.rect((x0, y0, z1), dx, dy, label, obj)
        if bottom:
            self.rect((x0, y0, z0), dx, dy, label, obj)
        for origin, u in (
            ((x0, y0, z0), dx),
            ((x0, y1, z0), dx),
            ((x0, y0, z0), dy),
            ((x1, y0, z0), dy),
        ):
            self.rect(origin, u, dz, label, obj)
        return obj

    def cylinder(
        self, centre: tuple[float, float], radius: float, z: tuple[float, float], label: int
    ) -> int:
        """Add the side and the top of an upright cylinder; return its id."""
        obj = self._new()
        n_around = max(8, round(2 * np.pi * radius / self.s))
        n_up = max(1, round((z[1] - z[0]) / self.s))
        t, h = np.meshgrid(
            np.arange(n_around) / n_around * 2 * np.pi, (np.arange(n_up) + 0.5) / n_up
        )
        t = t.ravel() + self.rng.uniform(-0.3, 0.3, t.size) * 2 * np.pi / n_around
        r = radius + self.rng.normal(0, 0.002, t.size)
        side = np.column_stack(
            [centre[0] + r * np.cos(t), centre[1] + r * np.sin(t), z[0] + h.ravel() * (z[1] - z[0])]
        )
        self.parts.append((side, label, obj))
        self._disc(centre, radius, z[1], label, obj)
        return obj

    def blob(self, centre: tuple[float, float, float], radius: float, label: int) -> int:
        """Add a bumpy sphere (foliage); return its id."""
        obj = self._new()
        n = round(4 * np.pi * radius**2 / self.s**2)
        k = np.arange(n) + 0.5  # Fibonacci sphere: even spacing
        phi, theta = np.arccos(1 - 2 * k / n), np.pi * (1 + 5**0.5) * k
        d = np.column_stack([np.sin(phi) * np.cos(theta), np.sin(phi) * np.sin(theta), np.cos(phi)])
        bump = 1 + 0.12 * np.sin(5 * theta) * np.sin(4 * phi)
        self.parts.append((np.asarray(centre) + d * (radius * bump)[:, None], label, obj))
        return obj

    def _disc(
        self, centre: tuple[float, float], radius: float, z: float, label: int, obj: int
    ) -> None:
        g = np.arange(-radius, radius, self.s) + self.s / 2
        x, y = np.meshgrid(g, g)
        inside = x**2 + y**2 <= radius**2
        pts = np.column_stack(
            [centre[0] + x[inside], centre[1] + y[inside], np.full(inside.sum(), z)]
        )
        self.parts.append((pts, label, obj))

    def _new(self) -> int:
        self.n_objects += 1
        return self.n_objects

    def arrays(
        self,
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.uint8], npt.NDArray[np.int64]]:
        """Return points, true labels and object ids (0 = room surfaces)."""
        points = np.concatenate([p for p, _, _ in self.parts])
        labels = np.concatenate([np.full(len(p), lab, np.uint8) for p, lab, _ in self.parts])
        objects = np.concatenate([np.full(len(p), obj, np.int64) for p, _, obj in self.parts])
        return points, labels, objects


def _furnish(sampler: _Sampler, rng: np.random.Generator) -> None:
    """Place an office: desks with monitors and bottles, chairs, a sofa, plants, a cabinet."""
    box = sampler.box
    desks = [(0.4, 1.0), (3.0, 1.0), (0.4, 2.6), (3.0, 2.6)]
    for i, (x, y) in enumerate(desks):
        x += rng.uniform(-0.05, 0.05)
        box((x, y, 0.72, x + 1.6, y + 0.8, 0.76), TABLE, bottom=True)
        for lx, ly in ((x, y), (x + 1.55, y), (x, y + 0.75), (x + 1.55, y + 0.75)):
            box((lx, ly, 0.0, lx + 0.05, ly + 0.05, 0.72), TABLE)
        box((x + 0.5, y + 0.55, 0.76, x + 1.1, y + 0.6, 1.16), TV, bottom=True)
        sampler.cylinder((x + 0.2 + 0.1 * i, y + 0.2), 0.04, (0.76, 1.0), CLUTTER)
        for cx in (x + 0.25, x + 0.95):  # two chairs in front, 15 cm from the desk
            _chair(sampler, cx, y - 0.6)
    box((0.3, 3.7, 0.0, 2.3, 4.4, 0.45), SOFA)
    box((0.3, 4.2, 0.45, 2.3, 4.4, 0.9), SOFA)
    box((2.6, 3.95, 0.0, 3.6, 4.45, 1.8), 0)  # a cabinet nobody labels
    box((2.8, 4.2, 1.8, 3.4, 4.25, 2.15), TV, bottom=True)  # a television on it
    for px, py in ((4.1, 4.05), (5.05, 3.3), (5.05, 0.35)):
        sampler.cylinder((px, py), 0.15, (0.0, 0.3), PLANT)
        sampler.blob((px, py, 0.62), 0.32, PLANT)
    sampler.cylinder((5.05, 2.0), 0.2, (0.0, 1.7), PERSON)
    box((2.35, 0.05, 0.0, 2.75, 0.45, 0.4), CLUTTER)


def _chair(sampler: _Sampler, x: float, y: float) -> None:
    """Add a chair (seat, back on the low-y side, four legs) at its low corner."""
    sampler.box((x, y, 0.43, x + 0.45, y + 0.45, 0.48), CHAIR, bottom=True)
    sampler.box((x, y, 0.48, x + 0.45, y + 0.04, 0.95), CHAIR)
    for lx, ly in ((x, y), (x + 0.42, y), (x, y + 0.42), (x + 0.42, y + 0.42)):
        sampler.box((lx, ly, 0.0, lx + 0.03, ly + 0.03, 0.43), CHAIR)


def indoor_scene(*, seed: int = 0, spacing_m: float = 0.016) -> SyntheticScene:
    """Return an office (5.5 x 4.5 m floor, one wall) with 2-D label-transfer errors.

    At the default spacing: ~330k points, ~180k of them on furniture (~157k on target objects).
    """
    rng = np.random.default_rng(seed)
    sampler = _Sampler(rng, spacing_m)
    sampler.rect((0, 0, 0), (5.5, 0, 0), (0, 4.5, 0), FLOOR, 0)
    sampler.rect((0, 4.5, 0), (5.5, 0, 0), (0, 0, 2.5), WALL, 0)
    _furnish(sampler, rng)
    points, truth, _ = sampler.arrays()
    labels = _transfer_errors(points, truth, rng, spacing_m=spacing_m)
    flying, flying_labels = _flying_pixels(points, labels, rng)
    all_points = np.concatenate([points, flying]).astype(np.float32)
    all_labels = np.concatenate([labels, flying_labels])
    all_truth = np.concatenate([truth, np.zeros(len(flying), np.uint8)])
    colors = np.asarray(LABEL_COLORS, np.uint8)[all_truth] // 2 + 60  # a dim scene colour
    shade = rng.integers(0, 40, (len(all_points), 1), dtype=np.uint8)
    cloud = LabelledCloud(all_points, colors + shade, all_labels)
    gt = LabelledCloud(points.astype(np.float32), colors[: len(points)], truth)
    return SyntheticScene(cloud, all_truth, gt, np.array([0.0, 0.0, 1.0]))


def _transfer_errors(
    points: npt.NDArray[np.float64],
    truth: npt.NDArray[np.uint8],
    rng: np.random.Generator,
    *,
    spacing_m: float,
) -> npt.NDArray[np.uint8]:
    """Return labels as 2-D segmentation projected into 3-D would give them.

    Patches are counted per square metre of surface, so the error rates do not depend on the
    sampling: ~11 missed patches (5-12 cm radius) and ~1.6 stray blobs (3-6 cm) per m^2.
    """
    per_m2 = spacing_m**2  # surface area of one point
    labels = np.where(truth >= TABLE, truth, 0).astype(np.uint8)  # structure: not the network's
    target = np.flatnonzero(truth >= TABLE)
    tree = cKDTree(points)
    # missed patches: the network saw background on part of an object
    seeds = rng.choice(target, round(len(target) * per_m2 * _MISSED_PER_M2), replace=False)
    for ball in tree.query_ball_point(points[seeds], rng.uniform(0.05, 0.12, len(seeds))):
        hit = np.asarray(ball, np.intp)
        labels[hit[truth[hit] >= TABLE]] = 0
    # boundary bleed: an object's label spills onto the background around it
    background = np.flatnonzero(truth < TABLE)
    distance, nearest = cKDTree(points[target]).query(points[background], distance_upper_bound=0.05)
    near = np.isfinite(distance) & (rng.random(len(background)) < 0.8)
    labels[background[near]] = truth[target[nearest[near]]]
    # stray blobs: small patches of a wrong class, on objects and on unlabelled furniture
    candidates = np.flatnonzero((truth >= TABLE) | (truth == 0))
    seeds = rng.choice(candidates, round(len(candidates) * per_m2 * _STRAY_PER_M2), replace=False)
    balls = tree.query_ball_point(points[seeds], rng.uniform(0.03, 0.06, len(seeds)))
    for seed, ball in zip(seeds, balls, strict=True):
        wrong = rng.choice([c for c in range(TABLE, CLUTTER + 1) if c != truth[seed]])
        hit = np.asarray(ball, np.intp)
        labels[hit[truth[hit] == truth[seed]]] = wrong
    return labels


def _flying_pixels(
    points: npt.NDArray[np.float64], labels: npt.NDArray[np.uint8], rng: np.random.Generator
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.uint8]]:
    """Return sparse points hanging off labelled objects (depth edges), with their labels."""
    source = rng.choice(np.flatnonzero(labels >= TABLE), len(points) // 150, replace=False)
    direction = rng.normal(size=(len(source), 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    flying = points[source] + direction * rng.uniform(0.05, 0.4, (len(source), 1))
    flying[:, 2] = np.maximum(flying[:, 2], 0.05)
    keep = rng.random(len(source)) < 0.7
    return flying, np.where(keep, labels[source], 0).astype(np.uint8)
