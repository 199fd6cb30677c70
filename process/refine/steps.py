"""The refinement as a table of contents: planes -> SOR -> adaptive DBSCAN -> regrowth."""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import numpy.typing as npt

from capture.recording import NUM_LABELS, OBJECT_LABELS, STRUCTURAL_LABELS, Label
from process.cloud import LabelledCloud
from process.errors import StageError
from process.evaluate import label_metrics
from process.refine.cells import attached_clusters, capped_cells, sparse_inside_others
from process.refine.config import RefineConfig
from process.refine.dbscan import DbscanChoice, KannCurves, dbscan, estimate_parameters, query_size
from process.refine.faces import bare_faces, enclosed_faces, fill_faces
from process.refine.flat import flat_on_floor, flat_on_walls
from process.refine.footing import beyond_feet
from process.refine.inside import structure_inside_objects
from process.refine.legs import legs_under_tables, seats_called_table
from process.refine.low import low_chairs, tall_chairs
from process.refine.orphans import adopt_orphans, lone_objects
from process.refine.outliers import rejoin_strays, sor_inliers
from process.refine.pieces import piece_vote
from process.refine.planes import PlaneSegmentation, segment_planes
from process.refine.raised import raised_off_tables
from process.refine.regrowth import regrow
from process.refine.screens import flat_screens
from process.refine.seams import seam_vote
from process.refine.sofas import narrow_sofas
from process.refine.surface_noise import network_surfaces
from process.refine.tabletop import tabletop_objects
from process.refine.tops import left_on_tops, tops_called_seats
from process.refine.walls import behind_walls, floor_said_low, main_floor, wall_bands

logger = logging.getLogger(__name__)

Indices = npt.NDArray[np.intp]
# a vote by the floor plane: (points, labels, clusters, floor, up) -> (labels, clusters, moved)
FloorRule = Callable[
    [
        npt.NDArray[np.float32],
        npt.NDArray[np.uint8],
        npt.NDArray[np.int32],
        npt.NDArray[np.float64] | None,
        npt.NDArray[np.float64],
    ],
    tuple[npt.NDArray[np.uint8], npt.NDArray[np.int32], Indices],
]


@dataclass(frozen=True)
class ClassClustering:
    """What adaptive DBSCAN did to one class (a row of the paper's Tables 1 and 8)."""

    label: int  # the class; 0 for method 1's estimate over all labelled points
    points: int
    curves: KannCurves | None  # None: too few points, or method 1's class (see the shared one)
    choice: DbscanChoice | None  # None: fewer points than a cluster needs, all set to 0
    clusters: int  # clusters kept
    relabelled: int  # points set to 0 (noise and small clusters)
    seconds_params: float
    seconds_cluster: float


