"""Entity-path helpers, stage table, colours and the blueprint of viz.layout."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from rerun.chunk import RrdReader

from capture.recording import LABEL_NAMES
from viz import layout


@pytest.mark.parametrize(
    ("name", "part"),
    [
        ("tv monitor", "tv_monitor"),
        ("phase III", "phase_III"),
        ("a/b", "a_b"),
        (" ", "_"),
        ("x-1", "x-1"),
    ],
)
def test_path_part_makes_one_safe_entity_part(name: str, part: str) -> None:
    assert layout.path_part(name) == part


def test_every_label_gets_its_own_dbscan_path() -> None:
    paths = {layout.dbscan_path("eps_m", name) for name in LABEL_NAMES}
    assert len(paths) == len(LABEL_NAMES)
    assert all(p.startswith("/plots/dbscan/eps_m/") for p in paths)


def test_stage_steps_follow_the_refinement_order() -> None:
    steps = [layout.STAGE_FUSED, layout.STAGE_PLANES, layout.STAGE_SOR, layout.STAGE_DBSCAN]
    steps += [layout.STAGE_REGROWTH, layout.STAGE_FINAL]
    assert steps == list(range(6))
    assert layout.STAGE_NAMES[layout.STAGE_DBSCAN] == "DBSCAN"


def test_paths_of_the_architecture_page_are_spelled_as_it_does() -> None:
    assert layout.CAMERA == "/world/camera"
    assert {layout.RGB, layout.DEPTH, layout.SEGMENTATION, layout.KEYPOINTS} == {
        f"/world/camera/image/{n}" for n in ("rgb", "depth", "segmentation", "keypoints")
    }
    assert set(layout.TRAJECTORY_KINDS.values()) == {
        "/world/trajectory/estimated",
        "/world/trajectory/ground_truth",
    }
    assert set(layout.MAP_KINDS.values()) == {"/world/map/fused", "/world/map/refined"}
    assert set(layout.REFINE_KINDS.values()) == {
        f"/world/refine/{n}" for n in ("planes", "outliers", "clusters", "regrown", "seams")
    }
    assert layout.LOGS == "/logs"


def test_cluster_palette_gives_distinct_colours_after_the_grey_of_no_cluster() -> None:
    palette = layout.cluster_palette(64)
    assert palette.shape == (64, 3)
    assert tuple(palette[0]) == layout.NO_CLUSTER_RGB
    assert len({tuple(c) for c in palette}) == 64
    # neighbouring cluster ids must not look alike: at least 40 levels apart in some channel
    steps = np.abs(np.diff(palette[1:].astype(int), axis=0)).max(axis=1)
    assert steps.min() >= 40


def test_blueprint_saves_as_an_rbl_the_viewer_can_load(tmp_path: Path) -> None:
    rbl = tmp_path / "semreplay.rbl"
    layout.blueprint().save(layout.APPLICATION_ID, rbl)
    reader = RrdReader(rbl)
    (store,) = reader.blueprints()
    assert store.application_id == layout.APPLICATION_ID
    entities = {chunk.entity_path for chunk in reader.stream(store=store)}
    assert any(e.startswith("/view/") for e in entities)
    assert any(e.startswith("/container/") for e in entities)
