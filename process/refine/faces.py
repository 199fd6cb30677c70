"""Faces: large planes that are no structure, told apart by what the network sees on them.

RANSAC's planes past the walls include the faces of furniture: a cabinet's or a wardrobe's
front or top, a television's screen, a desk's side. The plane step leaves them to the objects
(they are neither floor, ceiling nor wall); here each large connected piece (gaps over 10 cm
separate) of an upright or level one is a face (`_faces`), and the network's labels on it say
what it is:

- Bare (under `bare_face_share` of it labelled an object class): furniture the network has no
  class for. An object standing on such furniture reaches down to the floor in regrowth (its
  pot, stem or legs are missed first) and walked down the front under it (generator 5's kitchen
  at 200k: 15,300 cabinet points made plant), and the clutter on a cabinet, its box widened by
  label bleed, grew over the cabinet's top (generator 5's kitchen, seed 1: 10,500 points). No
  object grows over a bare face, upright or level (a table surface is labelled table, so it is
  never bare). Planes RANSAC finds past `max_planes` that are no structure are looked at for
  this only (`PlaneSegmentation.faces_only`): in generator 5's kitchen the floor, four walls
  and three cabinet fronts came first, and the counter's top, found next, was dropped, so the
  bottles on it grew over it as clutter (7,600 points; F1 0.775 -> 0.794). Kept as full planes
  (table surfaces, filled faces, fronts), more planes cost generator 2 up to 0.011.
- One object's (not bare, and one class holds `face_fill_share` of its object labels): a
  screen seen with most of it missed. After regrowth its points still unlabelled take that
  class (upright faces only: a desk's top filled by its majority cost generator 4 up to
  0.005): regrowth reaches only r1 beyond the object's box, and the box is only the part the
  network saw (generator 2's room 6: a television 80 % unlabelled, three quarters of its labels
  monitor and the rest a seated person's bleed; F1 of the class 0.779 -> 0.847).

- Bare, but enclosed by one object: after regrowth most of the points around its edge (within
  RIM_M, off the face) are one object class, and its unlabelled points take it
  (`enclosed_faces`). A sofa the network missed whole grew back from its few labelled specks
  around its seat, which is a bare level face (generator 2, a fresh seed: 3,513 seat points
  left out, the rim 96 % sofa); furniture the network has no class for is rimmed by its own
  unlabelled sides, the floor or a wall (under 25 % one object class on every bare face of
  the suite).

Faces are not a step of the paper's; its office has no furniture the network cannot name.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from capture.recording import Label
from process.refine.config import RefineConfig
from process.refine.graph import kd_tree
from process.refine.plane_grid import PIECE_CELL_M, connected_pieces, plane_uv

RIM_M = 0.05  # a face's rim: the points this close to it, not on it (enclosed_faces)
RIM_PROBES = 3000  # face points whose neighbourhoods make the rim

if TYPE_CHECKING:
    from process.refine.planes import PlaneSegmentation


def bare_faces(
    points: npt.NDArray[np.float32],
    planes: PlaneSegmentation,
    labels: npt.NDArray[np.uint8],
    cfg: RefineConfig,
) -> list[npt.NDArray[np.intp]]:
    """Return the inliers of each face the network leaves bare (`labels`: its labels)."""
    if cfg.bare_face_share <= 0:
        return []
    return [
        face
        for face in _faces(points, planes, cfg, level_too=True, past_max=True)
        if np.count_nonzero(labels[face] >= Label.TABLE) < cfg.bare_face_share * len(face)
    ]


def enclosed_faces(
    points: npt.NDArray[np.float32],
    bare: list[npt.NDArray[np.intp]],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    cfg: RefineConfig,
    *,
    open_: npt.NDArray[np.bool_] | None = None,
) -> npt.NDArray[np.intp]:
    """Give a bare face the class that holds most of its rim after regrowth (in place).

    `bare`: the bare faces' inliers (`bare_faces`); `labels` and `clusters`: the refined ones,
    updated in place: the face's points still 0 (and in `open_`, if given) take the class that
    holds `bare_face_rim_share` of the rim's points, and the cluster that holds most of the
    rim's points of that class. Returns the indices of the points filled.
    """
    filled: list[npt.NDArray[np.intp]] = []
    if cfg.bare_face_rim_share <= 0:
        return np.zeros(0, np.intp)
    for face in bare:
        empty = face[(labels[face] == 0) if open_ is None else (labels[face] == 0) & open_[face]]
        if len(empty) == 0:
            continue
        probe = points[face[:: max(1, len(face) // RIM_PROBES)]]  # a sample's rim is the rim
        box = np.all(
            (points >= probe.min(axis=0) - RIM_M) & (points <= probe.max(axis=0) + RIM_M), axis=1
        )
        box[face] = False
        near = np.flatnonzero(box)
        rim = near[np.isfinite(kd_tree(probe).query(points[near], distance_upper_bound=RIM_M)[0])]
        counts = np.bincount(labels[rim], minlength=Label.TABLE + 1)
        top = int(np.argmax(counts[Label.TABLE :])) + Label.TABLE
        if len(rim) == 0 or counts[top] < cfg.bare_face_rim_share * len(rim):
            continue
        own = clusters[rim[labels[rim] == top]]
        labels[empty] = top
        clusters[empty] = np.bincount(own[own > 0]).argmax() if (own > 0).any() else 0
        filled.append(empty)
    return np.concatenate(filled) if filled else np.zeros(0, np.intp)


def fill_faces(
    points: npt.NDArray[np.float32],
    planes: PlaneSegmentation,
    network: npt.NDArray[np.uint8],
    labels: npt.NDArray[np.uint8],
    clusters: npt.NDArray[np.int32],
    cfg: RefineConfig,
    *,
    open_: npt.NDArray[np.bool_] | None = None,
) -> npt.NDArray[np.intp]:
    """Give each face's unlabelled points its class, where one class holds the face (in place).

    The network's labels (`network`) decide whose a face is; `labels` and `clusters` are the
    refined ones (after regrowth), and a filled point joins the largest cluster of the face's
    class on it; `open_`: the points that may be filled (not SOR's outliers), all if None.
    Returns the indices of the points filled.
    """
    filled: list[npt.NDArray[np.intp]] = []
    if cfg.face_fill_share <= 0:
        return np.zeros(0, np.intp)
    for face in _faces(points, planes, cfg):
        said = network[face]
        objects = said[said >= Label.TABLE]
        if len(objects) == 0 or len(objects) < cfg.bare_face_share * len(face):
            continue  # bare: no object's
        counts = np.bincount(objects)
        top = int(np.argmax(counts))
        lab = labels[face]
        empty = face[(lab == 0) if open_ is None else (lab == 0) & open_[face]]
        if counts[top] < cfg.face_fill_share * len(objects) or len(empty) == 0:
            continue
        own = clusters[face[lab == top]]
        labels[empty] = top
        clusters[empty] = np.bincount(own[own > 0]).argmax() if (own > 0).any() else 0
        filled.append(empty)
    return np.concatenate(filled) if filled else np.zeros(0, np.intp)


def _faces(
    points: npt.NDArray[np.float32],
    planes: PlaneSegmentation,
    cfg: RefineConfig,
    *,
    level_too: bool = False,
    past_max: bool = False,
) -> Iterator[npt.NDArray[np.intp]]:
    """Yield the inliers of each large piece of each upright plane that is no structure.

    Large: the plane step's Min points, or `face_min_area_m2` at the cloud's density where
    that is fewer (a 200k-point generator-5 room's Min is 13,000 points, 1.7 m^2: a television
    stand's top, 0.6 m^2, was no face).

    `level_too`: of each level one too (a cabinet's top); table surfaces are labelled table.
    `past_max`: of the planes found past max_planes too (`PlaneSegmentation.faces_only`).
    """
    if planes.up is None:
        return
    upright = math.sin(math.radians(cfg.horizontal_tolerance_deg))
    level = math.cos(math.radians(cfg.horizontal_tolerance_deg))
    least = float(planes.min_points)  # a plane's Min, or face_min_area_m2 if that is fewer
    if math.isfinite(planes.density_per_m2):
        least = min(least, cfg.face_min_area_m2 * planes.density_per_m2)
    for plane in planes.planes + (planes.faces_only if past_max else ()):
        cosine = abs(float(plane.model[:3] @ planes.up))
        if plane.label or (cosine > upright and not (level_too and cosine >= level)):
            continue
        piece = connected_pieces(plane_uv(points[plane.indices], plane.model), PIECE_CELL_M)
        sizes = np.bincount(piece)
        for k in np.flatnonzero(sizes >= max(least, 1)):
            yield plane.indices[piece == k]
