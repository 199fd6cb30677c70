"""The files of `process run --out DIR`: written whole into a staging folder, then moved in.

A run writes into `DIR/.run.part<PID>/`; only when every output is complete are the folder's
old outputs removed and the new ones renamed into place, so the folder never holds a mix of
runs nor a half-written file. A failing or interrupted run leaves the folder as it was; the
staging folder of a killed run (SIGKILL) is removed by the next run into the folder.
"""

from __future__ import annotations

import json
import logging
import math
import os
import re
import shutil
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Final

from rich.table import Table

from process.errors import OutputError
from viz.logger import Logger

logger = logging.getLogger(__name__)

RRD: Final = "recording.rrd"
MAP_FUSED: Final = "map_fused.ply"
MAP_REFINED: Final = "map_refined.ply"
TRAJECTORY: Final = "trajectory.tum"
METRICS: Final = "metrics.json"
CONFIG: Final = "config.toml"
PREVIEW: Final = "preview.png"  # top view of the refined (else fused) map, named in metrics.json
OUTPUTS: Final = (RRD, MAP_FUSED, MAP_REFINED, TRAJECTORY, METRICS, CONFIG, PREVIEW)
STAGING_PREFIX: Final = ".run.part"
# Temporaries of ours: `.NAME.part<PID>`, `.NAME.<PID>.tmp` (clouds), `.run.part<PID>/`.
_TEMPORARY: Final = re.compile(r"\..+\.part(\d+)|\..+\.(\d+)\.tmp")


def temporary_path(path: Path) -> Path:
    """Return the name a file is written under before it is renamed into place."""
    return path.with_name(f".{path.name}.part{os.getpid()}")


@contextmanager
def atomic_path(path: Path) -> Iterator[Path]:
    """Yield a temporary path next to `path`; rename it into place only if the block succeeds.

    The project's one atomic writer: every output file goes through it.

    Raises:
        OutputError: the file could not be written or renamed (disk full, no permission).
    """
    tmp = temporary_path(path)
    try:
        yield tmp
        tmp.replace(path)
    except OSError as err:
        raise OutputError(
            f"cannot write {path.name} ({err.strerror or err}); check the folder's free space"
            f" and permissions: {path}"
        ) from err
    finally:
        tmp.unlink(missing_ok=True)


def write_text_atomic(path: Path, text: str) -> None:
    """Write UTF-8 text to `path` through a temporary file and a rename."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def write_bytes_atomic(path: Path, data: bytes) -> None:
    """Write bytes to `path` through a temporary file and a rename."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # another user's process
    return True


def remove_stale_temporaries(folder: Path) -> list[str]:
    """Remove the temporaries of runs that died (their PID is gone); return their names."""
    removed = []
    for entry in folder.iterdir():
        match = _TEMPORARY.fullmatch(entry.name)
        if match is None:
            continue
        pid = int(match.group(1) or match.group(2))
        if pid == os.getpid() or _pid_alive(pid):
            continue
        if entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry, ignore_errors=True)
        else:
            entry.unlink(missing_ok=True)
        removed.append(entry.name)
    if removed:
        logger.warning("removed temporaries of runs that died: %s", ", ".join(removed))
    return removed


def prepare_out(out: Path, *, force: bool) -> Path:
    """Check --out, clean dead runs' temporaries, make and return this run's staging folder.

    Raises:
        OutputError: --out is a file, cannot be created or written, or holds files and
            `force` is not set.
    """
    if out.exists() and not out.is_dir():
        raise OutputError(f"--out must be a folder, found a file; choose another path: {out}")
    try:
        out.mkdir(parents=True, exist_ok=True)
        remove_stale_temporaries(out)
        existing = sorted(p.name for p in out.iterdir() if _TEMPORARY.fullmatch(p.name) is None)
    except OSError as err:
        raise OutputError(
            f"cannot use --out ({err.strerror}); choose another folder: {out}"
        ) from err
    if existing and not force:
        raise OutputError(
            f"--out is not empty ({len(existing)} entries, e.g. {existing[0]}); pass --force to "
            f"replace its outputs, or choose an empty folder: {out}"
        )
    staging = out / f"{STAGING_PREFIX}{os.getpid()}"
    try:
        shutil.rmtree(staging, ignore_errors=True)
        staging.mkdir()
        (staging / ".write-test").write_bytes(b"")
        (staging / ".write-test").unlink()
    except OSError as err:
        shutil.rmtree(staging, ignore_errors=True)
        raise OutputError(
            f"cannot write into --out ({err.strerror}); check its permissions or free space: {out}"
        ) from err
    return staging


