"""Procedural, tileable surface textures: noise, planks, tiles, weave, leaves, screens, spines.

Every texture is a square RGB image of `TEXTURE_SIZE` texels that repeats without seams, so the
renderer can look a hit point up by world coordinates modulo the tile (a triplanar mapping).
Patterns with edges and corners (plank seams, tile grout, windows on a screen, book spines) are
there so that feature trackers such as ORB find stable keypoints, as on real furniture.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Final

import numpy as np
import numpy.typing as npt

TEXTURE_SIZE: Final = 256  # texels per side, a power of two so the lookup can wrap with a mask
FloatImage = npt.NDArray[np.float32]


@dataclass(frozen=True, slots=True)
class Material:
    """How a surface looks: a base colour, a pattern, the texel size and its IR behaviour."""

    kind: str  # one of PATTERNS
    color: tuple[float, float, float]  # RGB in [0, 1]
    texel_m: float = 0.004  # metres per texel
    contrast: float = 0.3
    glossy: bool = False  # specular: the D435 loses depth where it mirrors the projector
    seed: int = 0


def fbm(rng: np.random.Generator, *, beta: float = 2.0, size: int = TEXTURE_SIZE) -> FloatImage:
    """Return tileable fractal noise in [0, 1] with a 1/f^beta power spectrum."""
    white = rng.standard_normal((size, size))
    f = np.hypot(*np.meshgrid(np.fft.fftfreq(size), np.fft.fftfreq(size), indexing="ij"))
    f[0, 0] = 1.0
    field = np.real(np.fft.ifft2(np.fft.fft2(white) / f ** (beta / 2)))
    lo, hi = field.min(), field.max()
    return np.asarray((field - lo) / (hi - lo + 1e-12), np.float32)


def _stretched(rng: np.random.Generator, factor: int) -> FloatImage:
    """Return noise stretched along the first texture axis (grain, brushed metal)."""
    small = fbm(rng, beta=1.6, size=TEXTURE_SIZE // factor)
    return np.asarray(np.repeat(small, factor, axis=0)[:, np.arange(TEXTURE_SIZE) % small.shape[1]])


def _gray(pattern: npt.ArrayLike, color: tuple[float, float, float], contrast: float) -> FloatImage:
    """Return the colour modulated by a pattern around its mean: 1 + contrast * (p - mean)."""
    p = np.asarray(pattern, np.float32)
    mod = 1.0 + contrast * (p - p.mean())
    return np.asarray(np.clip(mod[..., None] * np.asarray(color, np.float32), 0.0, 1.0), np.float32)


def _noise(m: Material, rng: np.random.Generator) -> FloatImage:
    pattern = 0.7 * fbm(rng, beta=2.2) + 0.3 * fbm(rng, beta=0.6)
    return _gray(pattern, m.color, m.contrast)


def _planks(m: Material, rng: np.random.Generator) -> FloatImage:
    n, width = TEXTURE_SIZE, TEXTURE_SIZE // 8
    grain = _stretched(rng, 8)
    tone = rng.uniform(-0.5, 0.5, 8)[np.arange(n) // width]
    pattern = 0.6 * grain + 0.4 * tone[None, :]
    pattern[:, np.arange(n) % width < 2] = -0.8  # long seams between planks
    for k in range(8):  # staggered end joints
        row = int(rng.integers(0, n - 2))
        pattern[row : row + 2, k * width : (k + 1) * width] = -0.8
    return _gray(pattern, m.color, m.contrast)


def _tiles(m: Material, rng: np.random.Generator) -> FloatImage:
    n, period = TEXTURE_SIZE, TEXTURE_SIZE // 4
    idx = np.arange(n) // period
    tone = rng.uniform(-0.4, 0.4, (4, 4))[idx[:, None], idx[None, :]]
    pattern = tone + 0.4 * fbm(rng, beta=1.5)
    grout = (np.arange(n) % period) < 3
    pattern[grout, :] = -1.2
    pattern[:, grout] = -1.2
    return _gray(pattern, m.color, m.contrast)


def _weave(m: Material, rng: np.random.Generator) -> FloatImage:
    u = np.arange(TEXTURE_SIZE) * (2 * np.pi / 4)
    weave = np.sin(u)[:, None] * np.sin(u)[None, :]
    return _gray((0.3 * weave + fbm(rng, beta=2.0)).astype(np.float32), m.color, m.contrast)


def _stripes(m: Material, rng: np.random.Generator) -> FloatImage:
    period = int(rng.choice([16, 32, 64]))
    stripes = ((np.arange(TEXTURE_SIZE) % period) < period // 2).astype(np.float32)
    ornament = (fbm(rng, beta=0.8) > 0.75).astype(np.float32)
    pattern = stripes[None, :] + 0.5 * ornament + 0.5 * fbm(rng, beta=2.0)
    return _gray(pattern, m.color, m.contrast)


def _leaves(m: Material, rng: np.random.Generator) -> FloatImage:
    blobs = fbm(rng, beta=1.2)
    light = np.clip(np.asarray(m.color, np.float32) * 1.5, 0.0, 1.0)
    dark = np.asarray(m.color, np.float32) * 0.35
    t = np.clip((blobs - 0.35) * 4.0, 0.0, 1.0)[..., None]
    return np.asarray(dark + t * (light - dark), np.float32)


def _speckle(m: Material, rng: np.random.Generator) -> FloatImage:
    return _gray(0.5 * fbm(rng, beta=0.3) + 0.5 * fbm(rng, beta=2.0), m.color, m.contrast)


def _brushed(m: Material, rng: np.random.Generator) -> FloatImage:
    return _gray(_stretched(rng, 16), m.color, m.contrast)


def _panels(m: Material, rng: np.random.Generator) -> FloatImage:
    n, period = TEXTURE_SIZE, TEXTURE_SIZE // 2
    pattern = 0.3 * fbm(rng, beta=1.0)
    lines = (np.arange(n) % period) < 3
    pattern[lines, :] = -1.0
    pattern[:, lines] = -1.0
    return _gray(pattern, m.color, m.contrast)


def _screen(m: Material, rng: np.random.Generator) -> FloatImage:
    n = TEXTURE_SIZE
    image = np.empty((n, n, 3), np.float32)
    image[:] = np.asarray(m.color, np.float32) * (0.6 + 0.4 * fbm(rng, beta=3.0))[..., None]
    for _ in range(int(rng.integers(3, 7))):  # windows with a title bar and lines of "text"
        r0, c0 = rng.integers(0, n - 64, 2)
        h, w = rng.integers(40, 120, 2)
        rows, cols = slice(r0, r0 + h), slice(c0, c0 + w)
        image[rows, cols] = rng.uniform(0.75, 1.0)
        image[r0 : r0 + 8, cols] = rng.uniform(0.1, 0.9, 3)
        for r in range(int(r0) + 14, int(r0 + h) - 4, 6):
            image[r : r + 2, int(c0) + 4 : int(c0 + rng.integers(10, max(11, w - 4)))] = 0.15
    return image


def _spines(m: Material, rng: np.random.Generator) -> FloatImage:
    edges = np.cumsum(rng.integers(6, 20, TEXTURE_SIZE))
    book = np.searchsorted(edges, np.arange(TEXTURE_SIZE), side="right")
    colors = rng.uniform(0.1, 0.9, (TEXTURE_SIZE + 1, 3)).astype(np.float32)
    image = np.broadcast_to(colors[book][None, :, :], (TEXTURE_SIZE, TEXTURE_SIZE, 3)).copy()
    image[:, np.isin(np.arange(TEXTURE_SIZE), edges)] *= 0.3
    return (image * (0.8 + 0.2 * fbm(rng, beta=2.0))[..., None]).astype(np.float32)


PATTERNS: Final[dict[str, Callable[[Material, np.random.Generator], FloatImage]]] = {
    "noise": _noise,
    "planks": _planks,
    "tiles": _tiles,
    "weave": _weave,
    "stripes": _stripes,
    "leaves": _leaves,
    "speckle": _speckle,
    "brushed": _brushed,
    "panels": _panels,
    "screen": _screen,
    "spines": _spines,
}


def make_texture(material: Material) -> npt.NDArray[np.uint8]:
    """Return the material's tileable RGB texture (TEXTURE_SIZE, TEXTURE_SIZE, 3) uint8."""
    rng = np.random.default_rng(material.seed)
    image = PATTERNS[material.kind](material, rng)
    return np.round(np.clip(image, 0.0, 1.0) * 255.0).astype(np.uint8)
