"""Which keyframes are segmented: those that see enough surface no segmented keyframe has seen.

Odometry wants a keyframe every 10 degrees (tracking needs overlap); labels need far fewer views,
and the network is the costliest stage of the job on a CPU. A keyframe's depth is sampled on a
coarse pixel grid and put into 8 cm cells of the world; it is segmented when at least
`min_new_share` of the samples fall in cells that no segmented keyframe covered. Keyframes in
between add geometry only. The decision is taken when the keyframe is tracked, so it depends on
the poses and depth alone, never on how fast the machine is.
"""

from __future__ import annotations

from typing import Final

import numpy as np
import numpy.typing as npt

from capture.recording import Intrinsics
from process.fusion.votes import voxel_keys
from process.geometry import normalise

CELL_M: Final = 0.08  # coverage cells: coarser than depth noise and pose jitter
PIXEL_STRIDE: Final = 8  # 80x60 samples of a 640x480 image
MAX_DEPTH_M: Final = 4.0  # what fusion keeps by default


class SegmentationSchedule:
    """Say for each keyframe whether it is due for segmentation."""

    def __init__(self, min_new_share: float) -> None:
        self.min_new_share = min_new_share  # [segmentation] min_new_share; 0 = every keyframe
        self._covered = np.zeros(0, np.int64)  # sorted cell keys seen by segmented keyframes

    def new_cells(
        self,
        depth_m: npt.NDArray[np.float32],
        *,
        intrinsics: Intrinsics,
        world_from_camera: npt.NDArray[np.float64],
    ) -> npt.NDArray[np.int64] | None:
        """Return the keyframe's coverage cells if it is due for segmentation, else None.

        Pass them to `cover` once the keyframe is on its way to the segmentation.
        """
        cells = np.unique(_cells(depth_m, intrinsics, world_from_camera))
        if self.min_new_share <= 0.0:
            return cells
        if len(cells) == 0:  # no depth: nothing to label
            return None
        where = np.searchsorted(self._covered, cells)
        seen = where < len(self._covered)
        seen[seen] = self._covered[where[seen]] == cells[seen]
        return cells if 1.0 - float(seen.mean()) >= self.min_new_share else None

    def cover(self, cells: npt.NDArray[np.int64]) -> None:
        """Count these cells as seen by a segmented keyframe."""
        self._covered = np.union1d(self._covered, cells)

    def due(
        self,
        depth_m: npt.NDArray[np.float32],
        *,
        intrinsics: Intrinsics,
        world_from_camera: npt.NDArray[np.float64],
    ) -> bool:
        """Return whether this keyframe is due, and count its cells covered if so."""
        cells = self.new_cells(depth_m, intrinsics=intrinsics, world_from_camera=world_from_camera)
        if cells is not None:
            self.cover(cells)
        return cells is not None


def _cells(
    depth_m: npt.NDArray[np.float32],
    intrinsics: Intrinsics,
    world_from_camera: npt.NDArray[np.float64],
) -> npt.NDArray[np.int64]:
    """Return the coverage cell of every sampled pixel with depth."""
    v, u = np.mgrid[0 : depth_m.shape[0] : PIXEL_STRIDE, 0 : depth_m.shape[1] : PIXEL_STRIDE]
    z = depth_m[v, u].astype(np.float64).ravel()
    ok = np.isfinite(z) & (z > 0.0) & (z <= MAX_DEPTH_M)
    uv = np.stack([u.ravel()[ok], v.ravel()[ok]], axis=1).astype(np.float64)
    camera = np.column_stack([normalise(uv, intrinsics) * z[ok, None], z[ok]])
    world = camera @ world_from_camera[:3, :3].T + world_from_camera[:3, 3]
    return voxel_keys(world, CELL_M)