@contextmanager
def staged(out: Path, *, force: bool) -> Iterator[Path]:
    """Yield this run's staging folder in --out; remove it afterwards, whatever happened."""
    staging = prepare_out(out, force=force)
    try:
        yield staging
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def commit(staging: Path, out: Path, written: list[Path]) -> list[Path]:
    """Replace the folder's outputs by the staged ones; return the final paths.

    Every old output of ours is removed first, so the folder never mixes two runs.
    """
    try:
        for name in OUTPUTS:
            (out / name).unlink(missing_ok=True)
        final = []
        for path in written:
            target = out / path.relative_to(staging)
            path.replace(target)
            final.append(target)
    except OSError as err:
        raise OutputError(f"cannot move the outputs into place ({err.strerror}): {out}") from err
    return final


def close_logger(viz: Logger, *, quiet: bool) -> None:
    """Close the .rrd logger; a failure (full disk) is an OutputError, or only logged if quiet."""
    try:
        viz.close()
    except Exception as err:  # rerun raises RuntimeError, the OS OSError; both mean "not written"
        if quiet:
            logger.debug("closing the .rrd logger failed too: %s", err)
            return
        raise OutputError(f"cannot finish {RRD} ({err}); free space and run again") from err


def _finite(value: Any) -> Any:
    """Replace NaN and infinities (not JSON) by None, recursively."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Mapping):
        return {str(k): _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value


def write_metrics(path: Path, metrics: Mapping[str, Any]) -> None:
    """Write metrics.json (the schema of ARCHITECTURE.md)."""
    write_text_atomic(path, json.dumps(_finite(metrics), indent=2, sort_keys=False) + "\n")


def summary_table(metrics: Mapping[str, Any], *, title: str = "semreplay process run") -> Table:
    """Return one table of timings and, where present, the metrics against ground truth."""
    table = Table(title=title)
    table.add_column("stage")
    table.add_column("figure")
    table.add_column("value", justify="right")
    stages = metrics.get("stages", {})
    for stage, seconds in metrics.get("seconds", {}).items():
        figures = stages.get(stage, {})
        text = f"{seconds:.2f} s wall"
        if figures.get("cpu_s") is not None:
            text += f", {figures['cpu_s']:.2f} s CPU"
        if figures.get("fps") is not None:
            text += f", {figures['fps']:.1f} frames/s"
        table.add_row(stage, "time", text)
    job = metrics.get("job", {})
    if job.get("fps") is not None:
        table.add_row("whole job", "frames/s", f"{job['fps']:.1f} ({job['cores_used']} cores used)")
        slowest = max(job["bottleneck_share"].items(), key=lambda kv: kv[1])
        table.add_row(
            "whole job", "bottleneck", f"{slowest[0]} ({100 * slowest[1]:.0f} % of the run)"
        )
    for key, value in metrics.get("follow", {}).items():  # seconds behind the camera, drops
        table.add_row("following", key, _fmt(value))
    odo = metrics.get("odometry", {})
    for key in (
        "frames",
        "keyframes",
        "fps",
        "ate_rmse_m",
        "rpe_trans_m",
        "rpe_rot_deg",
        "rolling_shutter_readout_s",
    ):
        if odo.get(key) is not None:
            table.add_row("odometry", key, _fmt(odo[key]))
    seg = metrics.get("segmentation", {})
    for key in (
        "model",
        "model_reason",  # why this model: the recording's device, --weights or the config
        "threads",
        "load_s",
        "keyframes",
        "ms_per_keyframe",
        "miou_2d",
    ):
        if seg.get(key) is not None:
            table.add_row("segmentation", key, _fmt(seg[key]))
    for key, value in metrics.get("refinement", {}).get("points", {}).items():
        table.add_row("refinement", f"points {key}", _fmt(value))
    phases = metrics.get("refinement", {}).get("phases", {})
    for phase, per_class in phases.items():
        overall = per_class.get("all", {})
        if overall:
            figures = ", ".join(
                f"{k} {overall[k]:.3f}"
                for k in ("iou", "precision", "recall", "f1")
                if k in overall
            )
            table.add_row("refinement", f"phase {phase} (all)", figures)
    return table


def _fmt(value: Any) -> str:
    return f"{value:.4g}" if isinstance(value, float) else str(value)
