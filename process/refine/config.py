"""The refinement's configuration: the paper's parameters (Table 5, section 2.4) and ours."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from process.errors import ConfigError
from process.refine.selection import RULES


@dataclass(frozen=True)
class RefineConfig:
    """Parameters of planes -> SOR -> adaptive DBSCAN -> regrowth.

    The paper's Table 5 picks D = 0.10 m, Min = 250,000 and Max = 100,000 for a 2.3-million
    point cloud of a whole office; our defaults suit voxel maps of 0.1-1 million points at
    1-2 cm, where 0.10 m would swallow chair feet and table legs into the floor.
    """

    plane_distance_m: float = 0.02  # D: RANSAC inlier distance
    plane_min_points: int = 0  # Min: a plane with fewer inliers ends the search; 0 = relative:
    plane_min_area_m2: float = 1.0  # ... this much surface at the cloud's density,
    plane_min_share: float = 0.02  # ... or this share of the points, whichever is smaller
    plane_max_remaining: int = 1000  # Max: the search ends once fewer points remain
    plane_iterations: int = 300  # RANSAC iterations per plane (Table 5: 300)
    plane_local_hypotheses: int = 300  # ... and this many planes of random points' neighbours
    # compete with RANSAC's (ransac.py: finds walls of a few % of the points); 0: off
    plane_sample_points: int = 20_000  # RANSAC hypotheses are scored on this many random points
    max_planes: int = 8  # planes tried at most, structural or not ...
    structure_planes: int = 4  # ... then up to this many more, kept only as walls, floors or
    # ceilings (generator 4: desks, seats and sofas use up the 8 and walls were left out), or
    # for bare faces (faces.py; 4 rather than 2: generator 5's kitchen at 60k 0.852 -> 0.872)
    horizontal_tolerance_deg: float = 10.0  # a normal this close to `up` is horizontal
    structure_height_tol_m: float = 0.3  # floor/ceiling: this close to the lowest/highest points
    wall_min_height_m: float = 1.5  # a wall rises this high; floor and ceiling are this far apart
    wall_object_depth_m: float = 0.2  # a wall plane's points this far in front of a parallel
    # wall behind it hang on that wall (a television): they go back to the objects (walls.py)
    furniture_depth_m: float = 1.2  # a wall plane up to this far in front of a larger parallel
    furniture_top_gap_m: float = 0.3  # wall, ending this much lower, is a cabinet (walls.py)
    wall_keep_out_m: float = 0.03  # points this far behind a wall plane (a door or window
    # recess) join no object in regrowth; 0: regrowth may cross walls (walls.py)
    structure_band_sigmas: float = 3.0  # a structural plane keeps its points this many robust
    # std of their distances deep (at most plane_distance_m); 0: all inliers (walls.py)
    wall_noise_sigmas: float = 4.0  # a noisy wall takes in the points, off all planes, that the
    # network calls no object, this many robust std of its own from it (at most three
    # plane_distance_m), where that is past plane_distance_m; 0: RANSAC's band (walls.py)
    walls_behind_objects: bool = True  # a thin wall takes in the points on its own surface
    # (refitted on its bare points) behind an object standing before it, which the network's
    # label bleeds onto and the plane step had kept with the object's wide region (walls.py)
    floor_label_max_m: float = 0.1  # "floor" this far above the floor plane is unlabelled
    # (walls.py; 0: the network's floor labels stand wherever they are)
    floor_band_regrows: bool = True  # "floor" off the planes, past plane_distance_m and up to
    # floor_label_max_m above the floor plane, is open to regrowth; what no object takes stays
    # floor (walls.py)
    plane_object_width_m: float = 0.25  # object-labelled regions this wide on a plane stay
    wall_object_share: float = 0.25  # ... on a wall, cells where object labels are the most of
    # the labelled points and over this share of all (floor and ceiling: over half; planes.py)
    # faces: pieces of upright or level planes that are no structure, this large (or the plane
    # step's Min if fewer points; faces.py) ...
    face_min_area_m2: float = 0.5
    bare_face_share: float = 0.1  # ... labelled an object on under this share join no object in
    # regrowth; 0: off
    face_fill_share: float = 0.6  # ... upright ones where one class holds this share of their
    # object labels give it to their points left 0 after regrowth; 0: off
    bare_face_rim_share: float = 0.5  # a bare face whose rim regrowth gave this share of to one
    # object class is that object's: a sofa's seat the network missed whole (faces.py); 0: off
    table_surfaces: bool = True  # a level plane at a desk's height is a table top (surfaces.py):
    table_heights_m: tuple[float, float] = (0.5, 1.1)  # ... its median this high above the floor
    table_min_area_m2: float = 0.25  # ... and this large; its structure, clutter and unlabelled
    # points become table (on TUM fr1_rpy the networks call the desk wall and clutter)
    table_tolerance_deg: float = 15.0  # ... and level to this (a fused desk tilts with drift);
    # a piece labelled an object class on less than this share of its points ...
    table_min_object_share: float = 0.1
    # ... over this many times its points unlabelled under it per metre of the body under it (10
    # cm over the floor to 10 cm under the top) is a cabinet's or counter's top (generator 5:
    # bare kitchen counters and a TV's low cabinet became table; surfaces.py)
    table_solid_per_m: float = 2.5
    table_other_cell_m: float = 0.2  # ... but cells this wide labelled more chair, person,
    # plant or sofa than desk stay out of it (0: none; surfaces.py)
    up: tuple[float, float, float] | None = None  # gravity-up in the cloud's frame; None = find
    sor_nb_neighbors: int = 20  # SOR: neighbours of the mean distance
    sor_std_ratio: float = 2.0  # SOR: outlier beyond mean + ratio * std of the mean distances
    dbscan_method: int = 2  # 1: one (eps, MinPts) for all classes; 2: one per class (paper)
    k_max: int = 30  # largest K of the KANN eps_K candidates
    cluster_voxel_m: float = 0.03  # DBSCAN runs on the centroids of voxels this size; 0 = points
    max_cells: int = 400_000  # SOR and each class's DBSCAN run on at most this many points or
    # voxel centroids; past it the voxels grow (multi-million-point clouds), labels carried back
    dbscan_rule: str = "plateau"  # K choice: "plateau" (selection.py) or "literal" (PAPER.md)
    plateau_tolerance: float = 0.25  # "plateau": large-cluster counts may vary by this share
    min_pts_statistic: str = "lower_quartile"  # MinPts_K: "mean" (paper) or "lower_quartile"
    max_eps_m: float = 0.15  # eps_K candidates stop here (0: none, the paper's K = 1..k_max)
    min_cluster_points: int = 30  # clusters smaller than this go back to label 0 ...
    min_cluster_area_m2: float = 0.01  # ... or smaller than this surface at the class's density
    full_curves: bool = False  # run DBSCAN for every K, not only until the stable run ends
    regrowth: bool = True  # recover unlabelled points around each cluster
    object_gap_m: float = 0.15  # regrowth: same-class clusters this close are one object, and
    # up to this far apart when a wrong-class patch touches both (a sofa's seat called chair
    # between its back and front: a fused simulated map gained 0.049; objects.py); 0: off
    object_bridge_m: float = 0.5
    floor_leaf: bool = True  # unlabelled points on the floor plane join an object in regrowth
    # but pass growth on to no other point, and only along surfaces (`regrow_surface_link`; 0:
    # within r1) (regrowth.py); False: they relay it
    sparse_clusters_yield: bool = True  # a cluster sparse at the paper's MinPts goes to 0
    # when its box overlaps a denser cluster of another class (lower_quartile keeps such)
    attach_small_clusters: bool = True  # a small cluster that close to a big one is kept
    nested_objects_yield: bool = True  # an object inside another class's box regrows only
    # the points the network gave its class (regrowth.py: a wrong-class patch stays small)
    nested_adopt_ratio: float = 1.5  # ... and takes its host's class where the host object
    # has this many times its points and it lies on the host, not just in its box (0: never);
    # 3 before the touch rule: a box's face the network calls chair has 1 / 1.7 of the box
    nested_patch_max_m: float = 0.7  # ... but only a patch nests: a cluster whose box has a
    # longer diagonal is an object of its own (a chair under a seated person); 0: any size
    table_top_m: float = 0.02  # regrowth: a table's box reaches this far above its top,
    # not r1: clutter on it that DBSCAN set to 0 stays off the table (0: r1, the paper's)
    regrow_surface_link: float = 2.5  # regrowth's waves first reach this many point spacings,
    # along surfaces, until none joins, then r1 (a seated person's r1 bridges the gap to his
    # chair's back; regrowth.py); 0: r1 only, the paper's
    rejoin_own_class: bool = True  # after regrowth, a point still 0 inside an object of its
    # phase-I class (not a table), and of no other class, joins it beyond r1 (regrowth.py)
    tabletop_objects: bool = True  # after regrowth, points still 0 of one object class that
    # stand on a table's top, min_cluster_points of them, become an object (tabletop.py)
    orphan_adoption: bool = True  # then a segment still 0 that the network labelled (a chair's
    # back it called floor) joins the one object class it touches, not a table (orphans.py)
    lone_objects: bool = True  # then a segment still 0 that touches no object, of at least
    # min_cluster_points, becomes an object of the class most of its network labels give
    # (orphans.py)
    rejoin_strays: bool = True  # after regrowth, a point the network calls plant that SOR or
    # phase II left out, not alone, joins the plant's refined points within r1, in waves:
    # sparse foliage is no noise (outliers.py)
    raised_vote: bool = True  # then table-labelled pieces above a table surface's noise band
    # (a monitor's base plate, forearms on a desk) take the class of the object they touch,
    # when that is most of their contacts and at least their size (raised.py)
    seam_vote_m: float = 0.08  # after regrowth, an object point this close to another class
    # takes the class of the smooth surface it lies on, if that class holds most of it and the
    # point's own object lies mostly elsewhere: a label bled across a contact (seams.py); 0: off
    seam_angle_deg: float = 15.0  # ... neighbours with normals this close share a surface,
    seam_flatness: float = 0.06  # ... where both vary less than this off their local plane
    piece_vote: bool = True  # then a face one class's label bled onto across a gap (a piece
    # of that class at the point spacing, not its object's largest, bordered all round by one
    # other class's larger piece, not a table's) takes that class (pieces.py)
    regrow_own_class_first: bool = True  # regrowth gives points back to their phase-I class first
    regrow_structure: bool = False  # regrowth may turn points the network calls structure
    # (ceiling, floor, wall) that DBSCAN set to 0 into objects (the paper: any 0 point grows)
    table_legs: bool = True  # chair clusters under a table's top, floor to top, are its legs
    # (legs.py)
    chair_seats: bool = True  # a low, level, seat-sized table cluster touching a chair is its
    # seat (legs.py)
    table_tops: bool = True  # a chair, person or sofa cluster lying mostly on a table's top
    # gives its points there to the table (tops.py)
    fill_tops: bool = True  # a table top's points the network calls table that nothing took
    # join the table (tops.py)
    flat_floor: bool = True  # an object cluster lying flat in the floor's band is floor (flat.py)
    low_chairs: bool = True  # a chair cluster lower than a seat, no part of a chair, is clutter
    # (low.py)
    narrow_sofas: bool = True  # a sofa object of a chair's size and shape is a chair (sofas.py)
    tall_chairs: bool = True  # a chair cluster 1.4-2.1 m tall is a person (low.py)
    screens: bool = True  # a thin upright clutter panel off the floor is a screen (screens.py)
    beyond_feet: bool = True  # what regrowth gave a screen or clutter on the level surface it
    # stands on, beyond its foot, is given back (footing.py)
    standing_bases: bool = True  # a segment the network saw in part (15 %), under an object of
    # a standing class it calls it, joins that object: a chair's base, a table's leg (orphans.py)
    structure_noise_m: float = 0.03  # a point left unlabelled that the network calls floor, wall
    # or ceiling, this close to a plane of that class, takes that label (surface_noise.py; 0: off)
    flat_walls: bool = True  # a standing-class cluster flat in a wall's band, over the floor and
    # apart from every other object, is wall (flat.py)
    inside_objects_share: float = 0.6  # a structure cluster off the planes whose labelled
    # neighbours are at least this share objects is opened to regrowth (inside.py; 0: never)
    inside_objects_link: float = 3.0  # ... neighbours within this many object point spacings
    seed: int = 0  # RANSAC sampling

    @classmethod
    def paper(cls, **overrides: Any) -> RefineConfig:
        """Return PAPER.md's literal reading wherever our defaults depart from it.

        The literal K rule (first run of 3 equal counts), MinPts the mean count, K = 1..k_max
        uncapped, clusters kept by size alone, regrowth blind to the network's labels and
        to objects nested in others, every inlier of a structural plane taken (objects on
        walls too), no table surfaces. What stays ours: DBSCAN on voxel cells, planes told
        by orientation and position (and the network's structure labels), only object
        classes regrowing, inside their object's box.
        """
        paper: dict[str, Any] = {
            "dbscan_rule": "literal",
            "min_pts_statistic": "mean",
            "max_eps_m": 0.0,
            "attach_small_clusters": False,
            "sparse_clusters_yield": False,
            "regrow_own_class_first": False,
            "nested_objects_yield": False,
            "plane_object_width_m": 0.0,
            "wall_object_depth_m": 0.0,
            "wall_keep_out_m": 0.0,
            "bare_face_share": 0.0,
            "face_fill_share": 0.0,
            "bare_face_rim_share": 0.0,
            "floor_leaf": False,
            "furniture_depth_m": 0.0,
            "plane_local_hypotheses": 0,
            "structure_band_sigmas": 0.0,
            "wall_noise_sigmas": 0.0,
            "walls_behind_objects": False,
            "floor_label_max_m": 0.0,
            "floor_band_regrows": False,
            "table_surfaces": False,
            "table_top_m": 0.0,
            "rejoin_own_class": False,
            "regrow_surface_link": 0.0,
            "tabletop_objects": False,
            "seam_vote_m": 0.0,
            "piece_vote": False,
            "raised_vote": False,
            "rejoin_strays": False,
            "orphan_adoption": False,
            "lone_objects": False,
            "object_bridge_m": 0.0,
            "regrow_structure": True,
            "inside_objects_share": 0.0,
            "table_legs": False,
            "chair_seats": False,
            "table_tops": False,
            "flat_floor": False,
            "low_chairs": False,
            "narrow_sofas": False,
            "tall_chairs": False,
            "screens": False,
            "beyond_feet": False,
            "structure_noise_m": 0.0,
            "standing_bases": False,
            "fill_tops": False,
            "flat_walls": False,
        }
        return cls(**{**paper, **overrides})

    def __post_init__(self) -> None:
        checks = {
            "plane_distance_m": (self.plane_distance_m, 1e-4, 1.0),
            "plane_min_points": (self.plane_min_points, 0, 10**9),
            "plane_min_area_m2": (self.plane_min_area_m2, 0.0, 10**6),
            "plane_min_share": (self.plane_min_share, 0.0, 1.0),
            "plane_max_remaining": (self.plane_max_remaining, 0, 10**9),
            "plane_iterations": (self.plane_iterations, 1, 100_000),
            "plane_local_hypotheses": (self.plane_local_hypotheses, 0, 100_000),
            "plane_sample_points": (self.plane_sample_points, 0, 10**9),
            "max_planes": (self.max_planes, 0, 100),
            "structure_planes": (self.structure_planes, 0, 100),
            "horizontal_tolerance_deg": (self.horizontal_tolerance_deg, 0.0, 45.0),
            "structure_height_tol_m": (self.structure_height_tol_m, 0.0, 10.0),
            "wall_min_height_m": (self.wall_min_height_m, 0.0, 100.0),
            "sor_nb_neighbors": (self.sor_nb_neighbors, 1, 1000),
            "sor_std_ratio": (self.sor_std_ratio, 0.01, 100.0),
            "dbscan_method": (self.dbscan_method, 1, 2),
            "k_max": (self.k_max, 3, 1000),
            "min_cluster_points": (self.min_cluster_points, 1, 10**9),
            "object_gap_m": (self.object_gap_m, 0.0, 10.0),
            "object_bridge_m": (self.object_bridge_m, 0.0, 10.0),
            "nested_adopt_ratio": (self.nested_adopt_ratio, 0.0, 10**6),
            "nested_patch_max_m": (self.nested_patch_max_m, 0.0, 10**3),
            "table_top_m": (self.table_top_m, 0.0, 1.0),
            "regrow_surface_link": (self.regrow_surface_link, 0.0, 100.0),
            "inside_objects_share": (self.inside_objects_share, 0.0, 1.0),
            "inside_objects_link": (self.inside_objects_link, 0.0, 100.0),
            "seam_vote_m": (self.seam_vote_m, 0.0, 1.0),
            "seam_angle_deg": (self.seam_angle_deg, 0.0, 90.0),
            "seam_flatness": (self.seam_flatness, 0.0, 1.0 / 3.0),
            "max_eps_m": (self.max_eps_m, 0.0, 10.0),
            "plane_object_width_m": (self.plane_object_width_m, 0.0, 10.0),
            "wall_object_depth_m": (self.wall_object_depth_m, 0.0, 10.0),
            "wall_keep_out_m": (self.wall_keep_out_m, 0.0, 10.0),
            "furniture_depth_m": (self.furniture_depth_m, 0.0, 10.0),
            "furniture_top_gap_m": (self.furniture_top_gap_m, 0.0, 10.0),
            "structure_band_sigmas": (self.structure_band_sigmas, 0.0, 100.0),
            "wall_noise_sigmas": (self.wall_noise_sigmas, 0.0, 100.0),
            "wall_object_share": (self.wall_object_share, 0.0, 1.0),
            "bare_face_share": (self.bare_face_share, 0.0, 1.0),
            "face_fill_share": (self.face_fill_share, 0.0, 1.0),
            "bare_face_rim_share": (self.bare_face_rim_share, 0.0, 1.0),
            "face_min_area_m2": (self.face_min_area_m2, 0.0, 100.0),
            "floor_label_max_m": (self.floor_label_max_m, 0.0, 100.0),
            "structure_noise_m": (self.structure_noise_m, 0.0, 1.0),
            "table_min_area_m2": (self.table_min_area_m2, 0.0, 100.0),
            "table_tolerance_deg": (self.table_tolerance_deg, 0.0, 45.0),
            "table_min_object_share": (self.table_min_object_share, 0.0, 1.0),
            "table_solid_per_m": (self.table_solid_per_m, 0.0, 1000.0),
            "table_other_cell_m": (self.table_other_cell_m, 0.0, 10.0),
            "cluster_voxel_m": (self.cluster_voxel_m, 0.0, 1.0),
            "max_cells": (self.max_cells, 1000, 10**9),
            "min_cluster_area_m2": (self.min_cluster_area_m2, 0.0, 100.0),
            "seed": (self.seed, 0, 2**31 - 1),
        }
        for name, (value, low, high) in checks.items():
            if not low <= value <= high:
                raise ConfigError(f"refinement.{name} must be in {low}..{high}, got {value}")
        if 0 < self.plane_min_points < 3:
            raise ConfigError(
                "refinement.plane_min_points must be 0 (relative to the cloud) or >= 3, "
                f"got {self.plane_min_points}"
            )
        if self.min_pts_statistic not in ("mean", "median", "lower_quartile"):
            raise ConfigError(
                "refinement.min_pts_statistic must be mean, median or lower_quartile, "
                f"got {self.min_pts_statistic!r}"
            )
        if self.dbscan_rule not in RULES:
            raise ConfigError(
                f"refinement.dbscan_rule must be one of {', '.join(RULES)}, "
                f"got {self.dbscan_rule!r}"
            )
        if not 0.0 <= self.plateau_tolerance <= 1.0:
            raise ConfigError(
                f"refinement.plateau_tolerance must be in 0..1, got {self.plateau_tolerance}"
            )
        if 0 < self.plane_sample_points < 3:
            raise ConfigError(
                "refinement.plane_sample_points must be 0 (all points) or >= 3, "
                f"got {self.plane_sample_points}"
            )
        low, high = self.table_heights_m if len(self.table_heights_m) == 2 else (1.0, 0.0)
        if not 0.0 <= low <= high <= 10.0:
            raise ConfigError(
                "refinement.table_heights_m must be [low, high] metres above the floor with "
                f"0 <= low <= high <= 10, got {list(self.table_heights_m)}"
            )
        if self.up is not None and (
            len(self.up) != 3
            or not all(math.isfinite(v) for v in self.up)
            or sum(v * v for v in self.up) < 1e-12
        ):
            raise ConfigError(
                f"refinement.up must be a finite non-zero 3-vector or absent, got {self.up}"
            )
