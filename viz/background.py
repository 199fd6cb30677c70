"""A `Logger` that hands every call to a thread, so encoding the `.rrd` overlaps the work.

Rerun's timelines are per thread, and the pipeline logs from more than one thread (frames from
the odometry loop, segmentations from the keyframe worker). Each caller's `set_frame`/`set_stage`
is therefore kept per calling thread and travels with every call it makes; the logging thread
sets the inner logger's timelines before a call whenever they differ from the last call's.
"""

from __future__ import annotations

import queue
import threading
import time
from typing import Any, Final

from viz.logger import Logger, NullLogger

_STOP: Final = object()


class BackgroundLogger(NullLogger):
    """Forward every logging call to `inner` on one background thread, in call order."""

    def __init__(self, inner: Logger, *, max_pending: int = 64) -> None:
        self._inner = inner
        self._queue: queue.Queue[Any] = queue.Queue(maxsize=max_pending)
        self._local = threading.local()
        self._error: BaseException | None = None
        self._closed = False
        self.seconds = 0.0  # wall time the logging thread spent in the inner logger
        self.cpu_seconds = 0.0
        self.blocked_seconds = 0.0  # time callers waited for a free slot: logging was behind
        self._thread = threading.Thread(target=self._drain, name="semreplay-viz", daemon=True)
        self._thread.start()

    def set_frame(self, index: int, *, stamp_ns: int) -> None:
        """Set the calling thread's `frame` and `capture_time` for the calls it makes next."""
        self._local.frame = (index, stamp_ns)

    def set_stage(self, step: int) -> None:
        """Set the calling thread's `stage` for the calls it makes next."""
        self._local.stage = step

    def __getattribute__(self, name: str) -> Any:
        if not name.startswith("log_"):
            return object.__getattribute__(self, name)
        this = object.__getattribute__

        def call(*args: Any, **kwargs: Any) -> None:
            if this(self, "_closed"):  # nothing drains the queue any more: it would block
                raise RuntimeError(f"{name} after close(): the logger is closed")
            this(self, "_raise_if_failed")()
            local = this(self, "_local")
            context = (getattr(local, "frame", None), getattr(local, "stage", None))
            t0 = time.perf_counter()
            this(self, "_queue").put((context, name, args, kwargs))
            self.blocked_seconds += time.perf_counter() - t0

        return call

    def close(self) -> None:
        """Log everything still pending, stop the thread and close the inner logger."""
        if self._closed:
            return
        self._closed = True
        self._queue.put(_STOP)
        self._thread.join()
        self._inner.close()
        self._raise_if_failed()

    def _raise_if_failed(self) -> None:
        if self._error is not None:
            error, self._error = self._error, None
            raise error

    def _drain(self) -> None:
        frame: tuple[int, int] | None = None
        stage: int | None = None
        while (item := self._queue.get()) is not _STOP:
            if self._error is not None:
                continue  # a failed logger takes no more calls; close() reports the error
            (want_frame, want_stage), name, args, kwargs = item
            t0, c0 = time.perf_counter(), time.thread_time()
            try:
                if want_frame is not None and want_frame != frame:
                    frame = want_frame
                    self._inner.set_frame(frame[0], stamp_ns=frame[1])
                if want_stage is not None and want_stage != stage:
                    stage = want_stage
                    self._inner.set_stage(stage)
                getattr(self._inner, name)(*args, **kwargs)
            except BaseException as err:  # handed to the caller at its next call or close()
                self._error = err
            self.seconds += time.perf_counter() - t0
            self.cpu_seconds += time.thread_time() - c0
