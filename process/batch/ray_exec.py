"""The Ray executor: one Ray task per recording, results streamed back as they finish.

Workers read the recordings and write DIR/<name> at the paths the driver passes, so the
recordings and DIR must be on a filesystem every node mounts at the same path.
"""

from __future__ import annotations

import logging
import shutil
from collections.abc import Callable, Sequence
from typing import Any

from process.batch import summary
from process.batch.tasks import Task, process_one
from process.config import BatchConfig
from process.errors import ReplayError

OnDone = Callable[[dict[str, Any]], None]
OnSubmit = Callable[[int], None]


def run_ray(
    tasks: Sequence[Task],
    *,
    address: str | None,
    cfg: BatchConfig,
    on_submit: OnSubmit,
    on_done: OnDone,
) -> None:
    """Submit every task to the cluster at `address` (None: a running one or a new local one).

    Raises:
        ReplayError: Ray is not installed, or the cluster cannot be reached.
    """
    try:
        import ray
    except ImportError as err:
        raise ReplayError(
            "--executor ray needs Ray: pip install 'semreplay[ray]' (or use --executor local)"
        ) from err
    owned = not ray.is_initialized()
    if owned:
        try:
            ray.init(address=address, log_to_driver=False, logging_level=logging.WARNING)
        except (ConnectionError, ValueError, RuntimeError) as err:
            raise ReplayError(
                f"cannot reach a Ray cluster at {address!r} ({err}); start one with"
                " `ray start --head` or leave out --address for a local one"
            ) from err
    try:
        _submit_and_collect(ray, tasks, cfg, on_submit, on_done)
    finally:
        if owned:
            ray.shutdown()


def _submit_and_collect(
    ray: Any, tasks: Sequence[Task], cfg: BatchConfig, on_submit: OnSubmit, on_done: OnDone
) -> None:
    remote = ray.remote(process_one).options(
        num_cpus=cfg.cpus_per_task,
        num_gpus=cfg.gpus_per_task,
        memory=int(cfg.memory_gb_per_task * 1024**3),
        max_retries=cfg.max_retries,  # worker process or node lost
        retry_exceptions=False,  # process_one returns a failed row for bad input
    )
    by_ref = {remote.remote(task): task for task in tasks}
    pending = list(by_ref)
    on_submit(len(pending))
    try:
        while pending:
            done, pending = ray.wait(pending, num_returns=1, timeout=1.0)
            for ref in done:
                on_done(_row(ray, ref, by_ref[ref], cfg.max_retries))
    except BaseException:
        for ref in pending:
            ray.cancel(ref, force=True)
        for ref in pending:
            shutil.rmtree(by_ref[ref].partial_dir, ignore_errors=True)
        raise


def _row(ray: Any, ref: Any, task: Task, retries: int) -> dict[str, Any]:
    """Return the task's row, or a failed row when its worker was lost on every try."""
    try:
        row: dict[str, Any] = ray.get(ref)
        return row
    except ray.exceptions.RayError as err:
        shutil.rmtree(task.partial_dir, ignore_errors=True)
        first = (str(err).strip().splitlines() or [""])[0]
        return summary.failed_row(
            task.name,
            task.recording,
            f"Ray task lost after {retries} retries ({type(err).__name__}): {first}",
        )
