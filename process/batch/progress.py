"""The batch's progress on the terminal: one bar over recordings, a line per running task."""

from __future__ import annotations

from typing import Any

from rich.console import Console
from rich.markup import escape
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    SpinnerColumn,
    TaskID,
    TextColumn,
    TimeElapsedColumn,
)

from process.batch.tasks import Task


class BatchProgress:
    """A rich progress display: the bar over recordings, a spinner per task running here.

    Each finished recording also prints one line (ok with its figures, or failed with the
    reason), which stays in the terminal's scrollback and in logs that are not terminals.
    """

    def __init__(self, total: int, *, reused: int, console: Console | None = None) -> None:
        self._console = console or Console(stderr=True)
        self._progress = Progress(
            SpinnerColumn(),
            TextColumn("{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            console=self._console,
            transient=False,
        )
        self._overall = self._progress.add_task("recordings", total=total, completed=reused)
        self._running: dict[str, TaskID] = {}
        if reused:
            self._console.print(f"{reused} of {total} recordings complete already: kept")

    def __enter__(self) -> BatchProgress:
        self._progress.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._progress.stop()

    def start(self, task: Task) -> None:
        """Show a task that started on this machine."""
        self._running[task.name] = self._progress.add_task(
            f"  {escape(task.name)}: running", total=None
        )

    def submitted(self, n: int) -> None:
        """Say that n tasks went to a cluster (they are not followed one by one)."""
        self._progress.update(self._overall, description=f"recordings ({n} sent to Ray)")

    def done(self, row: dict[str, Any]) -> None:
        """Advance the bar and print the recording's one line."""
        task_id = self._running.pop(row["name"], None)
        if task_id is not None:
            self._progress.remove_task(task_id)
        self._progress.advance(self._overall)
        self._progress.console.print(line(row))


def line(row: dict[str, Any]) -> str:
    """Return a finished recording's one line (rich markup)."""
    name = escape(row["name"])
    if row["status"] != "ok":
        return f"[red]failed[/red] {name}: {escape(row['reason'])}"
    parts = [f"{row['frames']} frames", f"{row['keyframes']} keyframes"]
    if row.get("ate_rmse_m") is not None:
        parts.append(f"ATE {row['ate_rmse_m']:.3f} m")
    if row.get("map_f1_III") is not None:
        parts.append(f"map F1 {row['map_f1_III']:.2f}")
    if row.get("wall_s") is not None:
        parts.append(f"{row['wall_s']:.1f} s")
    return f"[green]ok[/green] {name}: " + ", ".join(parts)
