"""Fusion: labelled keyframe pixels -> a world voxel map with confidence-weighted label votes."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import numpy.typing as npt

from capture.recording import NUM_LABELS, Intrinsics
from process.cloud import LabelledCloud
from process.errors import ConfigError, StageError

logger = logging.getLogger(__name__)

_AXIS_BITS = 21  # voxel index bits per axis in the int64 key: +-2^20 voxels (+-10 km at 1 cm)
_AXIS_OFFSET = 1 << (_AXIS_BITS - 1)


@dataclass(frozen=True)
class FusionConfig:
    """How keyframe pixels become map points."""

    voxel_size_m: float = 0.02  # edge of a map voxel
    min_depth_m: float = 0.2  # the D435 sees nothing nearer
    max_depth_m: float = 4.0  # beyond this D435 depth noise exceeds a few centimetres
    min_confidence: float = 0.3  # pixels less sure than this add geometry but no label vote
    pixel_stride: int = 2  # use every n-th pixel in each direction

    def __post_init__(self) -> None:
        if not 0.001 <= self.voxel_size_m <= 1.0:
            raise ConfigError(f"fusion.voxel_size_m must be in 0.001..1 m, got {self.voxel_size_m}")
        if not 0.0 <= self.min_depth_m < self.max_depth_m <= 100.0:
            raise ConfigError(
                "fusion needs 0 <= min_depth_m < max_depth_m <= 100, got "
                f"{self.min_depth_m} and {self.max_depth_m}"
            )
        if not 0.0 <= self.min_confidence <= 1.0:
            raise ConfigError(f"fusion.min_confidence must be in 0..1, got {self.min_confidence}")
        if not 1 <= self.pixel_stride <= 64:
            raise ConfigError(f"fusion.pixel_stride must be in 1..64, got {self.pixel_stride}")


@lru_cache(maxsize=8)
def _rays(
    intrinsics: Intrinsics, stride: int
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.intp]]:
    """Return the normalised image coordinates (x/z, y/z) and flat indices of the sampled pixels."""
    v, u = np.mgrid[0 : intrinsics.height : stride, 0 : intrinsics.width : stride]
    uv = np.stack([u.ravel(), v.ravel()], axis=1).astype(np.float64)
    if intrinsics.is_distorted:
        import cv2  # undistortion of the pixel grid (Brown-Conrady / rational), once per camera

        undistorted = cv2.undistortPoints(
            uv.reshape(-1, 1, 2), intrinsics.matrix, np.asarray(intrinsics.coeffs, np.float64)
        )
        xy = np.asarray(undistorted, np.float64).reshape(-1, 2)
    else:
        xy = (uv - (intrinsics.cx, intrinsics.cy)) / np.array((intrinsics.fx, intrinsics.fy))
    flat = (v.ravel() * intrinsics.width + u.ravel()).astype(np.intp)
    return xy, flat


def voxel_keys(points: npt.NDArray[np.float64], voxel_size_m: float) -> npt.NDArray[np.int64]:
    """Return one int64 key per point: its voxel's integer coordinates packed 21 bits per axis."""
    ijk = np.floor(points / voxel_size_m).astype(np.int64) + _AXIS_OFFSET
    if len(ijk) and (ijk.min() < 0 or ijk.max() >= 1 << _AXIS_BITS):
        raise StageError(
            f"fusion map exceeds +-{_AXIS_OFFSET * voxel_size_m:.0f} m from the origin; "
            "the poses are diverging, check the odometry"
        )
    return (ijk[:, 0] << (2 * _AXIS_BITS)) | (ijk[:, 1] << _AXIS_BITS) | ijk[:, 2]


