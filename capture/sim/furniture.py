"""Furniture built from parts in its own frame: origin on the floor, front towards -y, z up.

Parts of one object touch but do not overlap where that is easy, so the ground-truth cloud sampled
from them lies on surfaces a camera can see. Sizes follow common furniture dimensions.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from capture.recording import Label
from capture.sim import palette as pal
from capture.sim.shapes import Mesh, box, cylinder, ellipsoid
from capture.sim.textures import Material


@dataclass(slots=True)
class Assembly:
    """An object in its own frame: a label, a name and (mesh, material) parts."""

    label: int
    name: str
    parts: list[tuple[Mesh, Material]] = field(default_factory=list)
    top_m: tuple[float, float, float] | None = None  # support surface: (width, depth, height)

    def add(self, mesh: Mesh, material: Material) -> None:
        """Append a part."""
        self.parts.append((mesh, material))

    @property
    def bounds(self) -> np.ndarray:
        """Return the local axis-aligned bounds (2, 3)."""
        b = np.stack([m.bounds for m, _ in self.parts])
        return np.stack([b[:, 0].min(axis=0), b[:, 1].max(axis=0)])


def _legs(a: Assembly, w: float, d: float, h: float, t: float, mat: Material) -> None:
    for sx in (-1, 1):
        for sy in (-1, 1):
            a.add(box((t, t, h), center=(sx * (w - t) / 2, sy * (d - t) / 2, h / 2)), mat)


def table(rng: np.random.Generator, *, width: float, depth: float, height: float) -> Assembly:
    """Return a four-legged table (or a round pedestal table when width == depth < 1 m)."""
    a = Assembly(Label.TABLE, "table")
    top, legs = pal.wood(rng), (pal.wood(rng) if rng.random() < 0.5 else pal.metal(rng))
    t = float(rng.uniform(0.025, 0.045))
    if width == depth and width < 1.0:
        a.add(cylinder(width / 2, t, center=(0, 0, height - t / 2), resolution=24), top)
        a.add(cylinder(0.04, height - t - 0.03, center=(0, 0, (height - t + 0.03) / 2)), legs)
        a.add(cylinder(0.25, 0.03, center=(0, 0, 0.015), resolution=20), legs)
    else:
        a.add(box((width, depth, t), center=(0, 0, height - t / 2)), top)
        inset = 0.04
        _legs(
            a,
            width - 2 * inset,
            depth - 2 * inset,
            height - t,
            float(rng.uniform(0.04, 0.07)),
            legs,
        )
    a.top_m = (width, depth, height)
    return a


def chair(rng: np.random.Generator) -> Assembly:
    """Return a chair: four legs, a seat and a back of slats or a panel (back at +y)."""
    a = Assembly(Label.CHAIR, "chair")
    frame = pal.wood(rng) if rng.random() < 0.6 else pal.metal(rng)
    seat = pal.fabric(rng) if rng.random() < 0.5 else pal.plastic(rng)
    w, d = rng.uniform(0.40, 0.48, 2)
    h, t, leg = rng.uniform(0.42, 0.48), rng.uniform(0.03, 0.05), rng.uniform(0.03, 0.04)
    _legs(a, w, d, h - t, leg, frame)
    a.add(box((w, d, t), center=(0, 0, h - t / 2)), seat)
    back_h, back_t = rng.uniform(0.35, 0.50), 0.025
    for sx in (-1, 1):  # back posts continue the rear legs
        a.add(
            box((leg, leg, back_h), center=(sx * (w - leg) / 2, (d - leg) / 2, h + back_h / 2)),
            frame,
        )
    inner = w - 2 * leg
    if rng.random() < 0.5:
        a.add(
            box((inner, back_t, back_h * 0.6), center=(0, (d - leg) / 2, h + back_h * 0.65)), seat
        )
    else:
        slats = int(rng.integers(2, 5))
        for k in range(slats):
            z = h + back_h * (0.3 + 0.65 * k / max(1, slats - 1)) - 0.03
            a.add(box((inner, back_t, 0.05), center=(0, (d - leg) / 2, z)), frame)
    return a


def monitor(rng: np.random.Generator) -> Assembly:
    """Return a desk monitor on a stand, screen facing -y."""
    a = Assembly(Label.TV_MONITOR, "tv monitor")
    body = pal.material(rng, "speckle", (*pal.METALS[:1], (0.22, 0.22, 0.24)), contrast=0.2)
    screen = pal.material(rng, "screen", ((0.15, 0.35, 0.6), (0.3, 0.5, 0.35), (0.5, 0.3, 0.5)))
    w = float(rng.uniform(0.45, 0.65))
    h, neck = w * 0.6, float(rng.uniform(0.08, 0.14))
    a.add(box((0.22, 0.16, 0.015), center=(0, 0, 0.0075)), body)
    a.add(box((0.05, 0.03, neck), center=(0, 0.03, 0.015 + neck / 2)), body)
    z0 = 0.015 + neck
    a.add(box((w, 0.035, h), center=(0, 0.0, z0 + h / 2)), body)
    a.add(box((w - 0.03, 0.004, h - 0.03), center=(0, -0.0195, z0 + h / 2)), screen)
    return a


def wall_tv(rng: np.random.Generator) -> Assembly:
    """Return a flat television hung on a wall (origin at its bottom edge), screen to -y."""
    a = Assembly(Label.TV_MONITOR, "tv monitor")
    body = pal.material(rng, "speckle", ((0.08, 0.08, 0.09),), contrast=0.2)
    on = rng.random() < 0.6
    colors = ((0.2, 0.4, 0.7), (0.6, 0.4, 0.2)) if on else ((0.05, 0.05, 0.06),)
    screen = pal.material(rng, "screen" if on else "noise", colors, glossy=True, contrast=0.1)
    w = float(rng.uniform(0.9, 1.4))
    h = w * 0.58
    a.add(box((w, 0.05, h), center=(0, 0, h / 2)), body)
    a.add(box((w - 0.04, 0.004, h - 0.04), center=(0, -0.027, h / 2)), screen)
    return a


def sofa(rng: np.random.Generator) -> Assembly:
    """Return a sofa: legs, base, seat cushions, back and two arms (back at +y)."""
    a = Assembly(Label.SOFA, "sofa")
    cloth, legs = pal.fabric(rng), pal.wood(rng)
    w, d = float(rng.uniform(1.6, 2.3)), float(rng.uniform(0.80, 0.95))
    leg_h, seat_h, arm_w = 0.08, float(rng.uniform(0.40, 0.46)), float(rng.uniform(0.15, 0.24))
    back_t, back_h, arm_h = 0.2, float(rng.uniform(0.80, 0.92)), float(rng.uniform(0.55, 0.65))
    _legs(a, w - 0.1, d - 0.1, leg_h, 0.05, legs)
    inner, base_top = w - 2 * arm_w, seat_h - 0.14
    a.add(
        box((inner, d - back_t, base_top - leg_h), center=(0, -back_t / 2, (leg_h + base_top) / 2)),
        cloth,
    )
    n = int(rng.integers(2, 4))
    for k in range(n):  # cushions with 1 cm gaps, whose seams give corners
        cw = inner / n - 0.01
        x = -inner / 2 + (k + 0.5) * inner / n
        a.add(box((cw, d - back_t - 0.01, 0.14), center=(x, -back_t / 2, base_top + 0.07)), cloth)
    a.add(
        box((inner, back_t, back_h - leg_h), center=(0, d / 2 - back_t / 2, (leg_h + back_h) / 2)),
        cloth,
    )
    for sx in (-1, 1):
        a.add(
            box((arm_w, d, arm_h - leg_h), center=(sx * (w - arm_w) / 2, 0, (leg_h + arm_h) / 2)),
            cloth,
        )
    return a


def plant(rng: np.random.Generator, *, tall: bool) -> Assembly:
    """Return a potted plant: a pot, soil and a bush of leafy ellipsoids."""
    a = Assembly(Label.PLANT, "plant")
    r, pot_h = float(rng.uniform(0.12, 0.2)), float(rng.uniform(0.2, 0.35))
    a.add(
        cylinder(r, pot_h, center=(0, 0, pot_h / 2), top_scale=1.2, resolution=20),
        pal.material(rng, "speckle", pal.POTS, contrast=0.3),
    )
    a.add(
        cylinder(r * 1.1, 0.01, center=(0, 0, pot_h + 0.005), resolution=20),
        pal.material(rng, "speckle", ((0.25, 0.17, 0.1),), contrast=0.6),
    )
    leaves = pal.material(rng, "leaves", pal.LEAVES, texel_m=0.003)
    bush_h = float(rng.uniform(0.8, 1.3) if tall else rng.uniform(0.3, 0.6))
    stem_top = pot_h + 0.01 + bush_h * 0.35
    a.add(
        cylinder(0.015, stem_top - pot_h - 0.01, center=(0, 0, (stem_top + pot_h + 0.01) / 2)),
        pal.material(rng, "noise", ((0.3, 0.22, 0.1),)),
    )
    spread = min(0.45, r * 2.2)
    for _ in range(int(rng.integers(4, 8))):
        rx, ry = rng.uniform(0.35, 0.6, 2) * spread
        rz = rng.uniform(0.2, 0.35) * bush_h
        cx, cy = rng.uniform(-0.4, 0.4, 2) * spread
        cz = float(np.clip(rng.uniform(stem_top, pot_h + bush_h - rz), stem_top, None))
        a.add(ellipsoid((rx, ry, rz), center=(cx, cy, cz)), leaves)
    return a
