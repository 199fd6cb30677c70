"""Logging on a thread: calls keep their caller's timelines and order; errors reach the caller."""

from __future__ import annotations

import threading
from typing import Any

import pytest

from viz.background import BackgroundLogger
from viz.logger import NullLogger


class _Recorder(NullLogger):
    def __init__(self, *, fail_on: str | None = None) -> None:
        self.calls: list[tuple[str, Any]] = []
        self.fail_on = fail_on

    def set_frame(self, index: int, *, stamp_ns: int) -> None:
        self.calls.append(("frame", index))

    def set_stage(self, step: int) -> None:
        self.calls.append(("stage", step))

    def log_text(self, message: str, *, level: str = "INFO") -> None:
        if message == self.fail_on:
            raise OSError("no space left on device")
        self.calls.append(("text", message))


def test_each_thread_logs_at_its_own_frame() -> None:
    inner = _Recorder()
    log = BackgroundLogger(inner)
    log.set_frame(1, stamp_ns=10)
    log.log_text("main at 1")

    def worker() -> None:
        log.set_frame(7, stamp_ns=70)
        log.log_text("worker at 7")

    thread = threading.Thread(target=worker)
    thread.start()
    thread.join()
    log.log_text("main still at 1")
    log.close()
    assert inner.calls == [
        ("frame", 1),
        ("text", "main at 1"),
        ("frame", 7),
        ("text", "worker at 7"),
        ("frame", 1),
        ("text", "main still at 1"),
    ]


def test_a_failing_logger_raises_at_close_and_a_closed_one_refuses_calls() -> None:
    log = BackgroundLogger(_Recorder(fail_on="boom"))
    log.log_text("boom")
    with pytest.raises(OSError, match="no space"):
        log.close()
    with pytest.raises(RuntimeError, match="closed"):
        log.log_text("late")
