"""Small objects (bottles, cups, books, boxes, bins, keyboards) and a standing person."""

from __future__ import annotations

import numpy as np

from capture.recording import Label
from capture.sim import palette as pal
from capture.sim.furniture import Assembly
from capture.sim.shapes import box, cylinder, ellipsoid


def bottle(rng: np.random.Generator) -> Assembly:
    """Return a bottle: body, shoulder, neck and cap."""
    a = Assembly(Label.CLUTTER, "bottle")
    glass = pal.material(rng, "noise", pal.GLASS, glossy=True, contrast=0.2, texel_m=0.001)
    cap = pal.plastic(rng)
    r, h = float(rng.uniform(0.03, 0.045)), float(rng.uniform(0.14, 0.24))
    a.add(cylinder(r, h, center=(0, 0, h / 2)), glass)
    a.add(cylinder(r, 0.04, center=(0, 0, h + 0.02), top_scale=0.4), glass)
    a.add(cylinder(r * 0.4, 0.04, center=(0, 0, h + 0.06), resolution=10), glass)
    a.add(cylinder(r * 0.45, 0.02, center=(0, 0, h + 0.09), resolution=10), cap)
    return a


def cup(rng: np.random.Generator) -> Assembly:
    """Return a mug (a closed cylinder)."""
    a = Assembly(Label.CLUTTER, "cup")
    h = float(rng.uniform(0.08, 0.11))
    a.add(cylinder(float(rng.uniform(0.035, 0.045)), h, center=(0, 0, h / 2)), pal.plastic(rng))
    return a


def books(rng: np.random.Generator) -> Assembly:
    """Return a stack of two to five books."""
    a = Assembly(Label.CLUTTER, "books")
    z = 0.0
    for _ in range(int(rng.integers(2, 6))):
        w, d, t = rng.uniform(0.15, 0.25), rng.uniform(0.2, 0.3), rng.uniform(0.02, 0.05)
        cover = pal.material(rng, "spines", ((0.5, 0.5, 0.5),), texel_m=0.001)
        a.add(box((w, d, t), center=(*rng.uniform(-0.01, 0.01, 2), z + t / 2)), cover)
        z += t
    return a


def carton(rng: np.random.Generator) -> Assembly:
    """Return a cardboard box standing on the floor."""
    a = Assembly(Label.CLUTTER, "box")
    w, d, h = rng.uniform(0.25, 0.6, 3)
    cardboard = pal.material(rng, "speckle", ((0.65, 0.5, 0.32),), contrast=0.4, texel_m=0.002)
    a.add(box((w, d, h), center=(0, 0, h / 2)), cardboard)
    return a


def waste_bin(rng: np.random.Generator) -> Assembly:
    """Return a waste bin (a frustum)."""
    a = Assembly(Label.CLUTTER, "bin")
    h = float(rng.uniform(0.3, 0.42))
    a.add(cylinder(0.12, h, center=(0, 0, h / 2), top_scale=1.25, resolution=20), pal.plastic(rng))
    return a


def keyboard(rng: np.random.Generator) -> Assembly:
    """Return a keyboard whose tile pattern draws the keys."""
    a = Assembly(Label.CLUTTER, "keyboard")
    keys = pal.material(rng, "tiles", pal.METALS, texel_m=0.00025, contrast=0.5)
    a.add(box((0.44, 0.14, 0.02), center=(0, 0, 0.01)), keys)
    return a


def person(rng: np.random.Generator) -> Assembly:
    """Return a standing person facing -y: shoes, legs, torso, arms, neck and head."""
    a = Assembly(Label.PERSON, "person")
    s = float(rng.uniform(1.55, 1.9)) / 1.75  # scale of a 1.75 m body
    skin = pal.material(rng, "noise", pal.SKINS, contrast=0.1)
    shirt = pal.material(rng, "weave", pal.FABRICS + pal.PLASTICS, texel_m=0.002)
    trousers = pal.material(rng, "weave", ((0.15, 0.2, 0.4), (0.1, 0.1, 0.1), (0.6, 0.55, 0.4)))
    shoes = pal.material(rng, "speckle", ((0.1, 0.08, 0.07), (0.9, 0.9, 0.9)))
    hair = pal.material(rng, "noise", ((0.1, 0.07, 0.05), (0.45, 0.3, 0.15), (0.8, 0.7, 0.4)))
    for sx in (-1, 1):
        a.add(
            box((0.1 * s, 0.26 * s, 0.07 * s), center=(sx * 0.1 * s, -0.04 * s, 0.035 * s)), shoes
        )
        a.add(cylinder(0.07 * s, 0.8 * s, center=(sx * 0.1 * s, 0, 0.47 * s)), trousers)
        a.add(cylinder(0.045 * s, 0.62 * s, center=(sx * 0.25 * s, 0, 1.12 * s)), shirt)
        a.add(
            ellipsoid((0.045 * s, 0.045 * s, 0.07 * s), center=(sx * 0.25 * s, 0, 0.74 * s)), skin
        )
    a.add(box((0.38 * s, 0.22 * s, 0.6 * s), center=(0, 0, 1.17 * s)), shirt)
    a.add(cylinder(0.05 * s, 0.08 * s, center=(0, 0, 1.51 * s)), skin)
    a.add(ellipsoid((0.085 * s, 0.1 * s, 0.12 * s), center=(0, 0, 1.66 * s)), skin)
    a.add(ellipsoid((0.09 * s, 0.105 * s, 0.06 * s), center=(0, 0.01 * s, 1.74 * s)), hair)
    return a