@dataclass(frozen=True)
class RefineResult:
    """Every step's output; arrays of length N follow the input cloud's order."""

    fused: LabelledCloud  # the input (phase I)
    planes: PlaneSegmentation
    sor_outliers: npt.NDArray[np.intp]  # input indices that SOR removed (some rejoin later)
    method: int
    dbscan: dict[int, ClassClustering]  # per class label
    shared: ClassClustering | None  # method 1: the one estimate for all classes
    labels_ii: npt.NDArray[np.uint8]  # (N,) after DBSCAN; plane labels on planes, 0 if removed
    clusters_ii: npt.NDArray[np.int32]  # (N,)
    labels_iii: npt.NDArray[np.uint8]  # (N,) after regrowth
    clusters_iii: npt.NDArray[np.int32]  # (N,)
    regrown: npt.NDArray[np.intp]  # input indices that regrowth labelled (faces filled too)
    r2_m: dict[int, float] = field(default_factory=dict)  # cluster id -> regrowth r2
    seconds: dict[str, float] = field(default_factory=dict)  # step -> wall time
    adopted: npt.NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, np.intp))
    # input indices of nested clusters that took their host object's class (regrowth.py)
    above_tables: int = 0  # points left 0 above table tops that r1 would have reached
    rejoined: int = 0  # points that joined an object of their phase-I class beyond r1
    tabletop: npt.NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, np.intp))
    # input indices of the small objects found standing on tables after regrowth (tabletop.py)
    behind_walls: int = 0  # unlabelled points behind a wall plane that regrowth left out
    seams: npt.NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, np.intp))
    # input indices that took the class of the smooth surface they lie on (seams.py)
    bare_faces: int = 0  # unlabelled points on large faces the network leaves bare (faces.py)
    faces_filled: npt.NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, np.intp))
    # input indices left unlabelled by regrowth on a face one class holds, given it (faces.py)
    pieces: npt.NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, np.intp))
    # input indices of pieces that took the class of the object holding them (pieces.py)
    orphans: npt.NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, np.intp))
    # input indices of unlabelled segments the network saw, given the class they touch (orphans.py)
    raised: npt.NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, np.intp))
    # input indices of table pieces above a table's top given the object they touch, and of
    # monitor points under a top given the table (raised.py)
    sunk: int = 0  # of them, the points under a top
    strays: npt.NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, np.intp))
    # input indices of plant-labelled points SOR or phase II left out that rejoined a plant
    # after regrowth (outliers.py; SOR's among them survive)
    enclosed: npt.NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, np.intp))
    # input indices on bare faces enclosed by one object that took its class (faces.py; they
    # are among faces_filled too)
    opened: npt.NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, np.intp))
    # input indices of floor and wall clusters amid object points, opened to regrowth (inside.py)
    legs: npt.NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, np.intp))
    # input indices of chair clusters under a table's top made its legs (legs.py)
    floor_band: npt.NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, np.intp))
    # input indices the network calls floor just over the floor's band that objects took
    lone: npt.NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, np.intp))
    # input indices of unlabelled segments the network saw touching no object, made objects
    seats: npt.NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, np.intp))
    # input indices of low, level table clusters touching a chair made its seat (legs.py)
    tops: npt.NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, np.intp))
    # input indices of table tops the network called chair, person or sofa, made table (tops.py)
    flat: npt.NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, np.intp))
    # input indices of object clusters lying flat in the floor's band, made floor (flat.py)
    flat_walls: npt.NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, np.intp))
    # input indices of standing-class clusters lying flat on a wall, apart, made wall (flat.py)
    low_chairs: npt.NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, np.intp))
    # input indices of chair clusters lower than a seat, part of no chair, made clutter (low.py)
    narrow_sofas: npt.NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, np.intp))
    # input indices of sofa objects of a chair's size and shape, made chair (sofas.py)
    tall_chairs: npt.NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, np.intp))
    # input indices of chair clusters taller than a chair, made person (low.py)
    screens: npt.NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, np.intp))
    # input indices of clutter clusters shaped as a screen, made tv_monitor (screens.py)
    beyond_feet: npt.NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, np.intp))
    # input indices regrowth gave a screen or clutter on the level surface under it, beyond its
    # foot, given back (footing.py)
    structure_noise: npt.NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, np.intp))
    # input indices left unlabelled that take the network's floor, wall or ceiling label by a
    # plane of that class (surface_noise.py; SOR's among them survive)
    top_filled: npt.NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, np.intp))
    # input indices on a table's top the network calls table, left 0, given the table (tops.py)

    @property
    def kept(self) -> npt.NDArray[np.bool_]:
        """Return the mask of input points that survive (all but SOR outliers that stay out)."""
        keep = np.ones(len(self.fused), bool)
        keep[self.sor_outliers] = False
        keep[self.strays] = True
        keep[self.structure_noise] = True
        return keep

    def final(self) -> LabelledCloud:
        """Return the refined map: every surviving point at its input position, final labels."""
        cloud = self.fused.with_labels(self.labels_iii, clusters=self.clusters_iii)
        return cloud.select(self.kept)

    def phase_clouds(self) -> dict[str, LabelledCloud]:
        """Return the input points labelled as phases I, II, III (removed points: label 0)."""
        return {
            "I": self.fused,
            "II": self.fused.with_labels(self.labels_ii, clusters=self.clusters_ii),
            "III": self.fused.with_labels(self.labels_iii, clusters=self.clusters_iii),
        }

    def phase_f1(self, truth: npt.NDArray[np.uint8]) -> dict[str, float]:
        """Return F1 over the object classes per phase ("I", "II", "III").

        `truth` holds a RECORDING.md label per input point, as the test-cloud generators give.
        """
        return {
            phase: label_metrics(cloud.labels, truth)["all"]["f1"]
            for phase, cloud in self.phase_clouds().items()
        }

    def plane_cloud(self) -> LabelledCloud:
        """Return the points on structural planes, labelled ceiling, floor or wall."""
        structural = self.planes.structural
        return self.fused.with_labels(self.planes.labels).select(structural)

    def outlier_cloud(self) -> LabelledCloud:
        """Return the points SOR removed, with their input labels."""
        return self.fused.select(self.sor_outliers)

    def cluster_cloud(self) -> LabelledCloud:
        """Return the object points DBSCAN kept, with their class and cluster."""
        keep = (self.clusters_ii > 0) & ~self.planes.structural
        return self.fused.with_labels(self.labels_ii, clusters=self.clusters_ii).select(keep)

    def seam_cloud(self) -> LabelledCloud:
        """Return the points the votes after regrowth relabelled: the .rrd's votes entity.

        The votes are seams.py's to screens.py's; the points footing.py gave back are shown too.
        """
        cloud = self.fused.with_labels(self.labels_iii, clusters=self.clusters_iii)
        votes = np.union1d(np.union1d(self.seams, self.pieces), np.union1d(self.raised, self.legs))
        votes = np.union1d(votes, self.seats)
        votes = np.union1d(votes, np.union1d(self.tops, self.flat))
        votes = np.union1d(votes, np.union1d(self.flat_walls, self.low_chairs))
        votes = np.union1d(votes, np.union1d(self.narrow_sofas, self.tall_chairs))
        votes = np.union1d(votes, np.union1d(self.screens, self.beyond_feet))
        return cloud.select(votes)

    def regrown_cloud(self) -> LabelledCloud:
        """Return the points regrowth labelled, with their new class and cluster."""
        cloud = self.fused.with_labels(self.labels_iii, clusters=self.clusters_iii)
        return cloud.select(self.regrown)


