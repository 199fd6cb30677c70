"""Generator 5's 2-D network: label images with the errors a segmentation network makes, per view.

Written blind to the refinement (issue 12). The network sees one rendered view (truth labels,
instances, parts and depth per pixel) and returns its label image. It labels objects only (structure
and background furniture are 0) and errs in image space, each family with a random strength per
object (drawn once) and per view:

- bleed: an object's mask dilated by 2-8 px along part of its outline, onto whatever lies beside or
  behind it in the image (often a wall metres behind);
- erosion: parts thinner than 3-9 px (legs, poles, stems, monitor stands, leaves) vanish (an
  opening of the mask);
- blobs: ellipses 15-60 px across inside an object set to 0, at random and at the object's
  "hard spots" (points fixed on its surface that the network misses from many views);
- confusion: the whole mask takes a plausible wrong class, in most views for a few objects and
  now and then for the others;
- speckle: low-confidence pixels near the outline take a random label of the ones in play.

Pixel sizes are given at REF_WIDTH and scale with the image width.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, Final

import cv2
import numpy as np
import numpy.typing as npt
from scipy import ndimage

from benchmarks import gen4_shapes as sh
from capture.recording import OBJECT_LABELS, Label

ERROR_NAMES: Final = ("bleed", "erosion", "blobs", "confusion", "speckle")
REF_WIDTH: Final = 424  # the pixel sizes of Gen5Errors are for images this wide
WRONG_CLASS: Final[dict[int, tuple[int, ...]]] = {
    Label.CHAIR: (Label.SOFA,),
    Label.SOFA: (Label.CHAIR,),
    Label.TABLE: (Label.CLUTTER,),
    Label.TV_MONITOR: (Label.CLUTTER,),
    Label.PERSON: (Label.CHAIR,),
    Label.PLANT: (Label.CLUTTER,),
}
_CLEAR_M2: Final = 1.0  # m2: bigger objects are picked for consistent confusion less often
_BEHIND_M: Final = 0.1  # bleed reaches an object pixel only this far behind the bleeding object


@dataclass(frozen=True)
class Gen5Errors:
    """Rates and sizes of the network's errors; a rate of 0 switches its family off."""

    bleed_rate: float = 0.8  # chance per object and view, times the object's propensity
    bleed_px: tuple[float, float] = (2.0, 8.0)  # dilation radius
    erosion_rate: float = 0.8
    erosion_px: tuple[float, float] = (3.0, 9.0)  # opening kernel: thinner parts vanish
    blob_rate: float = 2.0  # random blobs per view per 10,000 px of object, times propensity
    spot_rate: float = 0.8  # chance a visible hard spot is missed, times propensity
    spots_per_m2: float = 2.0  # hard spots per square metre of an object's surface
    blob_px: tuple[float, float] = (15.0, 60.0)  # blob diameter
    confusion_share: float = 0.15  # share of confusable objects (at least 1) confused in most views
    confusion_always: float = 0.8  # chance per view that such an object is confused
    confusion_now_and_then: float = 0.06  # the same for the other confusable objects
    speckle_rate: float = 0.15  # share of pixels near an outline with a random label
    speckle_px: float = 3.0  # half width of the band along the outline

    @classmethod
    def none(cls) -> Gen5Errors:
        """Return a network without errors (objects right, structure 0)."""
        off: dict[str, Any] = {name: 0.0 for names in _RATES.values() for name in names}
        return replace(cls(), **off)

    def only(self, family: str) -> Gen5Errors:
        """Return these errors with every family but `family` (one of ERROR_NAMES) off."""
        if family not in ERROR_NAMES:
            raise ValueError(f"expected an error family in {ERROR_NAMES}; got {family!r}")
        return replace(Gen5Errors.none(), **{n: getattr(self, n) for n in _RATES[family]})


_RATES: Final = {  # the fields that switch each family off when 0
    "bleed": ("bleed_rate",),
    "erosion": ("erosion_rate",),
    "blobs": ("blob_rate", "spot_rate"),
    "confusion": ("confusion_share", "confusion_now_and_then"),
    "speckle": ("speckle_rate",),
}


@dataclass(frozen=True)
class View:
    """One rendered view: the exact truth per pixel and the camera that saw it."""

    labels: npt.NDArray[np.uint8]  # (H, W) RECORDING.md label per pixel, 0 where nothing
    instances: npt.NDArray[np.int32]  # (H, W) object instance id, 0 where nothing
    parts: npt.NDArray[np.int32]  # (H, W) index into the room's parts, -1 where nothing
    depth_m: npt.NDArray[np.float32]  # (H, W) exact z-depth, 0 where nothing
    world_from_camera: npt.NDArray[np.float64]  # (4, 4) optical frame: x right, y down, z ahead
    focal: tuple[float, float, float, float]  # fx, fy, cx, cy in pixels


