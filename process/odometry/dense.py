"""The dense half of the visual odometry: Open3D's tensor RGB-D odometry on small images.

Measured on rendered views with exact depth, Open3D's point-to-plane alignment recovers a 5 cm
motion to 0.1 mm, while its photometric term (alone or in "hybrid") is biased by 1-7 mm. Point-to-
plane is blind along any direction the surfaces do not constrain, though (a camera facing one
wall, or a room corner): it then slides; and on noisy depth (a D435 beyond ~1.5 m) hybrid is the
more accurate. "auto" therefore measures how well the surface normals of both images span 3-D and
how rough their depth is, and uses point-to-plane only where the normals span 3-D and the depth
is smooth, hybrid elsewhere. The photometric methods run Open3D's per-iteration kernels on
pyramids built here (photometric_multi_scale: Open3D's own pyramid varied with buffer addresses).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt
import open3d as o3d
from scipy.spatial.transform import Rotation

from capture.recording import Intrinsics
from process.geometry import rigid_inverse

_METHODS = {
    "point_to_plane": o3d.t.pipelines.odometry.Method.PointToPlane,
    "hybrid": o3d.t.pipelines.odometry.Method.Hybrid,
    "intensity": o3d.t.pipelines.odometry.Method.Intensity,
}
DENSE_METHODS = ("auto", *_METHODS)
# Smallest / largest eigenvalue of the normals' scatter below which point-to-plane may slide
# (0: one plane or two; measured on rendered rooms, sliding starts below about 0.015).
_MIN_CONDITIONING = 0.02
# Median relative depth range within 2x2 blocks above which depth counts as noisy and the
# photometric term of hybrid helps (simulated D435 depth, registered: 0.009-0.012; exact
# renders: < 0.003). On the noisy simulated loops hybrid gives 0.22-0.29 % ATE / path where
# point-to-plane gives 0.35-0.50 %; on exact renders point-to-plane is ten times more precise.
_MAX_ROUGHNESS = 0.005


@dataclass(frozen=True, slots=True)
class DenseImage:
    """A frame prepared for dense alignment."""

    rgbd: Any  # open3d.t.geometry.RGBDImage, downsampled
    conditioning: float  # how well the surface normals span 3-D: 0 (a plane) .. 1 (isotropic)
    roughness: float  # median depth range within a block / depth: sensor noise, ~0 when exact


@dataclass(frozen=True, slots=True)
class DenseResult:
    """A dense alignment: the refined transform and how much of the image supported it."""

    target_from_source: npt.NDArray[np.float64]  # (4, 4)
    fitness: float  # fraction of source pixels with a correspondence
    method: str


class DenseAligner:
    """Refine a relative pose by dense alignment of two downsampled RGB-D images."""

    def __init__(
        self,
        intrinsics: Intrinsics,
        *,
        scale: int,
        max_depth_m: float,
        iterations: tuple[int, ...],
        quick_iterations: tuple[int, ...] = (3,),
        method: str = "auto",
        reproducible: bool = True,
    ) -> None:
        self.method = method
        self.reproducible = reproducible
        self.scale = scale
        self.size = (intrinsics.width // scale, intrinsics.height // scale)
        k = intrinsics.matrix.copy()
        # Pixel centres of the area-downsampled image sit at (x + 0.5) / s - 0.5.
        k[:2, :2] /= scale
        k[0, 2] = (k[0, 2] + 0.5) / scale - 0.5
        k[1, 2] = (k[1, 2] + 0.5) / scale - 0.5
        self.k_small = k
        self.camera_matrix = o3d.core.Tensor.from_numpy(k)
        self.max_depth_m = max_depth_m
        criteria = o3d.t.pipelines.odometry.OdometryConvergenceCriteria
        self.criteria = [criteria(n) for n in iterations]
        self.quick_criteria = [criteria(n) for n in quick_iterations]

    def prepare(self, gray: npt.NDArray[np.uint8], depth_m: npt.NDArray[np.float32]) -> DenseImage:
        """Return the downsampled RGB-D image of a frame and its geometric conditioning."""
        w, h = self.size
        s = self.scale
        small = cv2.resize(gray, (w, h), interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0
        color = np.ascontiguousarray(np.repeat(small[:, :, None], 3, axis=2))
        # Strided views of the s x s blocks: much faster than reducing a reshaped array.
        views = [depth_m[i : h * s : s, j : w * s : s] for i in range(s) for j in range(s)]
        lo, hi, total = views[0].copy(), views[0].copy(), views[0].copy()
        for v in views[1:]:
            np.minimum(lo, v, out=lo)
            np.maximum(hi, v, out=hi)
            total += v
        mean = total / (s * s)
        # A block average is a depth only where the block is complete and not across an edge.
        valid = (lo > 0) & (hi - lo <= 0.1 * mean) & (mean <= self.max_depth_m)
        depth = np.ascontiguousarray(np.where(valid, mean, 0.0).astype(np.float32))
        rgbd = o3d.t.geometry.RGBDImage(
            o3d.t.geometry.Image(o3d.core.Tensor.from_numpy(color)),
            o3d.t.geometry.Image(o3d.core.Tensor.from_numpy(depth)),
        )
        ratio = (hi - lo)[valid] / mean[valid]
        roughness = float(np.median(ratio)) if ratio.size else 1.0
        return DenseImage(rgbd, normal_conditioning(depth, self.k_small, block=4), roughness)

    def align(
        self,
        source: DenseImage,
        target: DenseImage,
        *,
        init_target_from_source: npt.NDArray[np.float64],
        quick: bool = False,
    ) -> DenseResult | None:
        """Return the refined target_from_source, or None where the alignment failed.

        quick: the short schedule, for a start that is already close (a PnP pose).
        """
        method = self.method
        if method == "auto":
            well_posed = min(source.conditioning, target.conditioning) >= _MIN_CONDITIONING
            exact = max(source.roughness, target.roughness) <= _MAX_ROUGHNESS
            method = "point_to_plane" if well_posed and exact else "hybrid"
        criteria = self.quick_criteria if quick else self.criteria
        init = np.array(init_target_from_source, np.float64)
        try:
            # see one_thread: Open3D's parallel sums vary in the last bits
            with one_thread() if self.reproducible else nullcontext():
                if method == "point_to_plane":
                    result = o3d.t.pipelines.odometry.rgbd_odometry_multi_scale(
                        source.rgbd,
                        target.rgbd,
                        self.camera_matrix,
                        o3d.core.Tensor.from_numpy(init),
                        1.0,
                        self.max_depth_m,
                        criteria,
                        _METHODS[method],
                    )
                    transform, fitness = result.transformation.numpy(), result.fitness
                else:
                    transform, fitness = photometric_multi_scale(
                        method, source, target, self.k_small, init, self.max_depth_m, criteria
                    )
        except RuntimeError:
            return None  # Open3D raises when too few pixels correspond
        transform = np.asarray(transform, np.float64)
        if not np.all(np.isfinite(transform)):
            return None
        return DenseResult(transform, float(fitness), method)


# Open3D's loss parameters (OdometryLossParams' defaults, which rgbd_odometry_multi_scale uses)
_LOSS = o3d.t.pipelines.odometry.OdometryLossParams()
# the 5-tap binomial weights of Open3D's PyrDownDepth
_BINOMIAL = np.array([0.0625, 0.25, 0.375, 0.25, 0.0625], np.float32)


def photometric_multi_scale(
    method: str,
    source: DenseImage,
    target: DenseImage,
    camera_matrix: npt.NDArray[np.float64],
    init_target_from_source: npt.NDArray[np.float64],
    max_depth_m: float,
    criteria: Sequence[Any],
) -> tuple[npt.NDArray[np.float64], float]:
    """Return (target_from_source, fitness) by Open3D's multi-scale "intensity" or "hybrid".

    Open3D 0.20's rgbd_odometry_multi_scale builds the intensity pyramid with its Gaussian
    filter (IPP), whose result depends on whether the image's buffer starts on an 8-byte
    boundary (measured: two outputs, by address mod 8): the same two images gave poses 1e-7 m
    apart from one call to the next, and two runs of a recording differed. This builds the same
    pyramids with OpenCV and NumPy, whose results follow the pixels alone, and runs Open3D's own
    Gauss-Newton step per iteration with its convergence test: poses within 2e-5 m of Open3D's
    (the Gaussian weights differ in the last bits), at the same cost. Raises RuntimeError where
    no pixel corresponds, as Open3D does. criteria: OdometryConvergenceCriteria per level,
    coarsest first.
    """
    trunc = _LOSS.depth_outlier_trunc
    levels = len(criteria)
    k = np.array(camera_matrix, np.float64)
    source_depth, target_depth = (_clip_depth(im, max_depth_m) for im in (source, target))
    source_gray, target_gray = (_gray(im) for im in (source, target))
    pyramid = []
    for level in range(levels):
        images = [source_depth, target_depth, source_gray, target_gray]
        if method == "hybrid":
            images += _sobel(target_depth)
        images += _sobel(target_gray)
        vertices = o3d.t.geometry.Image(_tensor(source_depth)).create_vertex_map(
            o3d.core.Tensor.from_numpy(k), float("nan")
        )
        pyramid.append(
            [_tensor(a) for a in images]
            + [vertices.as_tensor(), o3d.core.Tensor.from_numpy(k.copy())]
        )
        if level < levels - 1:
            source_depth = pyrdown_depth(source_depth, 2 * trunc)
            target_depth = pyrdown_depth(target_depth, 2 * trunc)
            source_gray, target_gray = gaussian_pyrdown(source_gray), gaussian_pyrdown(target_gray)
            k = k / 2
            k[2, 2] = 1.0
    odometry = o3d.t.pipelines.odometry
    step_fn: Any = (
        odometry.compute_odometry_result_hybrid
        if method == "hybrid"
        else odometry.compute_odometry_result_intensity
    )
    loss: tuple[float, ...] = (
        (trunc, _LOSS.depth_huber_delta, _LOSS.intensity_huber_delta)
        if method == "hybrid"
        else (trunc, _LOSS.intensity_huber_delta)
    )
    transform = np.array(init_target_from_source, np.float64)
    rmse, fitness = 0.0, 1.0
    for level_images, criterion in zip(reversed(pyramid), criteria, strict=True):
        for _ in range(criterion.max_iteration):
            step = step_fn(*level_images, o3d.core.Tensor.from_numpy(transform), *loss)
            transform = step.transformation.numpy() @ transform
            # Open3D's test; against rmse 0 at the start it divides by zero: never converged
            if (
                rmse > 0
                and abs(fitness - step.fitness) / fitness < criterion.relative_fitness
                and abs(rmse - step.inlier_rmse) / rmse < criterion.relative_rmse
            ):
                break
            rmse, fitness = step.inlier_rmse, step.fitness
    return transform, fitness


def _clip_depth(image: DenseImage, max_depth_m: float) -> npt.NDArray[np.float32]:
    depth = image.rgbd.depth.as_tensor().numpy()[:, :, 0]
    return np.where((depth > 0) & (depth < max_depth_m), depth, np.nan).astype(np.float32)


def _gray(image: DenseImage) -> npt.NDArray[np.float32]:
    gray = image.rgbd.color.rgb_to_gray().as_tensor().numpy()
    return np.ascontiguousarray(gray[:, :, 0], dtype=np.float32)


def _tensor(a: npt.NDArray[np.float32]) -> Any:
    return o3d.core.Tensor.from_numpy(np.ascontiguousarray(a[:, :, None]))


def _sobel(a: npt.NDArray[np.float32]) -> list[npt.NDArray[np.float32]]:
    """Return the 3x3 Sobel x and y derivatives, edges replicated (Open3D's FilterSobel)."""
    return [
        np.asarray(
            cv2.Sobel(a, cv2.CV_32F, dx, 1 - dx, ksize=3, borderType=cv2.BORDER_REPLICATE),
            np.float32,
        )
        for dx in (1, 0)
    ]


def gaussian_pyrdown(a: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
    """Return Open3D's PyrDown: a 5x5 Gaussian of sigma 1, edges replicated, every other pixel."""
    h, w = a.shape[0] // 2 * 2, a.shape[1] // 2 * 2
    smooth = cv2.GaussianBlur(a, (5, 5), 1.0, borderType=cv2.BORDER_REPLICATE)
    return np.ascontiguousarray(smooth[:h:2, :w:2])


def pyrdown_depth(depth: npt.NDArray[np.float32], max_diff: float) -> npt.NDArray[np.float32]:
    """Return Open3D's PyrDownDepth (not exposed to Python, hence by hand).

    Every other pixel: the binomial 5x5 mean of its neighbours within max_diff of it, NaN where
    it is NaN; neighbours that are NaN or off the image are left out.
    """
    h, w = depth.shape[0] // 2, depth.shape[1] // 2
    padded = np.pad(depth, 2, constant_values=np.nan)
    filled = np.nan_to_num(padded)  # a neighbour left out adds w * 0: the same float sums
    centre = depth[: 2 * h : 2, : 2 * w : 2]
    total = np.zeros((h, w), np.float32)
    weight = np.zeros((h, w), np.float32)
    for dy in range(5):
        for dx in range(5):
            near = np.abs(padded[dy : dy + 2 * h : 2, dx : dx + 2 * w : 2] - centre) < max_diff
            w_ij = _BINOMIAL[dy] * _BINOMIAL[dx]
            total += w_ij * filled[dy : dy + 2 * h : 2, dx : dx + 2 * w : 2] * near
            weight += w_ij * near
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(weight > 0, total / weight, np.nan).astype(np.float32)


@contextmanager
def one_thread() -> Iterator[None]:
    """Run Open3D on the calling thread alone for the duration (its limit is process-wide).

    Open3D's RGB-D odometry sums its normal equations in float32 on parallel threads, and how
    the range is split among them depends on the scheduling: the same two images gave poses
    3e-6 apart from one call to the next, which made two runs of a recording differ. On one
    thread the sums, and the poses, follow the inputs alone. Threads that are in Open3D calls
    meanwhile (the fusion's TSDF) run on without helpers until the limit is restored.
    """
    threads = o3d.utility.get_max_threads()
    o3d.utility.set_max_threads(1)
    try:
        yield
    finally:
        o3d.utility.set_max_threads(threads)


def normal_conditioning(
    depth_m: npt.NDArray[np.float32], camera_matrix: npt.NDArray[np.float64], *, block: int = 1
) -> float:
    """Return the smallest / largest eigenvalue of the scatter of surface normals (0 .. 1).

    Normals come from central differences of the back-projected depth, averaged over blocks of
    block x block pixels first so that sensor noise does not pass for surface variety; the ratio
    is 0 when all surfaces share a normal (one plane) or lie in one pencil of directions.
    """
    k = camera_matrix.copy()
    if block > 1:
        h, w = depth_m.shape[0] // block, depth_m.shape[1] // block
        cropped = np.ascontiguousarray(depth_m[: h * block, : w * block])
        # Block means by area resampling (much faster than reducing a reshaped array).
        mean = cv2.resize(cropped, (w, h), interpolation=cv2.INTER_AREA)
        share = cv2.resize((cropped > 0).astype(np.float32), (w, h), interpolation=cv2.INTER_AREA)
        depth_m = np.where(share > 0.999, mean, 0.0).astype(np.float32)
        k[:2, :2] /= block
        k[:2, 2] = (k[:2, 2] + 0.5) / block - 0.5
    h, w = depth_m.shape
    fx, fy, cx, cy = k[0, 0], k[1, 1], k[0, 2], k[1, 2]
    u = (np.arange(w, dtype=np.float32) - cx) / fx
    v = (np.arange(h, dtype=np.float32) - cy) / fy
    z = depth_m
    points = np.stack([u[None, :] * z, v[:, None] * z, z], axis=-1)
    dx = points[1:-1, 2:] - points[1:-1, :-2]
    dy = points[2:, 1:-1] - points[:-2, 1:-1]
    ok = (z[1:-1, 2:] > 0) & (z[1:-1, :-2] > 0) & (z[2:, 1:-1] > 0) & (z[:-2, 1:-1] > 0)
    normals = np.cross(dx[ok], dy[ok])
    length = np.linalg.norm(normals, axis=1)
    normals = normals[length > 0] / length[length > 0, None]
    if len(normals) < 20:
        return 0.0
    eig = np.linalg.eigvalsh(normals.T.astype(np.float64) @ normals / len(normals))
    return float(eig[0] / eig[-1]) if eig[-1] > 0 else 0.0


def pose_difference(a: npt.NDArray[np.float64], b: npt.NDArray[np.float64]) -> tuple[float, float]:
    """Return (translation m, rotation deg) between two transforms."""
    delta = rigid_inverse(a) @ b
    angle = float(np.degrees(Rotation.from_matrix(delta[:3, :3]).magnitude()))
    return float(np.linalg.norm(delta[:3, 3])), angle