class Fusion:
    """A voxel map that averages position and colour and sums confidence-weighted label votes."""

    def __init__(self, cfg: FusionConfig) -> None:
        self.cfg = cfg
        self._keys = np.zeros(0, np.int64)  # sorted voxel keys
        self._slot_of_key = np.zeros(0, np.int64)  # data row of each sorted key
        self._size = 0
        self._sum_xyz = np.zeros((0, 3), np.float64)
        self._sum_rgb = np.zeros((0, 3), np.float64)
        self._count = np.zeros(0, np.float64)
        self._votes = np.zeros((0, NUM_LABELS), np.float32)
        self.frames = 0

    def __len__(self) -> int:
        return self._size

    def integrate(
        self,
        color: npt.NDArray[np.uint8],
        depth_m: npt.NDArray[np.float32],
        labels: npt.NDArray[np.uint8],
        confidence: npt.NDArray[np.float32],
        *,
        intrinsics: Intrinsics,
        world_from_camera: npt.NDArray[np.float64],
    ) -> None:
        """Add one labelled keyframe; depth, labels and confidence are in the colour camera.

        Args:
            color: (H, W, 3) RGB.
            depth_m: (H, W) metres, 0 = no depth, registered to the colour camera.
            labels: (H, W) RECORDING.md label ids.
            confidence: (H, W) segmentation confidence in 0..1 (the vote weight).
            intrinsics: the colour camera.
            world_from_camera: (4, 4) pose of the colour optical frame.
        """
        shape = (intrinsics.height, intrinsics.width)
        for name, image in (
            ("color", color),
            ("depth_m", depth_m),
            ("labels", labels),
            ("confidence", confidence),
        ):
            if image.shape[:2] != shape:
                raise StageError(
                    f"fusion expects {name} of {shape[1]}x{shape[0]} (the colour camera), "
                    f"got {image.shape[1]}x{image.shape[0]}; register depth to colour first"
                )
        xy, flat = _rays(intrinsics, self.cfg.pixel_stride)
        z = depth_m.reshape(-1)[flat].astype(np.float64)
        valid = np.isfinite(z) & (z > self.cfg.min_depth_m) & (z <= self.cfg.max_depth_m)
        xy, flat, z = xy[valid], flat[valid], z[valid]
        camera_points = np.column_stack([xy * z[:, None], z])
        world = camera_points @ world_from_camera[:3, :3].T + world_from_camera[:3, 3]
        weight = np.nan_to_num(confidence.reshape(-1)[flat].astype(np.float32))
        weight = np.where(weight >= self.cfg.min_confidence, weight, np.float32(0.0))
        self._accumulate(world, color.reshape(-1, 3)[flat], labels.reshape(-1)[flat], weight)
        self.frames += 1

    def _accumulate(
        self,
        world: npt.NDArray[np.float64],
        rgb: npt.NDArray[np.uint8],
        labels: npt.NDArray[np.uint8],
        weight: npt.NDArray[np.float32],
    ) -> None:
        if len(world) == 0:
            return
        if int(labels.max()) >= NUM_LABELS:
            raise StageError(
                f"fusion expects label ids 0..{NUM_LABELS - 1}, got {int(labels.max())}"
            )
        keys, inverse = np.unique(voxel_keys(world, self.cfg.voxel_size_m), return_inverse=True)
        # aggregate the frame per voxel first, so the cost per frame does not grow with the map
        n = len(keys)
        sum_xyz = np.stack([np.bincount(inverse, world[:, a], minlength=n) for a in range(3)], 1)
        sum_rgb = np.stack([np.bincount(inverse, rgb[:, a], minlength=n) for a in range(3)], 1)
        vote_index = inverse * NUM_LABELS + labels.astype(np.int64)
        votes = np.bincount(vote_index, weight, minlength=n * NUM_LABELS).reshape(n, NUM_LABELS)
        slots = self._slots(keys)  # unique rows, so fancy-index += is safe
        self._sum_xyz[slots] += sum_xyz
        self._sum_rgb[slots] += sum_rgb
        self._count[slots] += np.bincount(inverse, minlength=n)
        self._votes[slots] += votes.astype(np.float32)

    def _slots(self, keys: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
        """Return the data row of each (sorted, unique) key, appending rows for new voxels."""
        where = np.searchsorted(self._keys, keys)
        found = where < len(self._keys)
        found[found] = self._keys[where[found]] == keys[found]
        slots = np.empty(len(keys), np.int64)
        slots[found] = self._slot_of_key[where[found]]
        new = ~found
        n_new = int(new.sum())
        slots[new] = np.arange(self._size, self._size + n_new)
        if n_new:
            self._reserve(self._size + n_new)
            self._size += n_new
            self._keys = np.insert(self._keys, where[new], keys[new])
            self._slot_of_key = np.insert(self._slot_of_key, where[new], slots[new])
        return slots

    def _reserve(self, size: int) -> None:
        """Grow the data arrays geometrically so that appending voxels is amortised O(1)."""
        capacity = len(self._count)
        if size <= capacity:
            return
        extra = max(size, 2 * capacity) - capacity
        self._sum_xyz = np.concatenate([self._sum_xyz, np.zeros((extra, 3))])
        self._sum_rgb = np.concatenate([self._sum_rgb, np.zeros((extra, 3))])
        self._count = np.concatenate([self._count, np.zeros(extra)])
        self._votes = np.concatenate([self._votes, np.zeros((extra, NUM_LABELS), np.float32)])

    def cloud(self) -> LabelledCloud:
        """Return the map: one point per voxel at its mean position, mean colour, winning label."""
        n = self._size
        count = self._count[:n, None]
        points = (self._sum_xyz[:n] / count).astype(np.float32)
        colors = np.clip(self._sum_rgb[:n] / count + 0.5, 0, 255).astype(np.uint8)
        votes = self._votes[:n]
        # a voxel nobody voted for confidently (all weights 0) stays unlabelled
        labels = np.where(votes.max(axis=1) > 0, votes.argmax(axis=1), 0)
        return LabelledCloud(points, colors, labels.astype(np.uint8))