@dataclass(frozen=True)
class _Traits:
    """How one object fares with the network, drawn once per scene."""

    label: int
    wrong: int  # the class it is confused with in most views; 0 = only now and then
    propensity: npt.NDArray[np.float64]  # (5,) per ERROR_NAMES
    spots: npt.NDArray[np.float64]  # (K, 3) hard spots on its surface, world frame


class Network:
    """A segmentation network with fixed habits per object and fresh mistakes per view."""

    def __init__(self, parts: list[sh.Part], errors: Gen5Errors, rng: np.random.Generator) -> None:
        self.errors = errors
        self.traits: dict[int, _Traits] = {}
        objects = {p.instance: p.label for p in parts if p.label in OBJECT_LABELS}
        wrong = _confused(parts, objects, errors.confusion_share, rng)
        for inst, label in sorted(objects.items()):
            mine = [p for p in parts if p.instance == inst]
            area = sum(p.mesh.get_surface_area() for p in mine)
            spots = _surface_points(mine, int(rng.poisson(errors.spots_per_m2 * area)), rng)
            propensity = rng.uniform(0.25, 1.0, len(ERROR_NAMES))
            self.traits[inst] = _Traits(label, wrong.get(inst, 0), propensity, spots)

    def predict(self, view: View, rng: np.random.Generator) -> npt.NDArray[np.uint8]:
        """Return the network's label image (H, W) for `view`."""
        is_object = np.isin(view.labels, OBJECT_LABELS)
        pred = np.where(is_object, view.labels, 0).astype(np.uint8)
        scale = view.labels.shape[1] / REF_WIDTH
        e = self.errors
        margin = int(np.ceil(max(e.bleed_px[1], e.speckle_px) * scale)) + 2
        boxes = ndimage.find_objects(view.instances)
        seen = [(i + 1, b) for i, b in enumerate(boxes) if b is not None and i + 1 in self.traits]
        seen.sort(
            key=lambda ib: -float(np.median(view.depth_m[ib[1]][view.instances[ib[1]] == ib[0]]))
        )
        strength = rng.uniform(0.5, 1.5, len(ERROR_NAMES))  # this view's mood
        for inst, box in seen:
            roi = _grow(box, margin, pred.shape)
            t = self.traits[inst]
            p = strength * t.propensity
            crop = _Crop(view, roi, inst, pred[roi], is_object[roi])
            crop.out[crop.mask] = cls = self._class(t, p[3], rng)
            if rng.random() < e.erosion_rate * p[1]:
                _erode(crop, rng.uniform(*e.erosion_px) * scale)
            self._blobs(crop, t, p[2], scale, rng)
            if rng.random() < e.bleed_rate * p[0]:
                _bleed(crop, cls, rng.uniform(*e.bleed_px) * scale, rng)
            if e.speckle_rate > 0:
                _speckle(crop, cls, e.speckle_rate * p[4], e.speckle_px * scale, rng)
        return pred

    def _class(self, t: _Traits, p: float, rng: np.random.Generator) -> int:
        """Return the class the whole mask gets in this view."""
        if t.label not in WRONG_CLASS:
            return t.label
        if t.wrong and rng.random() < self.errors.confusion_always:
            return t.wrong
        if rng.random() < self.errors.confusion_now_and_then * p:
            return int(rng.choice(WRONG_CLASS[t.label]))
        return t.label

    def _blobs(
        self, crop: _Crop, t: _Traits, p: float, scale: float, rng: np.random.Generator
    ) -> None:
        """Set ellipses inside the mask to 0: at random, and at hard spots seen in this view."""
        e = self.errors
        n = int(rng.poisson(e.blob_rate * p * crop.mask.sum() / (1e4 * scale**2)))
        ys, xs = np.nonzero(crop.mask)
        centres = [(xs[i], ys[i]) for i in rng.integers(0, len(xs), n)] if len(xs) else []
        for x, y in _visible(crop, t.spots):
            if rng.random() < e.spot_rate * p:
                centres.append((x, y))
        if not centres:
            return
        canvas = np.zeros(crop.mask.shape, np.uint8)
        for x, y in centres:
            a, b = rng.uniform(*e.blob_px, 2) * scale / 2
            angle = rng.uniform(0, 180)
            cv2.ellipse(canvas, (int(x), int(y)), (int(a), int(b)), angle, 0, 360, 1, -1)
        crop.out[crop.mask & (canvas > 0)] = 0


@dataclass
class _Crop:
    """One object's neighbourhood in one view; `out` is a view into the label image."""

    view: View
    roi: tuple[slice, slice]
    instance: int
    out: npt.NDArray[np.uint8]
    is_object: npt.NDArray[np.bool_]

    @property
    def mask(self) -> npt.NDArray[np.bool_]:
        """Return the object's true silhouette in the crop."""
        return np.asarray(self.view.instances[self.roi] == self.instance)


def _grow(box: tuple[slice, slice], margin: int, shape: tuple[int, ...]) -> tuple[slice, slice]:
    rows, cols = box
    return (
        slice(max(0, rows.start - margin), min(shape[0], rows.stop + margin)),
        slice(max(0, cols.start - margin), min(shape[1], cols.stop + margin)),
    )