def refine(
    cloud: LabelledCloud, cfg: RefineConfig, *, up: npt.NDArray[np.float64] | None = None
) -> RefineResult:
    """Refine a fused labelled cloud; `up` (gravity-up in the cloud's frame) overrides cfg.up."""
    if len(cloud) and int(cloud.labels.max()) >= NUM_LABELS:
        raise StageError(
            f"refinement expects RECORDING.md label ids 0..{NUM_LABELS - 1}, "
            f"found {int(cloud.labels.max())}; map the labels first"
        )
    if up is not None and not np.isfinite(up).all():
        raise StageError(f"refinement expects a finite gravity-up, got {list(up)}; pass None")
    seconds: dict[str, float] = {}
    start = tick = time.perf_counter()

    def lap(step: str) -> None:
        nonlocal tick
        now = time.perf_counter()
        seconds[step], tick = seconds.get(step, 0.0) + now - tick, now  # a step may come twice

    planes = segment_planes(cloud.points, cfg, up=up, labels=cloud.labels)
    network = planes.object_labels(cloud.labels)  # phase I, table surfaces made table
    lap("planes")
    objects = np.flatnonzero(~planes.structural)
    keep = _sor(cloud.points[objects], cfg)
    outliers, objects = objects[~keep], objects[keep]
    lap("sor")
    points = cloud.points[objects]
    labels, clusters, per_class, shared = _correct(points, network[objects], cfg)
    lap("dbscan")
    labels_ii = np.where(planes.structural, planes.labels, 0).astype(np.uint8)
    clusters_ii = np.zeros(len(cloud), np.int32)
    labels_ii[objects], clusters_ii[objects] = labels, clusters
    labels_iii, clusters_iii = labels_ii.copy(), clusters_ii.copy()
    opened, inside = np.zeros(len(objects), bool), np.zeros(0, np.intp)
    if cfg.regrowth and cfg.inside_objects_share > 0:  # structure segments inside objects
        inside = structure_inside_objects(
            cloud.points, labels_ii, clusters_ii,
            share=cfg.inside_objects_share, link=cfg.inside_objects_link, network=network,
        )  # fmt: skip
        opened = np.isin(objects, inside)
        inside = objects[opened]  # not SOR's outliers: they take no part in regrowth
    low = np.zeros(len(objects), bool)  # the network's "floor" just over the floor's band
    if cfg.regrowth and cfg.floor_band_regrows:
        low = floor_said_low(points, planes.planes, planes.up, network[objects], cfg)
        opened |= low
    labels, clusters = np.where(opened, 0, labels), np.where(opened, 0, clusters)
    regrown, r2, adopted, above, rejoined = np.zeros(0, np.intp), {}, np.zeros(0, np.intp), 0, 0
    n_behind = n_faces = 0
    filled = orphans = lone = strays_rejoined = enclosed = off_feet = np.zeros(0, np.intp)
    tabletop = floor_band = np.zeros(0, np.intp)
    growable = None  # the points regrowth could label (None: no regrowth)
    if cfg.regrowth:
        r1 = {c: e.choice.eps_m for c, e in per_class.items() if e.choice is not None}
        # only objects grow: structure is the plane step's, and a leftover wall or floor
        # piece of the network's would otherwise take the object points DBSCAN set to 0
        seeds = np.where(np.isin(labels, OBJECT_LABELS), clusters, 0).astype(np.int32)
        prior = network[objects] if cfg.regrow_own_class_first else None
        # a point the network calls ceiling, floor or wall is evidence against every object,
        # and so is standing behind a wall plane (walls.behind_walls)
        behind_any = behind_walls(cloud.points, planes.planes, cfg)  # SOR's outliers too
        behind = behind_any[objects]
        keep_out = (
            behind
            if cfg.regrow_structure
            else behind | (np.isin(network[objects], STRUCTURAL_LABELS) & ~opened)
        )
        # ... and lying on a large upright face the network leaves bare: furniture it has no
        # class for (a cabinet's front under a plant on it; faces.py)
        bare = bare_faces(cloud.points, planes, network, cfg)
        on_bare = np.zeros(len(cloud), bool)
        for face in bare:
            on_bare[face] = True
        faces = on_bare[objects]
        keep_out |= faces
        on_floor = np.zeros(len(cloud), bool)  # RANSAC's floor band (its inliers)
        for plane in planes.planes:
            if plane.label == Label.FLOOR:
                on_floor[plane.indices] = True
        leaf = None
        if cfg.floor_leaf:  # unlabelled floor-plane points join objects but relay no growth
            leaf = on_floor[objects] & (labels == 0)
        n_behind = int((behind & (labels == 0)).sum())
        n_faces = int((faces & (labels == 0)).sum())
        grown = regrow(
            points, labels, seeds, r1_m=r1, gap_m=cfg.object_gap_m, bridge_m=cfg.object_bridge_m,
            up=planes.up, prior=prior, keep_out=keep_out, leaf=leaf, nest=cfg.nested_objects_yield,
            adopt_ratio=cfg.nested_adopt_ratio, patch_max_m=cfg.nested_patch_max_m,
            table_top_m=cfg.table_top_m, rejoin=cfg.rejoin_own_class,
            surface_link=cfg.regrow_surface_link,
        )  # fmt: skip
        new_labels, new_clusters = grown.labels, grown.clusters
        if cfg.tabletop_objects and planes.up is not None:
            new_labels, new_clusters, found = tabletop_objects(
                points, new_labels, new_clusters, network[objects], r1_m=r1, up=planes.up,
                min_points=cfg.min_cluster_points, first_id=int(clusters.max(initial=0)) + 1,
            )  # fmt: skip
            tabletop = objects[found]
        labels_iii[objects] = new_labels
        clusters_iii[objects] = np.where(new_clusters > 0, new_clusters, clusters)
        regrown, r2, adopted = objects[grown.regrown], grown.r2_m, objects[grown.adopted]
        above, rejoined = grown.above_tables, grown.rejoined
        open_ = np.zeros(len(cloud), bool)
        open_[objects] = True  # not on a structural plane, not SOR's outlier
        growable = np.zeros(len(cloud), bool)  # ... nor behind a wall, nor on a bare face
        growable[objects[~keep_out]] = True
        filled = fill_faces(
            cloud.points, planes, network, labels_iii, clusters_iii, cfg, open_=open_
        )
        enclosed = enclosed_faces(cloud.points, bare, labels_iii, clusters_iii, cfg, open_=open_)
        filled = np.union1d(filled, enclosed)
        regrown = np.union1d(regrown, filled)  # shown with the regrown points in the .rrd
        if cfg.orphan_adoption:  # what the network saw and phase II left unlabelled
            labels_iii, clusters_iii, orphans = adopt_orphans(
                cloud.points, labels_iii, clusters_iii, objects[~keep_out], cloud.labels,
                misnamed=planes.not_floor,
                up=planes.up if cfg.standing_bases else None, ground=on_floor,
            )  # fmt: skip
            regrown = np.union1d(regrown, orphans)  # shown with the regrown points too
        if cfg.lone_objects:  # what the network saw apart from every object, DBSCAN dropped
            labels_iii, clusters_iii, lone = lone_objects(
                cloud.points, labels_iii, clusters_iii, objects[~keep_out], cloud.labels,
                min_points=cfg.min_cluster_points, misnamed=planes.not_floor,
                up=planes.up if cfg.standing_bases else None, ground=on_floor,
            )  # fmt: skip
            regrown = np.union1d(regrown, lone)  # shown with the regrown points too
        if cfg.rejoin_strays:  # sparse foliage SOR and DBSCAN took for noise, to its plant
            left = np.zeros(len(cloud), bool)
            left[objects[~keep_out]] = True  # not behind a wall, not on a bare face
            left &= labels_iii == 0
            strays = np.union1d(outliers[~behind_any[outliers]], np.flatnonzero(left))
            plant = per_class.get(int(Label.PLANT))
            crown_min = plant.choice.min_size if plant and plant.choice else cfg.min_cluster_points
            strays_rejoined = rejoin_strays(
                cloud.points, strays, network, labels_iii, clusters_iii, r1, up=planes.up,
                crown_min=crown_min,
            )  # fmt: skip
            regrown = np.union1d(regrown, strays_rejoined)  # shown with the regrown points
        if cfg.beyond_feet and planes.up is not None:  # a screen ends at its foot (footing.py)
            lap("regrowth")  # the growth so far; the floor band's after it counts there too
            off_feet = beyond_feet(cloud.points, labels_iii, clusters_iii, regrown, planes.up)
            back = off_feet  # to what they were before regrowth: unlabelled
            labels_iii[back], clusters_iii[back] = labels_ii[back], clusters_ii[back]
            regrown = np.setdiff1d(regrown, off_feet)
            lap("beyond_feet")
        left = objects[low & (labels_iii[objects] == 0)]  # no object took them: floor again
        labels_iii[left], clusters_iii[left] = labels_ii[left], clusters_ii[left]
        floor_band = objects[low & np.isin(labels_iii[objects], OBJECT_LABELS)]
    lap("regrowth")
    raised, sunk, legs = np.zeros(0, np.intp), 0, np.zeros(0, np.intp)
    standing = None  # points above tables' tops: what stands on them (raised.py, seams.py)
    tops = [(p.model, p.top) for p in planes.planes if p.top is not None]
    if cfg.raised_vote and planes.up is not None:
        lifted = raised_off_tables(cloud.points, labels_iii, clusters_iii, tops, planes.up)
        labels_iii, clusters_iii, raised = lifted.labels, lifted.clusters, lifted.relabelled
        sunk, standing = lifted.sunk, lifted.above
        lap("raised")
    floor = main_floor(planes.planes)
    if cfg.table_legs and planes.up is not None:
        labels_iii, clusters_iii, legs = legs_under_tables(
            cloud.points, labels_iii, clusters_iii, tops, None if floor is None else floor.model,
            planes.up, network,
        )  # fmt: skip
        lap("legs")
    floor_model = None if floor is None else floor.model

    def by_floor(rules: tuple[tuple[str, FloorRule, bool], ...]) -> dict[str, Indices]:
        """Run each rule that is on with the floor plane; return the points each moved."""
        nonlocal labels_iii, clusters_iii
        moved = {}
        for step, rule, on in rules:
            moved[step] = np.zeros(0, np.intp)
            if on and planes.up is not None:
                labels_iii, clusters_iii, moved[step] = rule(
                    cloud.points, labels_iii, clusters_iii, floor_model, planes.up
                )
                lap(step)
        return moved

    # votes by a cloud's floor plane: objects flat on it (flat.py), seats called table (legs.py;
    # after flat: a table sheet in the floor's band by a chair's feet is floor, not its seat),
    # chairs lower than a seat (low.py)
    floor_votes = by_floor(
        (
            ("flat", flat_on_floor, cfg.flat_floor),
            ("seats", seats_called_table, cfg.chair_seats),
            ("low_chairs", low_chairs, cfg.low_chairs),
        )
    )
    on_walls = np.zeros(0, np.intp)
    if cfg.flat_walls and planes.up is not None:
        labels_iii, clusters_iii, on_walls = flat_on_walls(
            cloud.points, labels_iii, clusters_iii, wall_bands(cloud.points, planes.planes, cfg),
            None if floor is None else floor.model, planes.up,
        )  # fmt: skip
        lap("flat_walls")
    on_tops = np.zeros(0, np.intp)
    if cfg.table_tops:
        labels_iii, clusters_iii, on_tops = tops_called_seats(
            cloud.points, labels_iii, clusters_iii, [top for _, top in tops]
        )
        lap("tops")
    top_filled = np.zeros(0, np.intp)
    if cfg.fill_tops and growable is not None:
        labels_iii, clusters_iii, top_filled = left_on_tops(
            labels_iii, clusters_iii, [top for _, top in tops], cloud.labels, growable
        )
        regrown = np.union1d(regrown, top_filled)  # shown with the regrown points
        lap("fill_tops")
    seams = np.zeros(0, np.intp)
    neighbours = None
    if cfg.seam_vote_m > 0:
        vote = seam_vote(
            cloud.points, labels_iii, clusters_iii, seam_m=cfg.seam_vote_m,
            angle_deg=cfg.seam_angle_deg, flatness=cfg.seam_flatness, max_points=cfg.max_cells,
            standing=standing, up=planes.up,
        )  # fmt: skip
        labels_iii, seams, neighbours = vote.labels, vote.relabelled, vote.neighbours
        lap("seams")
    pieces = np.zeros(0, np.intp)
    if cfg.piece_vote:
        held = piece_vote(
            cloud.points, labels_iii, clusters_iii, max_points=cfg.max_cells,
            neighbours=neighbours,
        )  # fmt: skip
        labels_iii, pieces = held.labels, held.relabelled
        lap("pieces")
    # after the votes, a whole object's class by its size and shape: sofas.py, low.py, screens.py
    after = by_floor(
        (
            ("narrow_sofas", narrow_sofas, cfg.narrow_sofas),
            ("tall_chairs", tall_chairs, cfg.tall_chairs),
            ("screens", flat_screens, cfg.screens),
        )
    )
    noise = np.zeros(0, np.intp)
    if cfg.structure_noise_m > 0:  # the network's floor, wall, ceiling near their planes
        noise = network_surfaces(
            cloud.points, labels_iii, network, planes.planes, cfg.structure_noise_m
        )
        labels_iii[noise] = network[noise]
        lap("structure_noise")
    seconds["total"] = time.perf_counter() - start
    logger.info("refined %d points in %.2f s: %s", len(cloud), seconds["total"], seconds)
    return RefineResult(
        cloud, planes, outliers, cfg.dbscan_method, per_class, shared,
        labels_ii, clusters_ii, labels_iii, clusters_iii, regrown, r2_m=r2, seconds=seconds,
        adopted=adopted, above_tables=above, rejoined=rejoined, tabletop=tabletop,
        behind_walls=n_behind, seams=seams, bare_faces=n_faces, faces_filled=filled,
        pieces=pieces, orphans=orphans, raised=raised, sunk=sunk, strays=strays_rejoined,
        enclosed=enclosed, opened=inside, legs=legs, floor_band=floor_band, lone=lone,
        seats=floor_votes["seats"], tops=on_tops, flat=floor_votes["flat"], flat_walls=on_walls,
        low_chairs=floor_votes["low_chairs"], top_filled=top_filled,
        narrow_sofas=after["narrow_sofas"], tall_chairs=after["tall_chairs"],
        screens=after["screens"], beyond_feet=off_feet, structure_noise=noise,
    )  # fmt: skip


