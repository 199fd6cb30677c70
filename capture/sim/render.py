"""Ray-cast rendering of a scene with Open3D's RaycastingScene (Embree, CPU).

One ray per pixel through its centre (OpenCV convention: pixel (u, v) centre at x = (u - cx) / fx).
Ray directions have z = 1 in the camera frame, so the returned hit distance is the z-depth a depth
camera reports. Colour is the material's texture (triplanar: the two world axes most parallel to
the hit triangle) shaded by Lambert's law from point lights plus ambient light.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np
import numpy.typing as npt
import open3d as o3d

from capture.recording.frames import Extrinsics, Intrinsics
from capture.sim.scene import Scene
from capture.sim.textures import TEXTURE_SIZE, make_texture

_TEXEL_OFFSET: Final = 32.0 * TEXTURE_SIZE  # keeps texel coordinates positive before the wrap
INVALID_ID: Final = np.uint32(0xFFFFFFFF)  # Embree's geometry id of a ray that hit nothing


@dataclass(frozen=True, slots=True)
class CameraRig:
    """The D435's colour and depth cameras and the rigid transform between them."""

    color: Intrinsics
    depth: Intrinsics
    depth_to_color: Extrinsics


def d435_rig(width: int = 640, height: int = 480) -> CameraRig:
    """Return D435-like intrinsics (colour fx 615, depth fx 385 at 640 px) and extrinsics.

    At 640x480 the colour camera sees 55 x 43 degrees (its 69 degrees are for 16:9 modes) and the
    depth camera 80 x 64 degrees. The depth origin (left imager) sits 14.7 mm from the colour
    camera with a slight rotation, as in a factory calibration.
    """
    s = width / 640.0
    color = Intrinsics(
        width, height, 615.0 * s, 615.0 * s, (width - 1) / 2 + 0.9 * s, (height - 1) / 2 - 1.6 * s
    )
    depth = Intrinsics(
        width, height, 385.0 * s, 385.0 * s, (width - 1) / 2 - 0.3 * s, (height - 1) / 2 + 1.1 * s
    )
    rx, ry, rz = np.deg2rad([0.05, -0.1, 0.03])
    rotation = _small_rotation(rx, ry, rz)
    color_from_depth = np.eye(4)
    color_from_depth[:3, :3] = rotation
    color_from_depth[:3, 3] = [0.0147, 0.0001, 0.0003]
    return CameraRig(color, depth, Extrinsics(color_from_depth))


def _small_rotation(rx: float, ry: float, rz: float) -> npt.NDArray[np.float64]:
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    rot_x = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    rot_y = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rot_z = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return np.asarray(rot_z @ rot_y @ rot_x, np.float64)


@dataclass(frozen=True, slots=True)
class ColorView:
    """What the colour camera sees, with exact ground truth in its pixels."""

    color: npt.NDArray[np.uint8]  # (H, W, 3) RGB
    labels: npt.NDArray[np.uint8]  # (H, W) RECORDING.md label ids
    instances: npt.NDArray[np.uint16]  # (H, W) instance ids, 0 = none
    depth_m: npt.NDArray[np.float32]  # (H, W) exact z-depth in this camera, 0 = no hit


@dataclass(frozen=True, slots=True)
class DepthView:
    """What the depth camera's stereo matcher works from, before the D435 noise model."""

    depth_m: npt.NDArray[np.float32]  # (H, W) exact z-depth, 0 = no hit
    cos_incidence: npt.NDArray[np.float32]  # (H, W) |cos| between ray and surface normal
    luminance: npt.NDArray[np.float32]  # (H, W) surface albedo luminance in [0, 1]
    glossy: npt.NDArray[np.bool_]  # (H, W) the surface is specular


@dataclass(slots=True)
class _Hits:
    depth_m: npt.NDArray[np.float32]  # (N,) z-depth, 0 where nothing was hit
    geometry: npt.NDArray[np.uint32]  # (N,) part index; len(parts) where nothing was hit
    triangle: npt.NDArray[np.uint32]  # (N,) row of the triangle tables; the last row = no hit
    barycentric: npt.NDArray[np.float32]  # (N, 2) Embree's (u, v): p = (1-u-v) p0 + u p1 + v p2
    normal: npt.NDArray[np.float32]  # (N, 3) world, outwards
    direction: npt.NDArray[np.float32]  # (N, 3) world ray directions (camera z = 1)