def _disk(radius: float) -> npt.NDArray[np.uint8]:
    size = 2 * max(1, round(radius)) + 1
    return np.asarray(cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size)), np.uint8)


def _erode(crop: _Crop, width_px: float) -> None:
    """Drop the parts of the mask thinner than `width_px` (a morphological opening)."""
    mask = crop.mask
    size = max(3, round(width_px) | 1)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))
    opened = cv2.morphologyEx(mask.astype(np.uint8), cv2.MORPH_OPEN, kernel) > 0
    crop.out[mask & ~opened] = 0


def _bleed(crop: _Crop, cls: int, radius_px: float, rng: np.random.Generator) -> None:
    """Dilate the mask by `radius_px` along part of its outline onto what lies beside or behind."""
    mask = crop.mask
    ring = (cv2.dilate(mask.astype(np.uint8), _disk(radius_px)) > 0) & ~mask
    depth = crop.view.depth_m[crop.roi]
    behind = depth > float(np.median(depth[mask])) + _BEHIND_M
    ring &= ~crop.is_object | behind
    if not ring.any():
        return
    h, w = mask.shape
    coarse = rng.random((max(2, h // 12), max(2, w // 12))).astype(np.float32)
    field = cv2.resize(coarse, (w, h), interpolation=cv2.INTER_LINEAR)
    share = rng.uniform(0.3, 1.0)  # of the outline
    ring &= field <= np.quantile(field[ring], share)
    crop.out[ring] = cls


def _speckle(crop: _Crop, cls: int, rate: float, half_px: float, rng: np.random.Generator) -> None:
    """Give a random label of the ones in play to `rate` of the pixels near the outline."""
    mask = crop.mask.astype(np.uint8)
    disk = _disk(half_px)
    band = (cv2.dilate(mask, disk) > 0) & ~(cv2.erode(mask, disk) > 0)
    band &= ~crop.is_object | (mask > 0)
    hit = band & (rng.random(band.shape) < rate)
    choices = np.array([0, cls, *WRONG_CLASS.get(cls, ())], np.uint8)
    crop.out[hit] = rng.choice(choices, int(hit.sum()))


def _visible(crop: _Crop, spots: npt.NDArray[np.float64]) -> list[tuple[int, int]]:
    """Return the crop pixels (x, y) where the object's hard spots show in this view."""
    if not len(spots):
        return []
    v = crop.view
    camera = (spots - v.world_from_camera[:3, 3]) @ v.world_from_camera[:3, :3]
    z = camera[:, 2]
    fx, fy, cx, cy = v.focal
    u = np.round(fx * camera[:, 0] / np.maximum(z, 1e-6) + cx).astype(int) - crop.roi[1].start
    r = np.round(fy * camera[:, 1] / np.maximum(z, 1e-6) + cy).astype(int) - crop.roi[0].start
    h, w = crop.out.shape
    inside = (z > 0) & (u >= 0) & (u < w) & (r >= 0) & (r < h)
    mask, depth = crop.mask, v.depth_m[crop.roi]
    out = []
    for i in np.flatnonzero(inside):
        if mask[r[i], u[i]] and abs(depth[r[i], u[i]] - z[i]) < 0.05:
            out.append((int(u[i]), int(r[i])))
    return out


def _confused(
    parts: list[sh.Part], objects: dict[int, int], share: float, rng: np.random.Generator
) -> dict[int, int]:
    """Return instance -> wrong class for `share` of the confusable objects, small ones likelier."""
    area: dict[int, float] = {}
    for p in parts:
        if objects.get(p.instance) in WRONG_CLASS:
            area[p.instance] = area.get(p.instance, 0.0) + p.mesh.get_surface_area()
    if share <= 0 or not area:
        return {}
    ids = sorted(area)
    weight = np.array([1.0 / max(area[i], _CLEAR_M2) for i in ids])
    count = max(1, round(share * len(ids)))
    chosen = rng.choice(ids, count, replace=False, p=weight / weight.sum())
    return {int(i): int(rng.choice(WRONG_CLASS[objects[int(i)]])) for i in chosen}


def _surface_points(
    parts: list[sh.Part], n: int, rng: np.random.Generator
) -> npt.NDArray[np.float64]:
    """Return `n` points spread uniformly over the parts' triangles."""
    tris = np.concatenate(
        [np.asarray(p.mesh.vertices)[np.asarray(p.mesh.triangles)] for p in parts]
    )
    area = np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
    pick = rng.choice(len(tris), n, p=area / area.sum())
    a, b = rng.random((2, n, 1))
    flip = a + b > 1
    a, b = np.where(flip, 1 - a, a), np.where(flip, 1 - b, b)
    t = tris[pick]
    return np.asarray(t[:, 0] + a * (t[:, 1] - t[:, 0]) + b * (t[:, 2] - t[:, 0]), np.float64)
