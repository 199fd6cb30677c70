"""Odometry on a real slice: the first 60 frames of TUM fr1_rpy (Kinect v1, fast rotation).

Measured on this slice: ATE 2.5 cm (Open3D's frame-to-frame odometry: several cm), about
1 s of tracking. A blank frame in the middle (lens covered, depth lost) must be marked lost,
keep the last good pose, and leave the rest of the trajectory where it was.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from benchmarks.tum_odometry import Run, run_odometry, tum_frames
from capture.recording import RgbdFrame

FRAMES = 60
BLANK = 30  # index of the frame blanked in the second run
ATE_BOUND_M = 0.03  # measured 0.025 (the whole sequence: 0.020)
MAX_SHIFT_M = 0.005  # how far the blank frame may move the poses around it (measured 1.7 mm)


@pytest.fixture(scope="module")
def frames(shared_data: Path) -> list[RgbdFrame]:
    folder = shared_data / "tum_fr1_rpy"
    if not folder.is_dir():
        pytest.skip(f"TUM fr1_rpy not found at {folder}")
    return list(tum_frames(folder, count=FRAMES))


@pytest.fixture(scope="module")
def clean(frames: list[RgbdFrame]) -> Run:
    return run_odometry(iter(frames))


def test_real_fast_rotation_stays_within_bound(clean: Run) -> None:
    assert clean.statuses.count("lost") == 0
    assert clean.ate_m < ATE_BOUND_M


def test_blank_frame_is_lost_and_does_not_move_the_trajectory(
    frames: list[RgbdFrame], clean: Run
) -> None:
    blank = replace(
        frames[BLANK],
        color=np.zeros_like(frames[BLANK].color),
        depth_m=np.zeros_like(frames[BLANK].depth_m),
    )
    corrupted = run_odometry(iter([*frames[:BLANK], blank, *frames[BLANK + 1 :]]))
    assert corrupted.statuses[BLANK] == "lost"
    assert corrupted.statuses[BLANK + 1] in ("ok", "relocalised")
    # The lost frame holds the last good pose ...
    np.testing.assert_allclose(corrupted.poses[BLANK], corrupted.poses[BLANK - 1], atol=1e-9)
    # ... the frames around it stay where the clean run put them (later ones drift apart by
    # chance: one millimetre at the relocalised frame grows along the keyframe chain, 2.5 cm
    # at worst here, as the clean run itself moves when its keyframes change) ...
    near = [*range(BLANK), BLANK + 1]
    shift = np.linalg.norm(corrupted.poses[near, :3, 3] - clean.poses[near, :3, 3], axis=1)
    assert shift.max() < MAX_SHIFT_M
    # ... and the whole trajectory is as good as the clean one.
    assert corrupted.ate_m < max(clean.ate_m, 0.02) + 0.005
