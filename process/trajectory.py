"""Trajectories: TUM files, time association, Umeyama alignment, ATE, RPE, path length.

The metrics follow evo (`evo_ape tum GT EST -a`, `evo_rpe tum GT EST -r trans_part|angle_deg
--delta 1 --delta_unit f`): the trajectories are associated by nearest time stamp starting from
the one with fewer poses, ATE is the RMSE of position errors after an SE(3) Umeyama alignment of
the estimate onto the ground truth, and RPE compares consecutive relative motions.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

from process.errors import ReplayError
from process.outputs import write_text_atomic

_NS_PER_S = 1_000_000_000


@dataclass(frozen=True, slots=True)
class Trajectory:
    """Camera poses over time: world_from_camera (colour optical frame) at each stamp."""

    stamps_ns: npt.NDArray[np.int64]  # (N,)
    poses: npt.NDArray[np.float64]  # (N, 4, 4)

    def __post_init__(self) -> None:
        n = len(self.stamps_ns)
        if self.stamps_ns.shape != (n,) or self.poses.shape != (n, 4, 4):
            raise ReplayError(
                f"expected N stamps and N 4x4 poses, found stamps {self.stamps_ns.shape} and"
                f" poses {self.poses.shape}; build it with Trajectory.of()"
            )

    @staticmethod
    def of(stamps_ns: Sequence[int], poses: Sequence[npt.ArrayLike]) -> Trajectory:
        """Return the trajectory of stamps and poses given as sequences of the same length."""
        if len(stamps_ns) != len(poses):
            raise ReplayError(
                f"expected one pose per stamp, found {len(stamps_ns)} stamps and {len(poses)}"
                " poses; pass matching lists"
            )
        return Trajectory(
            np.asarray(stamps_ns, np.int64).reshape(-1),
            np.asarray(poses, np.float64).reshape(-1, 4, 4),
        )

    def __len__(self) -> int:
        return len(self.stamps_ns)

    @property
    def positions(self) -> npt.NDArray[np.float64]:
        """Return the (N, 3) camera positions in the world frame."""
        return self.poses[:, :3, 3]


def write_tum(path: Path, trajectory: Trajectory) -> None:
    """Write `timestamp tx ty tz qx qy qz qw` lines (seconds, camera-to-world) atomically."""
    lines = [
        _tum_line(int(s), p) for s, p in zip(trajectory.stamps_ns, trajectory.poses, strict=True)
    ]
    write_text_atomic(path, "# timestamp tx ty tz qx qy qz qw\n" + "".join(lines))


def _tum_line(stamp_ns: int, pose: npt.NDArray[np.float64]) -> str:
    q = Rotation.from_matrix(pose[:3, :3]).as_quat()  # x y z w
    if q[3] < 0:
        q = -q
    sec, ns = divmod(stamp_ns, _NS_PER_S)
    t = pose[:3, 3]
    return (
        f"{sec}.{ns:09d} {t[0]:.9f} {t[1]:.9f} {t[2]:.9f} "
        f"{q[0]:.9f} {q[1]:.9f} {q[2]:.9f} {q[3]:.9f}\n"
    )


def read_tum(path: Path) -> Trajectory:
    """Read a TUM trajectory file into (stamps_ns, world_from_camera poses)."""
    path = Path(path)
    stamps: list[int] = []
    rows: list[list[float]] = []
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as err:
        raise ReplayError(f"cannot read trajectory ({err.strerror}): {path}") from err
    for number, line in enumerate(text.splitlines(), start=1):
        fields = line.replace(",", " ").split()
        if not fields or fields[0].startswith("#"):
            continue
        if len(fields) != 8:
            raise ReplayError(
                f"expected 8 fields 'timestamp tx ty tz qx qy qz qw' on line {number},"
                f" found {len(fields)}; is this a TUM file?: {path}"
            )
        stamps.append(_seconds_to_ns(fields[0]))
        rows.append([float(v) for v in fields[1:]])
    data = np.array(rows, np.float64).reshape(-1, 7)
    poses = np.tile(np.eye(4), (len(data), 1, 1))
    if len(data):
        poses[:, :3, :3] = Rotation.from_quat(data[:, 3:]).as_matrix()
        poses[:, :3, 3] = data[:, :3]
    return Trajectory(np.array(stamps, np.int64), poses)


def _seconds_to_ns(text: str) -> int:
    """Parse decimal seconds exactly (a float64 would lose the nanoseconds of an epoch stamp)."""
    whole, _, frac = text.partition(".")
    if "e" in text.lower():
        return round(float(text) * _NS_PER_S)
    sign = -1 if whole.startswith("-") else 1
    return int(whole or "0") * _NS_PER_S + sign * int((frac + "000000000")[:9])


def associate(
    stamps_a: npt.ArrayLike, stamps_b: npt.ArrayLike, *, max_dt_ns: int = 10_000_000
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Return index pairs (ia, ib): for each stamp of a, the nearest stamp of b within max_dt_ns."""
    a = np.asarray(stamps_a, np.int64)
    b = np.asarray(stamps_b, np.int64)
    if len(a) == 0 or len(b) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    order = np.argsort(b, kind="stable")
    sorted_b = b[order]
    right = np.clip(np.searchsorted(sorted_b, a, side="right"), 0, len(b) - 1)
    left = np.clip(right - 1, 0, len(b) - 1)
    diff_right = np.abs(sorted_b[right] - a)
    diff_left = np.abs(a - sorted_b[left])
    # Ties go to the earlier stamp, as in evo's matching_time_indices.
    best = np.where(diff_left <= diff_right, left, right)
    ok = np.minimum(diff_left, diff_right) <= max_dt_ns
    return np.flatnonzero(ok).astype(np.int64), order[best[ok]].astype(np.int64)


