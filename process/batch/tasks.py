"""One batch task: a recording processed into DIR/.<name>.partial, then renamed to DIR/<name>.

A folder DIR/<name> is complete when it holds `batch.json` (written last, before the rename)
whose fingerprint matches the command being run: the same recording, effective config (less
[batch]), stages, weights and --no-viz. The rename makes it appear whole or not at all, so a
killed batch leaves only DIR/.<name>.partial folders, which the next run deletes.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import shutil
import socket
import sys
import time
from pathlib import Path
from typing import Any, Final

from capture.errors import CaptureError
from process import outputs
from process.batch import summary
from process.config import BatchConfig, ReplayConfig, to_toml
from process.errors import ReplayError
from process.job import run_recording

MARKER: Final = summary.MARKER
THREAD_VARS: Final = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


@dataclasses.dataclass(frozen=True, slots=True)
class Task:
    """Everything a worker needs to process one recording (picklable; paths seen by workers)."""

    recording: Path
    name: str
    out_root: Path
    cfg: ReplayConfig
    stages: tuple[str, ...]
    weights: Path | None = None
    device: str = "auto"
    no_viz: bool = False
    threads: int = 1

    @property
    def final_dir(self) -> Path:
        """Return DIR/<name>, where the outputs appear when complete."""
        return self.out_root / self.name

    @property
    def partial_dir(self) -> Path:
        """Return DIR/.<name>.partial, where the outputs are written first."""
        return self.out_root / f".{self.name}.partial"

    def fingerprint(self) -> dict[str, Any]:
        """Return what must match for an earlier folder to count as this task's output."""
        return {
            "recording": str(self.recording.resolve()),
            "stages": list(self.stages),
            "weights": str(self.weights.resolve()) if self.weights else None,
            "no_viz": self.no_viz,
            "config": to_toml(dataclasses.replace(self.cfg, batch=BatchConfig())),
        }


def completed_row(task: Task) -> dict[str, Any] | None:
    """Return the stored row if DIR/<name> is complete for this task, else None."""
    try:
        marker = json.loads((task.final_dir / MARKER).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(marker, dict) or marker.get("fingerprint") != task.fingerprint():
        return None
    row = marker.get("row")
    if not isinstance(row, dict) or not (task.final_dir / outputs.METRICS).is_file():
        return None
    return summary.with_output_names({**row, "reused": True}, task.final_dir)


def process_one(task: Task) -> dict[str, Any]:
    """Process one recording into DIR/<name>; return its summary row, never raise on bad input."""
    limit_threads(task.threads)
    reset_peak_rss()
    t0 = time.perf_counter()
    host = socket.gethostname()
    if task.final_dir.exists() and not (task.final_dir / MARKER).is_file():
        reason = (
            f"{task.final_dir} exists and was not written by batch (no {MARKER}); move it away"
            " or choose another --out"
        )
        return summary.failed_row(task.name, task.recording, reason, host=host)
    shutil.rmtree(task.partial_dir, ignore_errors=True)
    try:
        return _run_and_publish(task, t0, host)
    except (ReplayError, CaptureError) as err:
        reason = str(err)
    except Exception as err:  # any other failure is this recording's, not the batch's
        reason = f"{type(err).__name__}: {err}"
    except BaseException:  # interrupted outside the pipeline (which says RunInterruptedError)
        shutil.rmtree(task.partial_dir, ignore_errors=True)
        raise
    shutil.rmtree(task.partial_dir, ignore_errors=True)
    wall_s = round(time.perf_counter() - t0, 3)
    return summary.failed_row(task.name, task.recording, reason, wall_s=wall_s, host=host)


def _run_and_publish(task: Task, t0: float, host: str) -> dict[str, Any]:
    """Run the recording into the partial folder, write its row last, rename it into place."""
    result = run_recording(
        task.recording,
        task.partial_dir,
        cfg=task.cfg,
        stages=task.stages,
        weights=task.weights,
        device=task.device,
        no_viz=task.no_viz,
        progress=False,
    )
    row = summary.ok_row(
        task.name,
        task.recording,
        result.metrics,
        task.final_dir,
        duration_s=recording_duration_s(task.recording),
        host=host,
        wall_s=round(time.perf_counter() - t0, 3),
        peak_rss_gb=peak_rss_gb(),
    )
    row = summary.with_output_names(row, task.partial_dir)
    if row["preview"]:
        row["preview"] = str(task.final_dir / summary.PREVIEW)
    marker = {"fingerprint": task.fingerprint(), "row": row}
    outputs.write_text_atomic(task.partial_dir / MARKER, json.dumps(marker, indent=2))
    publish(task)
    return row


def publish(task: Task) -> None:
    """Rename DIR/.<name>.partial to DIR/<name>, replacing an older folder of that name."""
    old = task.out_root / f".{task.name}.old"
    shutil.rmtree(old, ignore_errors=True)
    if task.final_dir.exists():
        task.final_dir.rename(old)
    task.partial_dir.rename(task.final_dir)
    shutil.rmtree(old, ignore_errors=True)


def recording_duration_s(recording: Path) -> float:
    """Return the recording's duration in seconds (first to last message)."""
    from capture.recording import RecordingReader

    with RecordingReader(recording) as rec:
        return round(rec.duration_ns / 1e9, 3)


def limit_threads(n: int) -> None:
    """Limit this process's BLAS, OpenMP, torch, OpenCV and Open3D thread pools to n threads."""
    for var in THREAD_VARS:
        os.environ[var] = str(n)  # libraries loaded from now on
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=n)  # BLAS and OpenMP pools loaded already
    import cv2
    import open3d as o3d

    cv2.setNumThreads(n)
    o3d.utility.set_max_threads(n)  # its own pool, sized when it loaded
    if "torch" in sys.modules:  # else torch reads OMP_NUM_THREADS when segmentation loads it
        sys.modules["torch"].set_num_threads(n)


def reset_peak_rss() -> None:
    """Reset this process's peak RSS to its current RSS (Linux; a reused worker starts afresh)."""
    with contextlib.suppress(OSError):
        Path("/proc/self/clear_refs").write_text("5")


def peak_rss_gb() -> float | None:
    """Return this process's peak RSS in GB since the last reset (None off Linux)."""
    with contextlib.suppress(OSError):
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return round(int(line.split()[1]) / 1024**2, 3)
    return None
