"""The whole refinement and the `refine` command's job, on our synthetic office."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest
from helpers_refine import RecordingLogger, grid_patch, labelled

from benchmarks.synthetic_office import SyntheticScene, indoor_scene
from process.cloud import ply_bytes, read_cloud, write_ply
from process.errors import CloudError, ConfigError, StageError
from process.evaluate import label_metrics
from process.refine import RefineConfig, refine
from process.refine.job import refine_and_log, refine_file

UP = np.array([0.0, 0.0, 1.0])


@pytest.fixture(scope="module")
def office() -> SyntheticScene:
    return indoor_scene(seed=1, spacing_m=0.03)  # ~95k points


def test_classes_clustered_side_by_side_give_what_one_at_a_time_gives(
    office: SyntheticScene, monkeypatch: pytest.MonkeyPatch
) -> None:
    import process.refine.steps as steps

    assert steps._workers(5) == min(5, len(os.sched_getaffinity(0)))
    monkeypatch.setattr(steps, "_workers", lambda tasks: min(tasks, 3))  # on any machine
    both = refine(office.cloud, RefineConfig(), up=UP)
    monkeypatch.setattr(steps, "_workers", lambda tasks: 1)
    alone = refine(office.cloud, RefineConfig(), up=UP)
    np.testing.assert_array_equal(both.labels_ii, alone.labels_ii)
    np.testing.assert_array_equal(both.clusters_ii, alone.clusters_ii)
    np.testing.assert_array_equal(both.labels_iii, alone.labels_iii)
    assert {c: e.choice for c, e in both.dbscan.items()} == {
        c: e.choice for c, e in alone.dbscan.items()
    }


def test_f1_over_target_classes_rises_from_phase_i_to_iii(office: SyntheticScene) -> None:
    result = refine(office.cloud, RefineConfig(), up=UP)
    f1 = {
        p: label_metrics(c.labels, office.truth)["all"]["f1"]
        for p, c in result.phase_clouds().items()
    }
    assert result.phase_f1(office.truth) == f1  # the benchmarks' shorthand says the same
    assert f1["I"] < 0.8  # the generator's label-transfer errors
    assert f1["III"] > 0.9 and f1["III"] > f1["I"] + 0.1
    assert {p.label for p in result.planes.planes} >= {2, 3}
    steps = {"planes", "sor", "dbscan", "regrowth", "raised", "legs", "seats", "tops", "seams"}
    steps |= {"flat", "flat_walls", "pieces", "low_chairs", "fill_tops", "narrow_sofas"}
    steps |= {"tall_chairs", "screens", "beyond_feet", "structure_noise"}
    assert set(result.seconds) == steps | {"total"}
    for entry in result.dbscan.values():
        assert entry.choice is not None and entry.curves is not None
        assert entry.curves.eps_m[entry.choice.k - 1] == entry.choice.eps_m


def test_capped_cells_carry_sor_and_dbscan_back_to_every_point(office: SyntheticScene) -> None:
    direct = refine(office.cloud, RefineConfig(), up=UP)
    capped = refine(office.cloud, RefineConfig(max_cells=5000), up=UP)  # coarser voxels
    assert len(capped.labels_iii) == len(office.cloud)
    f1 = {
        name: label_metrics(r.labels_iii, office.truth)["all"]["f1"]
        for name, r in (("direct", direct), ("capped", capped))
    }
    assert f1["capped"] > f1["direct"] - 0.1
    agree = float(np.mean(capped.labels_iii == direct.labels_iii))
    assert agree > 0.8


def test_method_1_shares_one_estimate_over_all_classes(office: SyntheticScene) -> None:
    result = refine(office.cloud, RefineConfig(dbscan_method=1), up=UP)
    assert result.shared is not None and result.shared.choice is not None
    assert {e.choice for e in result.dbscan.values()} == {result.shared.choice}
    f1 = {
        p: label_metrics(c.labels, office.truth)["all"]["f1"]
        for p, c in result.phase_clouds().items()
    }
    assert f1["III"] > f1["I"]


def test_refine_file_writes_every_surviving_point_and_the_metrics(
    office: SyntheticScene, tmp_path: Path
) -> None:
    write_ply(tmp_path / "fused.ply", office.cloud)
    write_ply(tmp_path / "truth.ply", office.gt_cloud)
    cfg = RefineConfig(up=(0.0, 0.0, 1.0))
    section = refine_file(
        tmp_path / "fused.ply", out_dir=tmp_path / "out", cfg=cfg, gt_cloud=tmp_path / "truth.ply"
    )
    written = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert written["refinement"] == section and written["seconds"]["refinement"] > 0
    assert set(section["phases"]) == {"I", "II", "III"}
    assert section["phases"]["III"]["all"]["f1"] > section["phases"]["I"]["all"]["f1"]
    assert {"k", "eps_m", "min_pts"} <= set(section["dbscan"]["chair"])
    refined = read_cloud(tmp_path / "out" / "map_refined.ply")
    assert refined.clusters is not None
    points = section["points"]
    assert (  # SOR's outliers are left out, but those that rejoined a plant (outliers.py)
        len(refined)
        == points["final"]
        == len(office.cloud) - points["sor_outliers"] + points["strays_rejoined_from_sor"]
    )
    kept = np.isin(office.cloud.points.view("V12").ravel(), refined.points.view("V12").ravel())
    assert kept.sum() == len(refined)  # at their input positions
    assert set(np.unique(refined.labels[refined.clusters > 0])) <= set(range(4, 11))


def test_a_cloud_file_without_labels_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "plain.pcd"
    path.write_text(
        "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1\n"
        "HEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 1\nDATA ascii\n0 0 0\n"
    )
    with pytest.raises(CloudError, match="expected a 'label' field per point, found fields x y z"):
        refine_file(path, out_dir=tmp_path / "out", cfg=RefineConfig())
    assert not (tmp_path / "out").exists()


@pytest.mark.filterwarnings("error")  # clean: no NumPy warning either (an empty mean)
@pytest.mark.parametrize("up", [UP, None])
@pytest.mark.parametrize("n", [0, 3])
def test_tiny_clouds_are_clean_no_ops(n: int, up: npt.NDArray[np.float64] | None) -> None:
    cloud = labelled(np.arange(3 * n, dtype=np.float32).reshape(n, 3), 5)
    result = refine(cloud, RefineConfig(), up=up)
    assert len(result.final()) == n
    assert (result.labels_iii == 0).all()  # 3 points cannot make a cluster of 100
    assert all(e.choice is None for e in result.dbscan.values())


def test_an_unlabelled_cloud_keeps_its_planes_and_clusters_nothing() -> None:
    floor = grid_patch((0.0, 3.0), (0.0, 3.0), step=0.02)
    wall = grid_patch((0.0, 3.0), (0.04, 2.5), step=0.02)[:, [0, 2, 1]]  # a floor needs a room
    wall[:, 1] = 3.0
    box = grid_patch((1.0, 1.5), (1.0, 1.5), z=0.5)
    points = np.concatenate([floor, wall, box])
    result = refine(labelled(points, 0), RefineConfig(), up=UP)
    assert (result.labels_iii[: len(floor)] == 2).all()
    assert (result.labels_iii[len(floor) : -len(box)] == 3).all()
    assert (result.labels_iii[-len(box) :] == 0).all()
    assert result.dbscan == {}


def test_a_class_too_small_for_a_cluster_is_relabelled_zero_and_reported() -> None:
    chair = grid_patch((0.0, 0.6), (0.0, 0.6), z=0.45)
    labels = np.full(len(chair), 5, np.uint8)
    speck = np.flatnonzero(np.linalg.norm(chair[:, :2] - 0.3, axis=1) < 0.025)  # 5 points
    labels[speck] = 7  # "plant" on the chair
    result = refine(labelled(chair, labels), RefineConfig(), up=UP)
    assert result.dbscan[7].choice is None and result.dbscan[7].relabelled == len(speck) == 5
    assert (result.labels_ii[speck] == 0).all()
    assert (result.labels_iii[speck] == 5).all()  # regrown into the chair around them
    chair_id = np.bincount(result.clusters_ii[result.clusters_ii > 0]).argmax()
    assert (result.clusters_iii[speck] == chair_id).all()  # and into its cluster


def test_refine_and_log_logs_every_step_in_stage_order(office: SyntheticScene) -> None:
    viz = RecordingLogger()
    truth = ply_bytes(office.gt_cloud)
    refined, section = refine_and_log(
        office.cloud, RefineConfig(), viz=viz, up=UP, gt_cloud_ply=truth
    )
    assert [c[1] for c in viz.calls if c[0] == "set_stage"] == [1, 2, 3, 4, 5]
    kinds = [c[1] for c in viz.calls if c[0] == "log_refine"]
    assert kinds == ["planes", "outliers", "clusters", "regrown", "seams"]
    curves = [c for c in viz.calls if c[0] == "log_dbscan_curves"]
    assert {c[1] for c in curves} == {e for e in section["dbscan"]}
    for _, _, kwargs in curves:
        drawn = kwargs["curves"]
        assert drawn.chosen_k in drawn.ks
        assert len(drawn.ks) == len(drawn.eps_m) == len(drawn.n_clusters)
    assert ("log_map", "refined") in [c[:2] for c in viz.calls]
    assert len(refined) == section["points"]["final"]
    assert section["phases"]["III"]["all"]["f1"] > 0.9


def test_labels_outside_the_recording_table_are_refused() -> None:
    with pytest.raises(StageError, match=r"label ids 0\.\.10, found 20"):
        refine(labelled(grid_patch((0.0, 0.2), (0.0, 0.2)), 20), RefineConfig())


def test_a_gravity_up_that_is_not_finite_is_refused() -> None:
    cloud = labelled(grid_patch((0.0, 0.2), (0.0, 0.2)), 4)
    with pytest.raises(StageError, match="finite gravity-up"):
        refine(cloud, RefineConfig(), up=np.array([np.nan, 0.0, 1.0]))


@pytest.mark.parametrize(
    "field",
    [
        {"dbscan_method": 3},
        {"k_max": 2},
        {"plane_distance_m": 0.0},
        {"plane_sample_points": 2},
        {"up": (0.0, 0.0, 0.0)},
        {"up": (float("nan"), 0.0, 1.0)},
        {"up": (0.0, float("inf"), 1.0)},
    ],
)
def test_bad_refine_config_values_are_refused(field: dict[str, object]) -> None:
    with pytest.raises(ConfigError, match="refinement"):
        RefineConfig(**field)  # type: ignore[arg-type]