class Renderer:
    """Render colour, labels, instances and depth of a scene from any camera pose."""

    def __init__(self, scene: Scene) -> None:
        self.scene = scene
        self._raycaster = o3d.t.geometry.RaycastingScene()
        materials = list(dict.fromkeys(p.material for p in scene.parts))
        index = {m: i for i, m in enumerate(materials)}
        for part in scene.parts:
            self._raycaster.add_triangles(
                o3d.core.Tensor.from_numpy(part.mesh.vertices.astype(np.float32)),
                o3d.core.Tensor.from_numpy(part.mesh.triangles.astype(np.uint32)),
            )
        counts = [len(p.mesh.triangles) for p in scene.parts]
        self._offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.uint32)
        self._sentinel = len(scene.parts)
        self._label = np.array([p.label for p in scene.parts] + [0], np.uint8)
        self._instance = np.array([p.instance for p in scene.parts] + [0], np.uint16)
        part_material = np.array([index[p.material] for p in scene.parts] + [0], np.int64)
        tinted = [make_texture(m) * np.asarray(scene.tint, np.float32) for m in materials]
        textures = np.stack([np.minimum(t, 255.0).astype(np.uint8) for t in tinted])
        self._texels = textures.reshape(-1, 3)
        luminance = textures.reshape(len(materials), -1, 3).mean(axis=1) @ [0.299, 0.587, 0.114]
        self._luminance = (luminance / 255.0).astype(np.float32)[part_material]
        self._glossy = np.array([m.glossy for m in materials])[part_material]
        self._tables = _triangle_tables(scene, part_material, [1.0 / m.texel_m for m in materials])
        self._dirs: dict[Intrinsics, tuple[npt.NDArray[np.float32], npt.NDArray[np.float32]]] = {}
        # Open3D builds the BVH lazily on the first cast; build it now, before worker threads cast.
        probe = np.array([[0.0, 0.0, 0.0, 0.0, 0.0, 1.0]], np.float32)
        self._raycaster.cast_rays(o3d.core.Tensor.from_numpy(probe))

    def _directions(self, k: Intrinsics) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.float32]]:
        """Return camera-frame ray directions (H*W, 3) with z = 1 and their inverse lengths."""
        if k not in self._dirs:
            u, v = np.meshgrid(np.arange(k.width), np.arange(k.height))
            d = np.stack([(u - k.cx) / k.fx, (v - k.cy) / k.fy, np.ones_like(u, np.float64)], -1)
            d = d.reshape(-1, 3)
            self._dirs[k] = (
                d.astype(np.float32),
                (1.0 / np.linalg.norm(d, axis=1)).astype(np.float32),
            )
        return self._dirs[k]

    def _cast(self, world_from_camera: npt.NDArray[np.float64], k: Intrinsics) -> _Hits:
        rays = np.empty((k.height * k.width, 6), np.float32)
        rays[:, :3] = world_from_camera[:3, 3]
        x, y, z = self._directions(k)[0].T
        r = world_from_camera[:3, :3].astype(np.float32)
        for row in range(3):  # by hand: BLAS threads spin, costing 20x the CPU for (N, 3) x (3, 3)
            rays[:, 3 + row] = x * r[row, 0] + y * r[row, 1] + z * r[row, 2]
        out = self._raycaster.cast_rays(o3d.core.Tensor.from_numpy(rays))
        depth, geometry = out["t_hit"].numpy(), out["geometry_ids"].numpy()
        miss = geometry == INVALID_ID
        geometry = np.minimum(geometry, np.uint32(self._sentinel))
        triangle = self._offsets[geometry] + out["primitive_ids"].numpy()
        if miss.any():  # only when a ray leaves the room, e.g. a camera outside it
            depth[miss] = 0.0
            triangle[miss] = self._offsets[-1]
        uvs, normals = out["primitive_uvs"].numpy(), out["primitive_normals"].numpy()
        return _Hits(depth, geometry, triangle, uvs, normals, rays[:, 3:])

    def render_color(
        self, world_from_camera: npt.NDArray[np.float64], *, intrinsics: Intrinsics
    ) -> ColorView:
        """Render colour with exact labels, instances and z-depth in the colour camera."""
        hits = self._cast(world_from_camera, intrinsics)
        shape = (intrinsics.height, intrinsics.width)
        return ColorView(
            self.surface_color(hits.triangle, barycentric=hits.barycentric).reshape(*shape, 3),
            self._label[hits.geometry].reshape(shape),
            self._instance[hits.geometry].reshape(shape),
            hits.depth_m.reshape(shape),
        )

    def surface_color(
        self, triangle: npt.NDArray[np.uint32], *, barycentric: npt.NDArray[np.float32]
    ) -> npt.NDArray[np.uint8]:
        """Return the shaded colour (N, 3) at points given by triangle row and Embree (u, v)."""
        row = self._tables[triangle]  # (N, 10): u, du1, du2, v, dv1, dv2, s, ds1, ds2, base
        b1, b2 = barycentric[:, 0], barycentric[:, 1]
        u = (row[:, 0] + b1 * row[:, 1] + b2 * row[:, 2]).astype(np.int32) & (TEXTURE_SIZE - 1)
        v = (row[:, 3] + b1 * row[:, 4] + b2 * row[:, 5]).astype(np.int32) & (TEXTURE_SIZE - 1)
        shade = ((row[:, 6] + b1 * row[:, 7] + b2 * row[:, 8]) * 256.0).astype(np.uint16)
        texel = row[:, 9].astype(np.int32) + v * TEXTURE_SIZE + u
        color = (self._texels[texel] * shade[:, None]) >> 8
        return np.asarray(np.minimum(color, 255), np.uint8)

    @property
    def triangle_offsets(self) -> npt.NDArray[np.uint32]:
        """Return the first triangle row of each part (len(parts) + 1,), for `surface_color`."""
        return self._offsets

    def render_depth(
        self, world_from_depth: npt.NDArray[np.float64], *, intrinsics: Intrinsics
    ) -> DepthView:
        """Render what the depth camera's noise model needs: z-depth, incidence, albedo, gloss."""
        hits = self._cast(world_from_depth, intrinsics)
        shape = (intrinsics.height, intrinsics.width)
        cos = (
            np.abs(np.einsum("ij,ij->i", hits.normal, hits.direction))
            * self._directions(intrinsics)[1]
        )
        return DepthView(
            hits.depth_m.reshape(shape),
            cos.reshape(shape),
            self._luminance[hits.geometry].reshape(shape),
            self._glossy[hits.geometry].reshape(shape),
        )

    def depth_image(
        self, world_from_camera: npt.NDArray[np.float64], *, intrinsics: Intrinsics
    ) -> npt.NDArray[np.float32]:
        """Return the exact z-depth (H, W) metres seen by any pinhole camera, 0 = no hit."""
        depth = self._cast(world_from_camera, intrinsics).depth_m
        return depth.reshape(intrinsics.height, intrinsics.width)


