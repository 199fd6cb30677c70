"""Step 2: Statistical Outlier Removal (Open3D) on the object cloud."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt


def sor_inliers(
    points: npt.NDArray[np.float32], *, nb_neighbors: int, std_ratio: float
) -> npt.NDArray[np.bool_]:
    """Return the mask of points that SOR keeps.

    A point is an outlier when its mean distance to its `nb_neighbors` nearest neighbours exceeds
    the mean of those distances over the cloud by `std_ratio` standard deviations. A cloud with
    no more than `nb_neighbors` points has no statistics to speak of and is kept whole.
    """
    keep = np.ones(len(points), bool)
    if len(points) <= nb_neighbors:
        return keep
    import open3d as o3d

    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points.astype(np.float64)))
    _, inliers = cloud.remove_statistical_outlier(nb_neighbors, std_ratio)
    keep[:] = False
    keep[np.asarray(inliers, np.intp)] = True
    return keep
