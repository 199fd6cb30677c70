"""The map's geometry: a truncated signed distance volume (Open3D) whose zero crossing is thin.

Averaging depth hits per voxel makes surfaces as thick as the depth noise (a D435 has ~4 cm of RMS
error at 3 m, so a floor seen for 10 minutes becomes a slab 10 cm thick, and the labels spread
into it). A TSDF averages distances along the rays instead (KinectFusion, Newcombe et al. 2011),
so more views make a surface sharper, not thicker. Open3D's VoxelBlockGrid holds it sparsely.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import open3d as o3d

from capture.recording import Intrinsics

_BLOCK_RESOLUTION = 8  # voxels per block edge: 16 cm blocks at 2 cm voxels
_INITIAL_BLOCKS = 20_000  # the hash map grows past this on its own


class TsdfSurface:
    """Integrate posed depth images; return the points of the surface seen often enough."""

    def __init__(
        self,
        *,
        voxel_size_m: float,
        truncation_voxels: float,
        min_depth_m: float,
        max_depth_m: float,
    ) -> None:
        self.truncation_voxels = truncation_voxels
        self.min_depth_m = min_depth_m
        self.max_depth_m = max_depth_m
        self._grid = o3d.t.geometry.VoxelBlockGrid(
            attr_names=("tsdf", "weight"),
            attr_dtypes=(o3d.core.float32, o3d.core.float32),
            attr_channels=(o3d.core.SizeVector([1]), o3d.core.SizeVector([1])),
            voxel_size=voxel_size_m,
            block_resolution=_BLOCK_RESOLUTION,
            block_count=_INITIAL_BLOCKS,
            device=o3d.core.Device("CPU:0"),
        )

    def integrate(
        self,
        depth_m: npt.NDArray[np.float32],
        *,
        intrinsics: Intrinsics,
        world_from_camera: npt.NDArray[np.float64],
    ) -> None:
        """Add one depth image (metres, 0 or NaN = none) seen from a pinhole camera pose.

        Lens distortion is ignored here (Open3D's TSDF is pinhole only); the vote voxels, which
        give the points their labels, are undistorted.
        """
        depth = np.nan_to_num(np.asarray(depth_m, np.float32), nan=0.0, posinf=0.0)
        depth[(depth < self.min_depth_m) | (depth > self.max_depth_m)] = 0.0
        if not depth.any():  # Open3D aborts on an image that touches no block
            return
        image = o3d.t.geometry.Image(o3d.core.Tensor.from_numpy(np.ascontiguousarray(depth)))
        matrix = o3d.core.Tensor.from_numpy(np.asarray(intrinsics.matrix, np.float64))
        extrinsic = o3d.core.Tensor.from_numpy(np.linalg.inv(world_from_camera).astype(np.float64))
        args = (1.0, self.max_depth_m, self.truncation_voxels)  # scale, range, truncation
        blocks = self._grid.compute_unique_block_coordinates(image, matrix, extrinsic, *args)
        self._grid.integrate(blocks, image, matrix, extrinsic, *args)

    def points(self, *, min_views: int) -> npt.NDArray[np.float32]:
        """Return (N, 3) points on the zero crossing seen by at least min_views images."""
        if self._grid.hashmap().size() == 0:
            return np.zeros((0, 3), np.float32)
        try:
            # a voxel's weight counts the images that saw it; Open3D keeps weight > threshold
            cloud = self._grid.extract_point_cloud(weight_threshold=min_views - 0.5)
        except RuntimeError:  # Open3D raises when no voxel reaches the weight: no surface yet
            return np.zeros((0, 3), np.float32)
        return canonical_order(np.asarray(cloud.point.positions.numpy(), np.float32).reshape(-1, 3))


def canonical_order(points: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
    """Return the (N, 3) points sorted by x, then y, then z: an order set by their values alone.

    Open3D extracts the surface from its hash map on parallel threads, so the same surface
    comes out in a different order from run to run (the points themselves are identical), and
    refinement samples points by index: sorted, the same surface gives the same refined map.
    """
    return np.ascontiguousarray(points[np.lexsort((points[:, 2], points[:, 1], points[:, 0]))])
