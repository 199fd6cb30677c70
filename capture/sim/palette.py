"""Class-typical colours and materials, varied per seed (wood, fabric, plastic, leaves, skin...)."""

from __future__ import annotations

from typing import Final

import numpy as np

from capture.sim.textures import Material

RGB = tuple[float, float, float]

WOODS: Final[tuple[RGB, ...]] = (
    (0.55, 0.38, 0.22),
    (0.72, 0.55, 0.35),
    (0.40, 0.26, 0.15),
    (0.82, 0.70, 0.52),
)
PAINTS: Final[tuple[RGB, ...]] = (
    (0.93, 0.92, 0.88),
    (0.90, 0.86, 0.76),
    (0.82, 0.84, 0.86),
    (0.78, 0.86, 0.92),
    (0.82, 0.90, 0.80),
    (0.94, 0.90, 0.74),
)
FABRICS: Final[tuple[RGB, ...]] = (
    (0.45, 0.47, 0.50),
    (0.20, 0.30, 0.55),
    (0.30, 0.45, 0.30),
    (0.50, 0.32, 0.22),
    (0.62, 0.18, 0.18),
    (0.70, 0.65, 0.55),
)
PLASTICS: Final[tuple[RGB, ...]] = (
    (0.85, 0.15, 0.12),
    (0.15, 0.35, 0.75),
    (0.12, 0.12, 0.13),
    (0.92, 0.92, 0.90),
    (0.95, 0.70, 0.10),
    (0.25, 0.60, 0.35),
)
METALS: Final[tuple[RGB, ...]] = ((0.15, 0.15, 0.16), (0.60, 0.62, 0.65), (0.80, 0.80, 0.82))
LEAVES: Final[tuple[RGB, ...]] = ((0.20, 0.50, 0.15), (0.30, 0.58, 0.22), (0.15, 0.40, 0.20))
POTS: Final[tuple[RGB, ...]] = ((0.72, 0.38, 0.22), (0.90, 0.90, 0.88), (0.35, 0.35, 0.38))
SKINS: Final[tuple[RGB, ...]] = ((0.95, 0.80, 0.68), (0.80, 0.60, 0.45), (0.55, 0.38, 0.27))
GLASS: Final[tuple[RGB, ...]] = ((0.20, 0.55, 0.25), (0.50, 0.30, 0.12), (0.55, 0.75, 0.85))


def pick(rng: np.random.Generator, colors: tuple[RGB, ...], *, spread: float = 0.08) -> RGB:
    """Return one of `colors` with a small per-seed variation of each channel."""
    base = np.asarray(colors[int(rng.integers(len(colors)))])
    varied = np.clip(base * rng.uniform(1.0 - spread, 1.0 + spread, 3), 0.0, 1.0)
    return (float(varied[0]), float(varied[1]), float(varied[2]))


def material(
    rng: np.random.Generator,
    kind: str,
    colors: tuple[RGB, ...],
    *,
    texel_m: float = 0.004,
    contrast: float = 0.3,
    glossy: bool = False,
) -> Material:
    """Return a material of `kind` in a colour picked from `colors`."""
    return Material(
        kind=kind,
        color=pick(rng, colors),
        texel_m=texel_m,
        contrast=contrast,
        glossy=glossy,
        seed=int(rng.integers(2**31)),
    )


def wood(rng: np.random.Generator) -> Material:
    """Return a wood material (grain along planks)."""
    return material(rng, "planks", WOODS, texel_m=0.002, contrast=0.5)


def fabric(rng: np.random.Generator) -> Material:
    """Return an upholstery fabric."""
    return material(rng, "weave", FABRICS, texel_m=0.002, contrast=0.35)


def plastic(rng: np.random.Generator) -> Material:
    """Return a coloured plastic with faint speckle."""
    return material(rng, "speckle", PLASTICS, texel_m=0.002, contrast=0.25)


def metal(rng: np.random.Generator) -> Material:
    """Return a brushed metal."""
    return material(rng, "brushed", METALS, texel_m=0.001, contrast=0.3)
