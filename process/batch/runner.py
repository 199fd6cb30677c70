"""run_batch: find the recordings, skip those already complete, run the rest, write the summary."""

from __future__ import annotations

import glob
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import psutil

from process.batch import report, summary
from process.batch.progress import BatchProgress
from process.batch.tasks import Task, completed_row
from process.config import ReplayConfig
from process.errors import ConfigError, RunInterruptedError

EXECUTORS = ("local", "ray")


def find_recordings(inputs: Sequence[str]) -> list[Path]:
    """Return the recordings named by files, folders (their *.mcap) and globs, in order, once each.

    Raises:
        ConfigError: an input names nothing, or two recordings share a file name.
    """
    found: list[Path] = []
    for item in inputs:
        path = Path(item)
        if path.is_dir():
            matches = sorted(path.glob("*.mcap"))
        elif path.is_file():
            matches = [path]
        else:
            # glob.glob takes absolute patterns too, Path.glob only relative ones
            matches = sorted(Path(p) for p in glob.glob(item) if Path(p).is_file())  # noqa: PTH207
        if not matches:
            raise ConfigError(
                f"no recording found at {item!r}: expected an .mcap file, a folder of .mcap"
                " files or a glob that matches some"
            )
        found.extend(m for m in matches if m.resolve() not in {f.resolve() for f in found})
    by_name: dict[str, Path] = {}
    for path in found:
        if path.stem in by_name:
            raise ConfigError(
                f"two recordings would share the output folder {path.stem!r}: {by_name[path.stem]}"
                f" and {path}; rename one or run them in separate batches"
            )
        by_name[path.stem] = path
    return found


def default_jobs(memory_gb_per_task: float) -> int:
    """Return how many tasks this machine runs at once: one per core, as memory allows."""
    cores = len(os.sched_getaffinity(0))
    memory_gb = psutil.virtual_memory().available / 1024**3
    return max(1, min(cores, int(memory_gb // memory_gb_per_task)))


def run_batch(
    inputs: Sequence[str],
    out: Path,
    *,
    cfg: ReplayConfig,
    stages: tuple[str, ...],
    weights: Path | None = None,
    device: str = "auto",
    no_viz: bool = False,
    jobs: int | None = None,
    executor: str = "local",
    address: str | None = None,
) -> list[dict[str, Any]]:
    """Process every recording into out/<name>/; write out/summary.{csv,parquet,html}.

    Returns the rows, in input order. Recordings whose folder is complete for these settings
    are skipped (their rows say reused); the others, failed ones included, are run.

    Raises:
        ConfigError: bad inputs or options.
        RunInterruptedError: Ctrl-C or SIGTERM; the summary lists what finished.
    """
    tasks, n_jobs = _plan(
        inputs, out, cfg, stages, weights, device, no_viz, jobs=jobs, executor=executor
    )
    out.mkdir(parents=True, exist_ok=True)
    rows = {t.name: row for t in tasks if (row := completed_row(t)) is not None}
    todo = [t for t in tasks if t.name not in rows]
    progress = BatchProgress(len(tasks), reused=len(rows))

    def finished(row: dict[str, Any]) -> None:
        rows[row["name"]] = row
        progress.done(row)
        _write(out, tasks, rows)

    try:
        with progress:
            if todo and executor == "local":
                from process.batch.local import run_local

                run_local(todo, jobs=n_jobs, on_start=progress.start, on_done=finished)
            elif todo:
                from process.batch.ray_exec import run_ray

                run_ray(
                    todo,
                    address=address,
                    cfg=cfg.batch,
                    on_submit=progress.submitted,
                    on_done=finished,
                )
    except KeyboardInterrupt as err:
        for task in todo:
            if task.name not in rows:
                reason = "not finished: the batch was interrupted"
                rows[task.name] = summary.failed_row(task.name, task.recording, reason)
        n_ok = sum(r["status"] == "ok" for r in _write(out, tasks, rows))
        raise RunInterruptedError(
            f"interrupted: {n_ok} of {len(tasks)} recordings complete in {out}; rerun the same"
            " command to process the rest"
        ) from err
    return _write(out, tasks, rows)


def _plan(
    inputs: Sequence[str],
    out: Path,
    cfg: ReplayConfig,
    stages: tuple[str, ...],
    weights: Path | None,
    device: str,
    no_viz: bool,
    *,
    jobs: int | None,
    executor: str,
) -> tuple[list[Task], int]:
    """Return one task per recording and how many run at once here (local executor)."""
    if executor not in EXECUTORS:
        raise ConfigError(f"unknown executor {executor!r}; valid: {', '.join(EXECUTORS)}")
    if jobs is not None and jobs < 1:
        raise ConfigError(f"--jobs must be >= 1, got {jobs}")
    recordings = find_recordings(inputs)
    n_jobs = min(jobs or default_jobs(cfg.batch.memory_gb_per_task), len(recordings))
    if executor == "ray":
        threads = max(1, int(cfg.batch.cpus_per_task))
    else:
        threads = max(1, len(os.sched_getaffinity(0)) // n_jobs)
    tasks = [
        Task(rec, rec.stem, out, cfg, stages, weights, device, no_viz, threads)
        for rec in recordings
    ]
    return tasks, n_jobs


def _write(
    out: Path, tasks: Sequence[Task], rows: dict[str, dict[str, Any]]
) -> list[dict[str, Any]]:
    """Write the summary of the rows so far, in input order; return them."""
    ordered = [rows[t.name] for t in tasks if t.name in rows]
    summary.write_tables(out, ordered)
    report.write_html(out, ordered)
    return ordered
