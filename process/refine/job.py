"""The `refine` command's job: a labelled cloud file in, `map_refined.ply` and metrics out."""

from __future__ import annotations

import logging
import math
import time
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from capture.recording import GT_CLOUD_ATTACHMENT, LABEL_NAMES
from process import outputs
from process.cloud import LabelledCloud, parse_ply, read_cloud, write_ply
from process.evaluate import cloud_phase_metrics
from process.refine import ClassClustering, RefineConfig, RefineResult, refine
from process.refine.steplog import log_steps
from viz.logger import Logger

logger = logging.getLogger(__name__)


def refine_file(
    cloud_path: Path,
    *,
    out_dir: Path,
    cfg: RefineConfig,
    gt_cloud: Path | None = None,
) -> dict[str, Any]:
    """Refine a labelled PLY/PCD; write map_refined.ply and metrics.json; return the section.

    metrics.json holds {"refinement": section, "seconds": {"refinement": s}}, the returned
    section being the "refinement" object of ARCHITECTURE.md.

    Raises:
        CloudError: a cloud file is missing, malformed or has no `label` field.
    """
    start = time.perf_counter()
    cloud = read_cloud(cloud_path, min_points=1)
    truth = read_cloud(gt_cloud) if gt_cloud is not None else None
    result = refine(cloud, cfg)
    out_dir.mkdir(parents=True, exist_ok=True)
    write_ply(out_dir / outputs.MAP_REFINED, result.final())
    section = refinement_metrics(result, gt_cloud=truth)
    metrics = {"refinement": section, "seconds": {"refinement": time.perf_counter() - start}}
    outputs.write_metrics(out_dir / outputs.METRICS, metrics)
    logger.info("refined %s -> %s", cloud_path, out_dir / outputs.MAP_REFINED)
    return section


def refine_and_log(
    cloud: LabelledCloud,
    cfg: RefineConfig,
    *,
    viz: Logger,
    up: npt.NDArray[np.float64] | None = None,
    gt_cloud_ply: bytes | None = None,
) -> tuple[LabelledCloud, dict[str, Any]]:
    """Refine the fused map, log every step, return the refined map and the metrics section.

    `gt_cloud_ply` is the recording's ground-truth cloud attachment (PLY bytes), if any.
    """
    truth = None
    if gt_cloud_ply is not None:
        truth = parse_ply(gt_cloud_ply, source=f"attachment {GT_CLOUD_ATTACHMENT}")
    result = refine(cloud, cfg, up=up)
    log_steps(result, viz)
    section = refinement_metrics(result, gt_cloud=truth)
    for phase, per_class in section.get("phases", {}).items():
        viz.log_metrics(f"refinement_phase_{phase}", per_class["all"])
    return result.final(), section


def refinement_metrics(
    result: RefineResult, *, gt_cloud: LabelledCloud | None, max_distance_m: float = 0.05
) -> dict[str, Any]:
    """Return the "refinement" section of metrics.json (phases only with a ground truth)."""
    section: dict[str, Any] = {}
    if gt_cloud is not None:
        section["phases"] = cloud_phase_metrics(
            result.phase_clouds(), gt_cloud, max_distance_m=max_distance_m
        )
    section["method"] = result.method
    section["dbscan"] = {LABEL_NAMES[c]: _clustering(e) for c, e in result.dbscan.items()}
    if result.shared is not None:
        section["dbscan_shared"] = _clustering(result.shared)
    up = result.planes.up
    section["up"] = None if up is None else [float(v) for v in up]
    section["up_source"] = result.planes.up_source
    section["plane_min_points"] = result.planes.min_points
    section["planes"] = [
        {
            "label": LABEL_NAMES[p.label] if p.label else "none",
            "inliers": len(p.indices),
            "removed": len(p.removed),
            "normal": [float(v) for v in p.model[:3]],
            "offset_m": float(p.model[3]),
            "height_m": None if math.isnan(p.height_m) else p.height_m,
            "network_says": LABEL_NAMES[p.network_label] if p.network_label else "none",
            "kept_as_objects": p.kept_as_objects,
            "table_points": p.table_points,
            "in_front_of_wall": p.on_wall,
            "beyond_band": p.off_band,
            "noise_taken_in": p.noise_taken,
            "behind_objects_taken_in": p.behind_taken,
            "note": p.note,
        }
        for p in result.planes.planes
    ]
    section["planes_past_max"] = [  # no structure: looked at for bare faces only (faces.py)
        {
            "inliers": len(p.indices),
            "normal": [float(v) for v in p.model[:3]],
            "offset_m": float(p.model[3]),
        }
        for p in result.planes.faces_only
    ]
    nf = result.planes.not_floor
    section["points"] = {
        "input": len(result.fused),
        "structural": int(result.planes.structural.sum()),
        "table_surfaces": int(sum(p.table_points for p in result.planes.planes)),
        "floor_labels_above_floor": 0 if nf is None else int(nf.sum()),
        "sor_outliers": len(result.sor_outliers),
        "structure_inside_objects": len(result.opened),
        "floor_band_regrown": len(result.floor_band),
        "regrown": len(result.regrown),
        "adopted_by_host": len(result.adopted),
        "held_above_tables": result.above_tables,
        "rejoined_own_class": result.rejoined,
        "tabletop_objects": len(result.tabletop),
        "behind_walls_left_out": result.behind_walls,
        "bare_faces_left_out": result.bare_faces,
        "faces_filled": len(result.faces_filled),
        "bare_faces_enclosed": len(result.enclosed),  # of faces_filled
        "seam_relabelled": len(result.seams),
        "piece_relabelled": len(result.pieces),
        "raised_relabelled": len(result.raised),
        "legs_relabelled": len(result.legs),
        "seats_relabelled": len(result.seats),
        "tops_relabelled": len(result.tops),
        "flat_on_floor": len(result.flat),
        "flat_on_walls": len(result.flat_walls),
        "low_chairs": len(result.low_chairs),
        "narrow_sofas": len(result.narrow_sofas),
        "tall_chairs": len(result.tall_chairs),
        "screens": len(result.screens),
        "beyond_feet": len(result.beyond_feet),
        "structure_noise": len(result.structure_noise),
        "structure_noise_from_sor": int(np.isin(result.structure_noise, result.sor_outliers).sum()),
        "tops_filled": len(result.top_filled),
        "sunk_under_tables": result.sunk,
        "orphans_adopted": len(result.orphans),
        "lone_objects": len(result.lone),
        "strays_rejoined": len(result.strays),
        "strays_rejoined_from_sor": int(np.isin(result.strays, result.sor_outliers).sum()),
        "final": int(result.kept.sum()),
    }
    section["seconds"] = dict(result.seconds)
    return section


def _clustering(entry: ClassClustering) -> dict[str, Any]:
    """Return one class's DBSCAN parameters, counts and times (the paper's Table 8 row)."""
    choice = entry.choice
    return {
        "k": None if choice is None else choice.k,
        "eps_m": None if choice is None else choice.eps_m,
        "min_pts": None if choice is None else choice.min_pts,
        "stable": None if choice is None else choice.stable,
        "rule": None if choice is None else choice.rule,
        "min_cluster_points": None if choice is None else choice.min_size,
        "note": "fewer points than min_cluster_points" if choice is None else choice.note,
        "points": entry.points,
        "clusters": entry.clusters,
        "relabelled": entry.relabelled,
        "seconds_params": entry.seconds_params,
        "seconds_cluster": entry.seconds_cluster,
    }
