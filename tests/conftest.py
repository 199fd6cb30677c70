"""Fixtures shared by every test: real data beside the checkout and small recordings of our own."""

from __future__ import annotations

import signal
from pathlib import Path

import numpy as np
import pytest

from capture.recording import Extrinsics, Intrinsics, RecordingWriter

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"

# A test run started in the background (`make test &` from a script) inherits SIGINT ignored, and
# so would every process the tests start: the Ctrl-C tests (batch, viewer) would send a signal
# their child never sees. Give the run Python's own handler; children then start at the default.
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

# A D435-like pair of cameras at 640x480 (colour) and 640x480 (depth), 15 mm baseline along x.
COLOR_K = Intrinsics(640, 480, 615.0, 615.0, 320.0, 240.0)
DEPTH_K = Intrinsics(640, 480, 385.0, 385.0, 321.0, 239.0)
DEPTH_TO_COLOR = Extrinsics.from_librealsense([1, 0, 0, 0, 1, 0, 0, 0, 1], [0.015, 0.0, 0.0])


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Return ../shared/data beside the checkout, or skip when it is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(
            f"real test data not found at {SHARED_DATA} (../shared/data beside the checkout)"
        )
    return SHARED_DATA


def write_synthetic_recording(path: Path, *, frames: int = 5, aligned: bool = False) -> Path:
    """Write a small recording of a fronto-parallel plane at 2 m, with ground-truth poses."""
    rng = np.random.default_rng(0)
    with RecordingWriter(path) as writer:
        writer.write_metadata("device", {"name": "synthetic", "depth_scale_m": "0.001"})
        if not aligned:
            writer.write_calibration(DEPTH_TO_COLOR, stamp_ns=1_000_000_000)
        for i in range(frames):
            stamp_ns = 1_000_000_000 + i * 33_333_333
            color = rng.integers(0, 255, (480, 640, 3), dtype=np.uint8)
            depth = np.full((480, 640), 2000, np.uint16)
            writer.write_color(color, stamp_ns=stamp_ns, intrinsics=COLOR_K)
            writer.write_depth(
                depth,
                stamp_ns=stamp_ns,
                intrinsics=COLOR_K if aligned else DEPTH_K,
                aligned=aligned,
            )
            pose = np.eye(4)
            pose[0, 3] = 0.01 * i
            writer.write_ground_truth(stamp_ns=stamp_ns, world_from_camera=pose)
    return path


@pytest.fixture
def recording(tmp_path: Path) -> Path:
    """Return a 5-frame synthetic recording (unaligned depth, with extrinsics and poses)."""
    return write_synthetic_recording(tmp_path / "synthetic.mcap")


@pytest.fixture(scope="session")
def sim_recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Return a short simulated D435 recording (seed 3, 30 frames, 640x480) with ground truth."""
    from capture.sim import simulate_recording

    path = tmp_path_factory.mktemp("sim") / "sim_seed3.mcap"
    simulate_recording(path, seed=3, frames=30, fps=30.0, width=640, height=480)
    return path
