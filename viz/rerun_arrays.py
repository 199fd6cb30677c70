"""Numpy arrays checked and shaped for Rerun: millimetre depth, (N, 3) points, curves, colours."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Final, Literal

import cv2
import numpy as np
import numpy.typing as npt
import rerun as rr

from capture.recording import LABEL_COLORS, LABEL_NAMES
from viz.logger import FloatArray, IntArray

_MM_PER_M: Final = 1000.0


# PNG level 1 with run-length matching: on 15 TUM fr1_rpy depth frames ~95 KB in ~10 ms each,
# smaller and faster than the default strategy at level 1 (110 KB, 14 ms) or 3 (99 KB, 20 ms);
# rerun's own DepthImage.compress (PIL) gave ~106 KB at level 1. Measured under load.
_PNG_PARAMS: Final = [
    cv2.IMWRITE_PNG_COMPRESSION,
    1,
    cv2.IMWRITE_PNG_STRATEGY,
    cv2.IMWRITE_PNG_STRATEGY_RLE,
]


def millimetres(depth_m: FloatArray) -> npt.NDArray[np.uint16]:
    """Return depth in whole millimetres (0 = none), clipped to uint16."""
    mm: npt.NDArray[np.uint16] = np.clip(depth_m * _MM_PER_M + 0.5, 0.0, 65535.0).astype(np.uint16)
    return mm


def depth_image(depth_m: FloatArray) -> rr.DepthImage:
    """Return a raw depth image in whole millimetres (half the bytes of float32 in the .rrd)."""
    return rr.DepthImage(millimetres(depth_m), meter=_MM_PER_M)


def depth_png(depth_m: FloatArray) -> rr.EncodedDepthImage:
    """Return depth in whole millimetres as a lossless 16-bit PNG."""
    ok, png = cv2.imencode(".png", millimetres(depth_m), _PNG_PARAMS)
    if not ok:
        raise ValueError(f"could not encode a depth image of shape {np.shape(depth_m)} as PNG")
    return rr.EncodedDepthImage(blob=png.tobytes(), media_type="image/png", meter=_MM_PER_M)


def image(
    pixels: npt.NDArray[np.uint8], model: Literal["RGB", "L"], *, jpeg_quality: int | None
) -> rr.Image | rr.EncodedImage:
    """Return an image as JPEG at jpeg_quality, or raw for None."""
    raw = rr.Image(pixels, color_model=model)
    return raw if jpeg_quality is None else raw.compress(jpeg_quality=jpeg_quality)


def depth(depth_m: FloatArray, *, png: bool) -> rr.DepthImage | rr.EncodedDepthImage:
    """Return depth in millimetres as a lossless PNG, or raw."""
    return depth_png(depth_m) if png else depth_image(depth_m)


def points(points: FloatArray, name: str) -> npt.NDArray[np.float32]:
    """Return (N, 3) float32 points, or raise ValueError naming the argument."""
    arr = np.asarray(points, dtype=np.float32)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"expected {name} of shape (N, 3), found {arr.shape}; pass xyz rows")
    return arr


def path_of(kind: str, kinds: Mapping[str, str], what: str) -> str:
    """Return the entity path of a kind, or raise ValueError listing the valid kinds."""
    if kind not in kinds:
        raise ValueError(f"expected a {what} kind in {sorted(kinds)}, found {kind!r}")
    return kinds[kind]


def curves_over_k(
    ks: IntArray, curves: Mapping[str, npt.ArrayLike], *, chosen_k: int
) -> tuple[npt.NDArray[np.int64], dict[str, npt.NDArray[np.float64]], npt.NDArray[np.intp]]:
    """Return ks, the curves as float64 and where chosen_k is; raise ValueError on a mismatch."""
    k = np.asarray(ks, dtype=np.int64)
    values = {name: np.asarray(v, dtype=np.float64) for name, v in curves.items()}
    if any(v.shape != k.shape for v in values.values()) or k.ndim != 1:
        shapes = {name: v.shape for name, v in values.items()}
        raise ValueError(f"expected curves of the shape of ks {k.shape}, found {shapes}")
    chosen = np.flatnonzero(k == chosen_k)
    if len(chosen) == 0:
        raise ValueError(f"expected chosen_k among ks {k.min()}..{k.max()}, found {chosen_k}")
    return k, values, chosen


def label_color(label_name: str) -> tuple[int, int, int] | None:
    """Return the colour of a label by name, None for an unknown name."""
    if label_name in LABEL_NAMES:
        return LABEL_COLORS[LABEL_NAMES.index(label_name)]
    return None
