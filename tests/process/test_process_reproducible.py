"""Two runs of one recording with one config give the same outputs, bit for bit (but timings)."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import open3d as o3d
import pytest

from process import outputs
from process.config import STAGES, ReplayConfig
from process.fusion.tsdf import canonical_order
from process.job import run_recording

# what metrics.json times rather than measures (at any depth; also keys "seconds_*"): it
# varies from run to run by nature
_TIMINGS = frozenset({"seconds", "stages", "job", "fps", "load_s", "ms_per_keyframe"})


@pytest.fixture
def open3d_threads() -> Iterator[None]:
    """Let Open3D use 4 threads, as on a machine with more cores than this one may have.

    Open3D's parallel reductions and hash map vary with the scheduling only when it has
    several threads; on one core a run would be reproducible whether or not the code makes it.
    """
    before = o3d.utility.get_max_threads()
    o3d.utility.set_max_threads(4)
    yield
    o3d.utility.set_max_threads(before)


def _measured(metrics: dict[str, Any], path: str = "") -> dict[str, Any]:
    """Return the metrics without the timings, flat: {"odometry.frames": 30, ...}."""
    out: dict[str, Any] = {}
    for key, value in metrics.items():
        if key in _TIMINGS or key.startswith("seconds_"):
            continue
        if isinstance(value, dict):
            out |= _measured(value, f"{path}.{key}" if path else key)
        else:
            out[f"{path}.{key}" if path else key] = value
    return out


@pytest.mark.usefixtures("open3d_threads")
def test_two_runs_of_a_recording_give_identical_outputs(
    sim_recording: Path, tmp_path: Path
) -> None:
    runs = [tmp_path / "first", tmp_path / "second"]
    for out in runs:
        run_recording(
            sim_recording, out, cfg=ReplayConfig(), stages=STAGES, no_viz=True, progress=False
        )
    first, second = runs
    for name in (outputs.TRAJECTORY, outputs.MAP_FUSED, outputs.MAP_REFINED):
        assert (first / name).read_bytes() == (second / name).read_bytes(), name
    metrics = [json.loads((out / outputs.METRICS).read_text()) for out in runs]
    assert metrics[0]["refinement"]["points"]["final"] > 1000  # a map, not two empty ones
    first_m, second_m = (_measured(m) for m in metrics)
    differ = {k: (first_m.get(k), second_m.get(k)) for k in first_m.keys() | second_m.keys()}
    assert {k: v for k, v in differ.items() if v[0] != v[1]} == {}


def test_the_canonical_order_sorts_by_x_then_y_then_z() -> None:
    points = np.array(
        [[1.0, 0.0, 0.0], [0.0, 2.0, 1.0], [0.0, 2.0, -1.0], [0.0, -3.0, 5.0], [-1.0, 9.0, 9.0]],
        np.float32,
    )
    expected = points[[4, 3, 2, 1, 0]]
    assert np.array_equal(canonical_order(points), expected)
    shuffled = np.random.default_rng(0).permutation(points)
    assert np.array_equal(canonical_order(shuffled), expected)
    assert canonical_order(np.zeros((0, 3), np.float32)).shape == (0, 3)


@pytest.mark.usefixtures("open3d_threads")
@pytest.mark.parametrize("reproducible", [True, False])
@pytest.mark.parametrize(
    ("method", "kernel"),
    [
        ("point_to_plane", "rgbd_odometry_multi_scale"),
        ("hybrid", "compute_odometry_result_hybrid"),
        ("intensity", "compute_odometry_result_intensity"),
    ],
)
def test_the_dense_alignment_sums_on_one_thread_only_when_reproducible(
    monkeypatch: pytest.MonkeyPatch, reproducible: bool, method: str, kernel: str
) -> None:
    from helpers_odometry import K_QVGA

    from process.odometry.dense import DenseAligner

    seen: list[int] = []
    before = o3d.utility.get_max_threads()  # Open3D caps the fixture's 4 at the cores

    def spy(*_args: Any) -> None:
        seen.append(o3d.utility.get_max_threads())
        raise RuntimeError("too few correspondences")  # align then gives up: None

    monkeypatch.setattr(o3d.t.pipelines.odometry, kernel, spy)
    aligner = DenseAligner(
        K_QVGA, scale=2, max_depth_m=4.0, iterations=(3,), method=method, reproducible=reproducible
    )
    rng = np.random.default_rng(0)
    gray = rng.integers(0, 255, (240, 320), dtype=np.uint8)
    depth = np.full((240, 320), 1.5, np.float32)
    image = aligner.prepare(gray, depth)
    assert aligner.align(image, image, init_target_from_source=np.eye(4)) is None
    assert seen == [1 if reproducible else before]
    assert o3d.utility.get_max_threads() == before  # the process-wide limit is restored
