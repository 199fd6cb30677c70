"""The local executor: one child process per recording, at most `jobs` at a time.

Children are forked from a multiprocessing forkserver that has imported the pipeline once, so a
task starts in milliseconds instead of seconds of imports. A child that dies (killed, out of
memory) is that recording's failed row; the others carry on. Children die with the batch: Ctrl-C
or SIGTERM stops them (each removes its partial folder), and SIGKILL of the batch ends the
forkserver, whose children then get SIGTERM.
"""

from __future__ import annotations

import contextlib
import ctypes
import multiprocessing
import os
import shutil
import signal
from collections.abc import Callable, Sequence
from multiprocessing.connection import Connection, wait
from typing import Any, NoReturn, cast

from process.batch import summary
from process.batch.tasks import Task

OnStart = Callable[[Task], None]
OnDone = Callable[[dict[str, Any]], None]
_PR_SET_PDEATHSIG = 1


def run_local(tasks: Sequence[Task], *, jobs: int, on_start: OnStart, on_done: OnDone) -> None:
    """Run the tasks, `jobs` at a time; call on_done with each row as it finishes."""
    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(["process.batch.tasks"])
    pending = list(reversed(tasks))
    running: dict[Connection, tuple[Any, Task]] = {}
    try:
        while pending or running:
            while pending and len(running) < jobs:
                task = pending.pop()
                receive, send = ctx.Pipe(duplex=False)
                child = ctx.Process(target=_child, args=(task, send), name=f"batch-{task.name}")
                child.start()
                send.close()
                running[receive] = (child, task)
                on_start(task)
            for ready in wait(list(running)):
                receive = cast(Connection, ready)
                child, task = running.pop(receive)
                on_done(_collect(receive, child, task))
    except BaseException:
        _stop([(child, task) for child, task in running.values()])
        raise


def _collect(receive: Connection, child: Any, task: Task) -> dict[str, Any]:
    """Return the child's row, or a failed row saying how the child died."""
    try:
        row: dict[str, Any] = receive.recv()
    except EOFError:
        row = {}
    finally:
        receive.close()
    child.join()
    if row:
        return row
    shutil.rmtree(task.partial_dir, ignore_errors=True)
    code = child.exitcode
    how = f"killed by {signal.Signals(-code).name}" if code and code < 0 else f"exit code {code}"
    return summary.failed_row(
        task.name, task.recording, f"worker process died ({how}; out of memory?)"
    )


def _stop(children: list[tuple[Any, Task]]) -> None:
    """Stop running children (SIGTERM, then SIGKILL) and remove their partial folders."""
    for child, _ in children:
        with contextlib.suppress(OSError):
            child.terminate()
    for child, task in children:
        child.join(timeout=10)
        if child.is_alive():
            child.kill()
            child.join()
        shutil.rmtree(task.partial_dir, ignore_errors=True)


def _raise_interrupt(signum: int, frame: object) -> NoReturn:
    raise KeyboardInterrupt


def _child(task: Task, send: Connection) -> None:
    """Body of one child process: process the task, send the row back."""
    from process.batch.tasks import process_one

    _die_with_parent()
    signal.signal(signal.SIGTERM, _raise_interrupt)  # cleans up like Ctrl-C
    send.send(process_one(task))
    send.close()


def _die_with_parent() -> None:
    """Ask Linux to SIGTERM this process when its parent (the forkserver) dies."""
    parent = os.getppid()
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)
    if os.getppid() != parent:  # the parent died before prctl took effect
        os.kill(os.getpid(), signal.SIGTERM)