def _correct(
    points: npt.NDArray[np.float32], labels: npt.NDArray[np.uint8], cfg: RefineConfig
) -> tuple[
    npt.NDArray[np.uint8], npt.NDArray[np.int32], dict[int, ClassClustering], ClassClustering | None
]:
    """Cluster each class; keep clusters of at least min_cluster_points, set the rest to 0."""
    out_labels = np.zeros(len(points), np.uint8)
    out_clusters = np.zeros(len(points), np.int32)
    shared = _shared_estimate(points, labels, cfg) if cfg.dbscan_method == 1 else None
    per_class: dict[int, ClassClustering] = {}
    next_id = 1
    sparse_ids: list[int] = []
    classes = [int(c) for c in np.unique(labels) if c > 0]
    members_of = {label: np.flatnonzero(labels == label) for label in classes}
    cells_of = {
        label: capped_cells(points[members], cfg.cluster_voxel_m, cfg.max_cells)
        for label, members in members_of.items()
    }
    for label, (_, _, voxel_m) in cells_of.items():
        if voxel_m != cfg.cluster_voxel_m:
            n = len(members_of[label])
            logger.info("class %d: %d points, DBSCAN on %.3f m voxels", label, n, voxel_m)
    # the classes are independent and most of a class's DBSCAN runs in NumPy, SciPy and the
    # KD-tree with the GIL released: two classes at a time on two cores took the 332k office's
    # step from 2.0-2.2 s to 1.2-1.5 s. Results do not depend on the order (each class alone).
    largest_first = sorted(classes, key=lambda c: -len(cells_of[c][0]))
    with ThreadPoolExecutor(max_workers=_workers(len(classes))) as pool:
        done = dict(
            zip(
                largest_first,
                pool.map(lambda c: _cluster_class(c, cells_of[c][0], cfg, shared), largest_first),
                strict=True,
            )
        )
    for label in classes:
        members = members_of[label]
        cells, cell_of, _ = cells_of[label]
        entry, cluster_of, dense = done[label]
        sizes = np.bincount(cluster_of[cluster_of >= 0], minlength=1)
        min_size = cfg.min_cluster_points if entry.choice is None else entry.choice.min_size
        keep = sizes >= min_size
        if cfg.attach_small_clusters:
            keep |= attached_clusters(cells, cluster_of, keep, cfg.object_gap_m)
        big = np.flatnonzero(keep)
        new_id = np.zeros(len(sizes) + 1, np.int32)  # index 0 takes noise (-1)
        new_id[big + 1] = np.arange(next_id, next_id + len(big))
        ids = new_id[cluster_of + 1][cell_of]  # each point takes its cell's cluster
        out_clusters[members] = ids
        out_labels[members[ids > 0]] = label
        is_dense = np.bincount(cluster_of[dense & (cluster_of >= 0)], minlength=len(sizes)) > 0
        sparse_ids.extend(int(new_id[c + 1]) for c in big if not is_dense[c])
        next_id += len(big)
        per_class[label] = replace(
            entry, points=len(members), clusters=len(big), relabelled=int((ids == 0).sum())
        )
    if cfg.sparse_clusters_yield and sparse_ids:
        drop = sparse_inside_others(points, out_labels, out_clusters, np.array(sparse_ids))
        gone = np.isin(out_clusters, drop)
        out_labels[gone], out_clusters[gone] = 0, 0
    return out_labels, out_clusters, per_class, shared