def _triangle_tables(
    scene: Scene, part_material: npt.NDArray[np.int64], inv_texel: list[float]
) -> npt.NDArray[np.float32]:
    """Return per triangle (T + 1, 10) float32, the last row for "no hit".

    Columns: texel u at vertex 0 and its changes to vertices 1 and 2, the same for v, then the
    same for the Gouraud shade, then the material's first texel index. Texture coordinates are
    the two world axes most parallel to the triangle (a triplanar mapping), reduced modulo the
    texture so that float32 keeps sub-texel precision.
    """
    rows = []
    for part, material in zip(scene.parts, part_material[:-1], strict=True):
        v = part.mesh.vertices[part.mesh.triangles]  # (M, 3 vertices, 3)
        normal = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        axes = np.array([[1, 2], [0, 2], [0, 1]])[np.argmax(np.abs(normal), axis=1)]
        uv = np.take_along_axis(v, axes[:, None, :], axis=2) * inv_texel[material]  # (M, 3, 2)
        uv -= np.floor(uv[:, :1] / TEXTURE_SIZE) * TEXTURE_SIZE
        uv += _TEXEL_OFFSET
        shade = np.minimum(_lambert(v, normal, scene), 1.0)  # (M, 3); x 256 fits uint16
        base = np.full((len(v), 1), material * TEXTURE_SIZE * TEXTURE_SIZE, np.float64)
        rows.append(
            np.concatenate([_deltas(uv[..., 0]), _deltas(uv[..., 1]), _deltas(shade), base], 1)
        )
    rows.append(np.zeros((1, 10)))
    return np.concatenate(rows).astype(np.float32)


def _deltas(x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Return (M, 3) values at the 3 vertices as (x0, x1 - x0, x2 - x0) for barycentric mixing."""
    return np.stack([x[:, 0], x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]], axis=1)


def _lambert(
    vertices: npt.NDArray[np.float64], normal: npt.NDArray[np.float64], scene: Scene
) -> npt.NDArray[np.float64]:
    """Return ambient + Lambert shade (M, 3) at each triangle vertex from the scene's lights."""
    shade = np.full(vertices.shape[:2], scene.ambient)
    for light in scene.lights_m:
        to_light = light - vertices
        cos = np.einsum("mvk,mk->mv", to_light, normal) / np.linalg.norm(to_light, axis=2)
        shade += scene.diffuse / len(scene.lights_m) * np.maximum(cos, 0.0)
    return shade