def associate_trajectories(
    est: Trajectory, gt: Trajectory, *, max_dt_ns: int = 10_000_000
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Return the (est, gt) poses paired in time, matching from the shorter one like evo."""
    if len(est) <= len(gt):
        i_est, i_gt = associate(est.stamps_ns, gt.stamps_ns, max_dt_ns=max_dt_ns)
    else:
        i_gt, i_est = associate(gt.stamps_ns, est.stamps_ns, max_dt_ns=max_dt_ns)
    if len(i_est) == 0:
        raise ReplayError(
            f"no time stamps of the estimate ({len(est)}) and the ground truth ({len(gt)})"
            f" lie within {max_dt_ns / 1e6:g} ms of each other; are both in the same clock?"
        )
    return est.poses[i_est], gt.poses[i_gt]


def align_umeyama(
    source: npt.ArrayLike, target: npt.ArrayLike, *, with_scale: bool = False
) -> tuple[npt.NDArray[np.float64], float]:
    """Return (target_from_source 4x4, scale) that minimise ||target - (s R source + t)||.

    Umeyama 1991, as in evo's `geometry.umeyama_alignment`; the scale is 1 unless with_scale.
    """
    x = np.asarray(source, np.float64).reshape(-1, 3)
    y = np.asarray(target, np.float64).reshape(-1, 3)
    if len(x) != len(y) or len(x) < 3:
        raise ReplayError(f"expected >= 3 paired points to align, found {len(x)} and {len(y)}")
    mean_x, mean_y = x.mean(axis=0), y.mean(axis=0)
    cov = (y - mean_y).T @ (x - mean_x) / len(x)
    u, d, vt = np.linalg.svd(cov)
    s = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        s[2, 2] = -1
    rot = u @ s @ vt
    var_x = float(np.mean(np.sum((x - mean_x) ** 2, axis=1)))
    scale = float(np.trace(np.diag(d) @ s) / var_x) if with_scale and var_x > 0 else 1.0
    out = np.eye(4)
    out[:3, :3] = rot
    out[:3, 3] = mean_y - scale * rot @ mean_x
    return out, scale


def ate_rmse(est: Trajectory, gt: Trajectory, *, max_dt_ns: int = 10_000_000) -> float:
    """Return the absolute trajectory error (RMSE of positions, metres) after SE(3) alignment."""
    e, g = associate_trajectories(est, gt, max_dt_ns=max_dt_ns)
    if len(e) < 3:
        return float(np.sqrt(np.mean(np.sum((e[:, :3, 3] - g[:, :3, 3]) ** 2, axis=1))))
    gt_from_est, _ = align_umeyama(e[:, :3, 3], g[:, :3, 3])
    aligned = e[:, :3, 3] @ gt_from_est[:3, :3].T + gt_from_est[:3, 3]
    return float(np.sqrt(np.mean(np.sum((aligned - g[:, :3, 3]) ** 2, axis=1))))


def rpe(
    est: Trajectory, gt: Trajectory, *, delta: int = 1, max_dt_ns: int = 10_000_000
) -> tuple[float, float]:
    """Return the relative pose error over `delta` frames: (trans RMSE m, rotation RMSE deg)."""
    e, g = associate_trajectories(est, gt, max_dt_ns=max_dt_ns)
    if len(e) <= delta:
        return 0.0, 0.0
    rel_e = np.linalg.inv(e[:-delta]) @ e[delta:]
    rel_g = np.linalg.inv(g[:-delta]) @ g[delta:]
    err = np.linalg.inv(rel_g) @ rel_e
    trans = np.linalg.norm(err[:, :3, 3], axis=1)
    rot_deg = np.degrees(Rotation.from_matrix(err[:, :3, :3]).magnitude())
    return float(np.sqrt(np.mean(trans**2))), float(np.sqrt(np.mean(rot_deg**2)))


def path_length(poses: npt.ArrayLike) -> float:
    """Return the length in metres of the path through the poses' positions."""
    p = np.asarray(poses, np.float64)
    if len(p) < 2:
        return 0.0
    return float(np.sum(np.linalg.norm(np.diff(p[:, :3, 3], axis=0), axis=1)))