def _workers(tasks: int) -> int:
    """Return how many classes to cluster at once: one per core this process may use."""
    try:
        cores = len(os.sched_getaffinity(0))  # the cores this process is allowed (containers)
    except AttributeError:  # macOS, Windows
        cores = os.cpu_count() or 1
    return max(1, min(tasks, cores))


def _sor(points: npt.NDArray[np.float32], cfg: RefineConfig) -> npt.NDArray[np.bool_]:
    """Return SOR's keep mask: on the points, or on voxel centroids past cfg.max_cells points.

    Past `max_cells` points, SOR runs on the centroids of the finest voxels (from a third of
    the clustering voxel up) that number at most `max_cells`: a stray point is alone in its
    voxel and far from the others, as before, and every point takes its voxel's verdict.
    """
    n, ratio = cfg.sor_nb_neighbors, cfg.sor_std_ratio
    if len(points) <= cfg.max_cells:
        return sor_inliers(points, nb_neighbors=n, std_ratio=ratio)
    cells, cell_of, voxel_m = capped_cells(points, cfg.cluster_voxel_m / 3, cfg.max_cells)
    logger.info(
        "SOR on %d centroids of %.3f m voxels (%d points)", len(cells), voxel_m, len(points)
    )
    keep: npt.NDArray[np.bool_] = sor_inliers(cells, nb_neighbors=n, std_ratio=ratio)[cell_of]
    return keep


