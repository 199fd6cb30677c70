"""The network's floor, wall and ceiling just off a structural plane keep their label."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from helpers_refine import UP, grid_patch, labelled

from capture.recording import Label
from process.refine import RefineConfig, refine
from process.refine.job import refinement_metrics
from process.refine.surface_noise import network_surfaces

FLOOR, WALL, CHAIR = Label.FLOOR, Label.WALL, Label.CHAIR
Points = npt.NDArray[np.float32]


def _scene() -> tuple[Points, npt.NDArray[np.uint8], dict[str, npt.NDArray[np.intp]]]:
    """A 4 x 4 m floor and a 2.5 m wall at x = 4 (2 cm grids), and beside them sparse layers the
    way a fused map's thick surfaces leave them (6 cm grids): the network's floor 2.5 cm under
    the floor and 2.5 cm over it, its wall 2.5 cm before the wall; its floor 4 cm under the floor
    (past a 3 cm band) and 2.5 cm under it 1 m beyond the floor's edge (past its extent); its
    wall 2.5 cm under the floor (no wall there); a chair's seat the network labels chair; three
    points of its floor 2.5 cm off the floor in the floor's far corners.
    Returns points, labels and each part's rows by name."""
    parts: dict[str, npt.NDArray[np.floating]] = {
        "floor": grid_patch((0.0, 4.0), (0.0, 4.0), step=0.02),
        "wall": grid_patch((0.0, 4.0), (0.0, 2.5), step=0.02)[:, [2, 0, 1]] + [4.0, 0.0, 0.0],
        "under": grid_patch((0.5, 1.5), (0.5, 1.5), z=-0.025, step=0.06),
        "over": grid_patch((2.0, 3.0), (0.5, 1.5), z=0.025, step=0.06),
        "before": grid_patch((0.5, 1.5), (0.5, 1.5), step=0.06)[:, [2, 0, 1]] + [3.975, 0, 0],
        "deep": grid_patch((0.5, 1.5), (2.5, 3.5), z=-0.04, step=0.06),
        "beyond": grid_patch((-1.5, -1.0), (0.5, 1.5), z=-0.025, step=0.06),
        "walls_word": grid_patch((2.0, 3.0), (2.5, 3.5), z=-0.025, step=0.06),
        "seat": grid_patch((1.0, 1.45), (2.0, 2.45), z=0.45, step=0.02),
        "strays": np.array([(0.1, 3.9, -0.025), (3.9, 3.9, 0.025), (3.9, 0.1, -0.025)], np.float32),
    }
    said = {"before": WALL, "walls_word": WALL, "wall": WALL, "seat": CHAIR}
    points = np.concatenate(list(parts.values())).astype(np.float32)
    sizes = [len(p) for p in parts.values()]
    labels = np.repeat(np.array([said.get(k, FLOOR) for k in parts], np.uint8), sizes)
    ends = np.cumsum([0, *sizes])
    rows = {k: np.arange(ends[i], ends[i + 1]) for i, k in enumerate(parts)}
    noise = np.random.default_rng(0).normal(0.0, 0.002, points.shape).astype(np.float32)
    return points + noise, labels, rows


def test_the_networks_structure_near_its_plane_takes_its_label_and_nothing_else() -> None:
    """With every point off the planes left unlabelled: over the floor, under it and before the
    wall within 3 cm, inside the planes' extents, the network's label stands; 4 cm under, 1 m
    beyond the floor's edge, and wall said by the floor stay unlabelled. A point phase III
    labelled is left as it is; a band of 0 takes nothing, a 5 cm band the deep layer too."""
    points, labels, rows = _scene()
    result = refine(labelled(points, labels), RefineConfig(structure_noise_m=0.0), up=UP)
    structural = result.planes.structural
    assert structural[rows["floor"]].mean() > 0.99 and structural[rows["wall"]].mean() > 0.99
    layers = np.concatenate([rows[k] for k in ("over", "before", "deep", "beyond")])
    assert not structural[layers].any()  # past RANSAC's 2 cm band (some of "under" is not)
    left = np.where(structural, result.planes.labels, 0).astype(np.uint8)
    planes = result.planes.planes
    taken = network_surfaces(points, left, labels, planes, 0.03)
    near = np.concatenate([rows[k] for k in ("floor", "wall", "under", "over", "before", "strays")])
    assert np.isin(taken, near[~structural[near]]).all()  # floor and wall RANSAC left too
    layered = np.concatenate([rows[k] for k in ("under", "over", "before", "strays")])
    assert np.isin(layered[~structural[layered]], taken).mean() > 0.99  # noise: 2.5 +- 0.6 cm
    assert len(network_surfaces(points, left, labels, planes, 0.0)) == 0
    wider = network_surfaces(points, left, labels, planes, 0.05)
    assert np.isin(taken, wider).all() and np.isin(rows["deep"], wider).all()
    assert not np.isin(np.concatenate([rows["beyond"], rows["walls_word"]]), wider).any()
    marked = left.copy()
    marked[rows["over"]] = CHAIR  # a label phase III gave stays
    assert not np.isin(rows["over"], network_surfaces(points, marked, labels, planes, 0.03)).any()


def test_the_refinement_keeps_the_networks_surface_noise_counted_and_switched_off() -> None:
    """The whole refinement, the layers scattered thin (10 % of their points): what the
    refinement without the rule (as in `paper()`) leaves unlabelled of them (DBSCAN's noise,
    SOR's outliers) the rule gives the network's floor and wall (SOR's outliers among them
    survive into the final map), within the band only; counted in metrics.json."""
    points, labels, rows = _scene()
    thin = np.random.default_rng(1).random(len(points)) < 0.1
    layers = ("under", "over", "before", "deep", "beyond", "walls_word")
    drop = np.concatenate([rows[k][~thin[rows[k]]] for k in layers])
    keep = np.setdiff1d(np.arange(len(points)), drop)
    points, labels = points[keep], labels[keep]
    rows = {k: np.flatnonzero(np.isin(keep, v)) for k, v in rows.items()}
    cloud = labelled(points, labels)
    off = refine(cloud, RefineConfig(structure_noise_m=0.0), up=UP)
    near = np.concatenate([rows[k] for k in ("floor", "wall", "under", "over", "before", "strays")])
    left = np.sort(near[(off.labels_iii[near] == 0)])  # the planes' own give-backs too
    assert np.isin(rows["strays"], left).all() and len(np.setdiff1d(left, rows["floor"])) > 20
    assert len(np.intersect1d(left, off.sor_outliers)) > 0
    assert not off.kept[np.intersect1d(left, off.sor_outliers)].any()
    result = refine(cloud, RefineConfig(), up=UP)
    assert np.array_equal(result.structure_noise, left)
    assert (result.labels_iii[left] == labels[left]).all() and result.kept[left].all()
    away = np.concatenate([rows[k] for k in ("deep", "beyond", "walls_word")])
    assert np.array_equal(result.labels_iii[away], off.labels_iii[away])
    unchanged = np.setdiff1d(np.arange(len(points)), left)
    assert np.array_equal(result.labels_iii[unchanged], off.labels_iii[unchanged])
    section = refinement_metrics(result, gt_cloud=None)["points"]
    assert section["structure_noise"] == len(left)
    assert section["structure_noise_from_sor"] == len(np.intersect1d(left, result.sor_outliers))
    assert RefineConfig.paper().structure_noise_m == 0.0
