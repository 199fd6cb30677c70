"""The files of `process run --out DIR`: each written to a temporary name and renamed."""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Final

from rich.table import Table

from process.errors import OutputError

RRD: Final = "recording.rrd"
MAP_FUSED: Final = "map_fused.ply"
MAP_REFINED: Final = "map_refined.ply"
TRAJECTORY: Final = "trajectory.tum"
METRICS: Final = "metrics.json"
CONFIG: Final = "config.toml"


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
    odo = metrics.get("odometry", {})
    for key in ("frames", "keyframes", "fps", "ate_rmse_m", "rpe_trans_m", "rpe_rot_deg"):
        if odo.get(key) is not None:
            table.add_row("odometry", key, _fmt(odo[key]))
    seg = metrics.get("segmentation", {})
    for key in ("keyframes", "ms_per_keyframe", "miou_2d"):
        if seg.get(key) is not None:
            table.add_row("segmentation", key, _fmt(seg[key]))
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