def _cluster_class(
    label: int, points: npt.NDArray[np.float32], cfg: RefineConfig, shared: ClassClustering | None
) -> tuple[ClassClustering, npt.NDArray[np.int64], npt.NDArray[np.bool_]]:
    """Return one class's clustering entry, DBSCAN labels (all -1: too small), dense cells.

    Dense: core at the paper's MinPts (the mean count) too, at the chosen eps.
    """
    entry = ClassClustering(label, len(points), None, None, 0, 0, 0.0, 0.0)
    noise = np.full(len(points), -1, np.int64)
    dense = np.ones(len(points), bool)
    if len(points) < max(cfg.min_cluster_points, 2):
        return entry, noise, dense  # no cluster of this class can reach the size threshold
    t0 = time.perf_counter()
    if shared is None:
        table, curves, choice = estimate_parameters(points, **_rule(cfg))
        t1 = time.perf_counter()
        cluster_of = table.labels(choice.k - 1, choice.min_pts)
        dense = table.counts[choice.k - 1] >= table.min_pts("mean")[choice.k - 1]
        seconds = time.perf_counter() - t1
        return (
            replace(
                entry, curves=curves, choice=choice, seconds_params=t1 - t0, seconds_cluster=seconds
            ),
            cluster_of,
            dense,
        )
    if shared.choice is None:
        return entry, noise, dense
    choice = shared.choice
    cluster_of = dbscan(
        points, eps_m=choice.eps_m, min_pts=choice.min_pts, k_query=query_size(cfg.k_max)
    )
    return (
        replace(entry, choice=choice, seconds_cluster=time.perf_counter() - t0),
        cluster_of,
        dense,
    )


def _shared_estimate(
    points: npt.NDArray[np.float32], labels: npt.NDArray[np.uint8], cfg: RefineConfig
) -> ClassClustering:
    """Return method 1's single (eps, MinPts), estimated over every labelled object point."""
    labelled = capped_cells(points[labels > 0], cfg.cluster_voxel_m, cfg.max_cells)[0]
    t0 = time.perf_counter()
    if len(labelled) < 2:
        return ClassClustering(0, len(labelled), None, None, 0, 0, 0.0, 0.0)
    _, curves, choice = estimate_parameters(labelled, **_rule(cfg))
    return ClassClustering(0, len(labelled), curves, choice, 0, 0, time.perf_counter() - t0, 0.0)


def _rule(cfg: RefineConfig) -> dict[str, Any]:
    """Return estimate_parameters' keyword arguments from the configuration."""
    return {
        "k_max": cfg.k_max,
        "full_curves": cfg.full_curves,
        "rule": cfg.dbscan_rule,
        "min_size": cfg.min_cluster_points,
        "min_area_m2": cfg.min_cluster_area_m2,
        "tolerance": cfg.plateau_tolerance,
        "max_eps_m": cfg.max_eps_m,
        "min_pts_statistic": cfg.min_pts_statistic,
    }
