"""What the refinement shows of each step: one call per step to a logger the pipeline passes in.

The logger is the pipeline's `viz.logger.Logger`. Stage numbers are ARCHITECTURE.md's `stage`
timeline (viz.layout).
"""

from __future__ import annotations

import numpy as np

from capture.recording import LABEL_NAMES
from process.refine.steps import ClassClustering, RefineResult
from viz.layout import STAGE_DBSCAN, STAGE_FINAL, STAGE_PLANES, STAGE_REGROWTH, STAGE_SOR
from viz.logger import DbscanCurves, Logger


def log_steps(result: RefineResult, viz: Logger) -> None:
    """Log planes, SOR outliers, DBSCAN clusters and curves, regrown points and the final map."""
    viz.set_stage(STAGE_PLANES)
    planes = result.plane_cloud()
    viz.log_refine("planes", planes.points, labels=planes.labels)
    for plane in result.planes.planes:
        name = LABEL_NAMES[plane.label] if plane.label else "not structural"
        text = f"plane {name}: {len(plane.indices)} inliers, {len(plane.removed)} removed"
        viz.log_text(f"{text}; {plane.note}" if plane.note else text)
    viz.set_stage(STAGE_SOR)
    outliers = result.outlier_cloud()
    viz.log_refine("outliers", outliers.points, labels=outliers.labels)
    viz.set_stage(STAGE_DBSCAN)
    clusters = result.cluster_cloud()
    viz.log_refine("clusters", clusters.points, labels=clusters.labels, clusters=clusters.clusters)
    entries = list(result.dbscan.values())
    if result.shared is not None:
        entries.insert(0, result.shared)
    for entry in entries:
        _log_curves(entry, viz)
    viz.set_stage(STAGE_REGROWTH)
    regrown = result.regrown_cloud()
    viz.log_refine("regrown", regrown.points, labels=regrown.labels, clusters=regrown.clusters)
    seams = result.seam_cloud()
    viz.log_refine("seams", seams.points, labels=seams.labels, clusters=seams.clusters)
    viz.set_stage(STAGE_FINAL)
    final = result.final()
    viz.log_map("refined", final.points, colors=final.colors, labels=final.labels)
    for step, seconds in result.seconds.items():
        viz.log_timing(f"refine_{step}", seconds)


def _log_curves(entry: ClassClustering, viz: Logger) -> None:
    """Log one class's eps / MinPts / cluster-count curves over the K that DBSCAN ran for."""
    name = LABEL_NAMES[entry.label] if entry.label else "all classes"
    if entry.curves is None or entry.choice is None:
        if entry.label and entry.choice is None:
            viz.log_text(f"adaptive DBSCAN {name}: {entry.points} points, too few for a cluster")
        return
    # the count the rule chose from: all clusters (literal) or those above the size (plateau)
    counts = entry.curves.n_clusters
    if entry.choice.rule == "plateau" and entry.curves.n_big is not None:
        counts = entry.curves.n_big
    ran = counts >= 0
    curves = DbscanCurves(
        ks=entry.curves.ks[ran],
        eps_m=entry.curves.eps_m[ran],
        min_pts=entry.curves.min_pts[ran].astype(np.float64),
        n_clusters=counts[ran],
        chosen_k=entry.choice.k,
    )
    viz.log_dbscan_curves(name, curves=curves)
    level = "INFO" if entry.choice.stable else "WARN"
    choice = entry.choice
    viz.log_text(
        f"adaptive DBSCAN {name}: K={choice.k} eps={choice.eps_m:.3f} m MinPts={choice.min_pts}"
        f" ({choice.rule}) {choice.note}",
        level=level,
    )
