"""preview.png: a small top view of a labelled map, coloured by label, with a legend and a scale.

Drawn with OpenCV: each point is a square in its label's colour (RECORDING.md), the highest
point of a pixel on top; ceiling points are left out so the room shows from above. "Up" is the
normal of the floor points where there are enough, else the caller's hint (the first camera's
up), else +z.
"""

from __future__ import annotations

from pathlib import Path
from typing import Final

import cv2
import numpy as np
import numpy.typing as npt

from capture.recording import LABEL_COLORS, LABEL_NAMES
from process.outputs import atomic_path

MAP_PX: Final = 480  # side of the square the map is drawn in
LEGEND_PX: Final = 150  # width of the legend on its right
MARGIN_PX: Final = 12
POINT_PX: Final = 2  # side of the square drawn per point
CEILING: Final = LABEL_NAMES.index("ceiling")
FLOOR: Final = LABEL_NAMES.index("floor")
MIN_FLOOR_POINTS: Final = 50
BACKGROUND: Final = (255, 255, 255)
TEXT_RGB: Final = (40, 40, 40)

FloatArray = npt.ArrayLike  # (N, 3) or (3,) floats
Image = npt.NDArray[np.uint8]


def up_vector(
    points: FloatArray, labels: npt.NDArray[np.integer], hint: FloatArray | None = None
) -> npt.NDArray[np.float64]:
    """Return world up: the floor points' normal, else the hint, else +z.

    The floor normal is turned so that most other points lie above the floor (towards the hint
    when there are none).
    """
    up = np.array([0.0, 0.0, 1.0]) if hint is None else np.asarray(hint, np.float64)
    up = up / np.linalg.norm(up)
    xyz = np.asarray(points, np.float64).reshape(-1, 3)
    on_floor = np.asarray(labels).reshape(-1) == FLOOR
    if on_floor.sum() < MIN_FLOOR_POINTS:
        return up
    floor = xyz[on_floor]
    normal: npt.NDArray[np.float64] = np.linalg.svd(
        floor - floor.mean(axis=0), full_matrices=False
    )[2][2]
    others = xyz[~on_floor] - floor.mean(axis=0)
    above = float(np.median(others @ normal)) if len(others) else float(normal @ up)
    return normal if above >= 0 else -normal


def _plane_axes(up: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Return two unit axes spanning the plane normal to up (rows): world x (or y) and up x it.

    With up = +z the picture's columns are world x and its rows world y, north up.
    """
    for axis in np.eye(3)[:2]:
        x = axis - (axis @ up) * up
        if np.linalg.norm(x) > 0.1:
            break
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(up, x)])


def render_top_view(
    points: FloatArray, labels: npt.NDArray[np.integer], *, up: FloatArray | None = None
) -> Image:
    """Return an RGB picture of the map seen from above, with its legend and a 1 m scale bar.

    Args:
        points: (N, 3) world points in metres.
        labels: (N,) RECORDING.md label ids.
        up: world up (e.g. from up_vector); None: up_vector's choice.
    """
    xyz = np.asarray(points, np.float64).reshape(-1, 3)
    ids = np.asarray(labels).astype(np.intp).reshape(-1)
    up_ = up_vector(xyz, ids) if up is None else np.asarray(up, np.float64)
    keep = ids != CEILING
    xyz, ids = xyz[keep], ids[keep]
    image = np.full((MAP_PX, MAP_PX + LEGEND_PX, 3), BACKGROUND, np.uint8)
    if len(xyz) == 0:
        _text(image, "empty map", (MARGIN_PX, MAP_PX // 2))
        return image
    uv = xyz @ _plane_axes(up_ / np.linalg.norm(up_)).T
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    px_per_m = (MAP_PX - 2 * MARGIN_PX - POINT_PX) / max(float((hi - lo).max()), 1e-6)
    cols_rows = ((uv - lo) * px_per_m).astype(np.intp) + MARGIN_PX
    cols_rows[:, 1] = MAP_PX - 1 - cols_rows[:, 1]  # image rows grow downwards
    _splat(image, cols_rows, ids, height=xyz @ up_)
    _legend(image, ids)
    _scale_bar(image, px_per_m)
    return image


def _splat(
    image: Image,
    cols_rows: npt.NDArray[np.intp],
    ids: npt.NDArray[np.intp],
    *,
    height: npt.NDArray[np.float64],
) -> None:
    """Draw each point as a POINT_PX square in its label colour, the highest on top."""
    order = np.argsort(height, kind="stable")  # low to high
    offsets = np.array([(dx, -dy) for dy in range(POINT_PX) for dx in range(POINT_PX)])
    cr = (cols_rows[order][None, :, :] + offsets[:, None, :]).reshape(-1, 2)
    cr = np.clip(cr, 0, MAP_PX - 1)
    label = np.tile(ids[order], len(offsets))
    rank = np.tile(np.arange(len(order)), len(offsets))  # higher rank: higher point
    key = cr[:, 1] * MAP_PX + cr[:, 0]
    by_pixel = np.lexsort((-rank, key))  # per pixel, the highest point first
    first = by_pixel[np.r_[True, key[by_pixel][1:] != key[by_pixel][:-1]]]
    image[cr[first, 1], cr[first, 0]] = np.array(LABEL_COLORS, np.uint8)[label[first]]


def _legend(image: Image, ids: npt.NDArray[np.intp]) -> None:
    """List the labels present, most points first, each with its colour."""
    counts = np.bincount(ids, minlength=len(LABEL_NAMES))
    x = MAP_PX + 8
    for row, label in enumerate(np.argsort(-counts, kind="stable")[: int((counts > 0).sum())]):
        y = MARGIN_PX + 22 * row
        colour = tuple(int(v) for v in LABEL_COLORS[label])
        cv2.rectangle(image, (x, y), (x + 14, y + 14), colour, thickness=-1)
        cv2.rectangle(image, (x, y), (x + 14, y + 14), TEXT_RGB, thickness=1)
        _text(image, LABEL_NAMES[label], (x + 20, y + 12))


def _scale_bar(image: Image, px_per_m: float) -> None:
    """Draw a 1 m bar (or 0.1 m for a small map) at the bottom of the legend."""
    metres = 1.0 if px_per_m * 1.0 <= LEGEND_PX - 20 else 0.1
    length = round(px_per_m * metres)
    x, y = MAP_PX + 8, MAP_PX - MARGIN_PX
    cv2.line(image, (x, y), (x + length, y), TEXT_RGB, thickness=3)
    _text(image, f"{metres:g} m", (x, y - 8))


def _text(image: Image, text: str, origin: tuple[int, int]) -> None:
    cv2.putText(image, text, origin, cv2.FONT_HERSHEY_SIMPLEX, 0.45, TEXT_RGB, 1, cv2.LINE_AA)


def write_preview(
    path: Path,
    points: FloatArray,
    labels: npt.NDArray[np.integer],
    *,
    up_hint: FloatArray | None = None,
) -> Path:
    """Write the top view of a labelled map as a PNG (through a temporary name); return path."""
    image = render_top_view(points, labels, up=up_vector(points, labels, up_hint))
    ok, png = cv2.imencode(".png", image[..., ::-1], [cv2.IMWRITE_PNG_COMPRESSION, 9])
    if not ok:
        raise ValueError(f"could not encode the preview of {np.shape(points)} points as PNG")
    with atomic_path(path) as tmp:
        tmp.write_bytes(png.tobytes())
    return path
