"""The paper's refinement of a fused labelled cloud: planes, SOR, adaptive DBSCAN, regrowth."""

from __future__ import annotations

from process.refine.config import RefineConfig
from process.refine.dbscan import DbscanChoice, KannCurves
from process.refine.planes import Plane, PlaneSegmentation
from process.refine.steps import ClassClustering, RefineResult, refine

__all__ = [
    "ClassClustering",
    "DbscanChoice",
    "KannCurves",
    "Plane",
    "PlaneSegmentation",
    "RefineConfig",
    "RefineResult",
    "refine",
]
