"""What a refinement reaches that gives every object the class most of its points carry.

A network that confuses an object in most views (generator 5's `confusion_share`) leaves it with
the wrong class on most of its points after fusion, and no step of the paper's method overrules a
majority. Here every true object (the connected points of one true class, `LINK_M` apart) takes
its phase-I majority object label (points the network left unlabelled or gave structure do not
vote; an object with no object label keeps its labels), and every point that is no object loses
any object label (the best a refinement can do there). The pooled F1 of that labelling is what a
refinement that gives each object one class, its network majority, reaches at best; objects of
one class that touch count as one, so a refinement that splits them can score above it
(`python -m benchmarks.refine_suite --ceiling`).

Written here because it needs the ground truth, which no library step has.
"""

from __future__ import annotations

from typing import Final

import numpy as np
import numpy.typing as npt

from capture.recording import OBJECT_LABELS
from process.evaluate import label_metrics
from process.refine.graph import radius_components

LINK_M: Final = 0.035  # points of one true class this near are one object (voxels up to 3 cm)


def majority_ceiling(
    points: npt.NDArray[np.floating],
    labels: npt.NDArray[np.uint8],
    truth: npt.NDArray[np.uint8],
    link_m: float = LINK_M,
) -> float:
    """Return the pooled object F1 when every true object takes its majority phase-I label."""
    out = np.where(np.isin(truth, OBJECT_LABELS), labels, truth).astype(np.uint8)
    for cls in np.intersect1d(truth, OBJECT_LABELS):
        own = np.flatnonzero(truth == cls)
        piece = radius_components(np.asarray(points[own], np.float64), link_m)
        order = np.argsort(piece, kind="stable")
        for members in np.split(own[order], np.cumsum(np.bincount(piece))[:-1]):
            voted = labels[members]
            voted = voted[np.isin(voted, OBJECT_LABELS)]
            if len(voted):
                out[members] = np.bincount(voted).argmax()
    return float(label_metrics(out, truth)["all"]["f1"])
