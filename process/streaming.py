"""A stage on its own thread behind a bounded queue, with its wall and CPU time measured.

The pipeline's odometry runs on the main thread; keyframe work (segmentation, fusion) and
logging run beside it. Threads rather than processes: the heavy parts (torch, OpenCV, Open3D,
NumPy, Rerun's encoders) release the GIL, frames need no copying between them, and a thread's
CPU time can be read (`time.thread_time`). The queue is bounded, so a slow stage holds the
producer back instead of letting memory grow; the time the producer waits is recorded as the
share of the run that this stage was the bottleneck.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable, Generator, Iterator
from typing import Final, Generic, TypeVar

T = TypeVar("T")
_STOP: Final = object()


class Worker(Generic[T]):
    """Run `handle(item)` for every submitted item on one thread, in order."""

    def __init__(self, name: str, handle: Callable[[T], None], *, max_pending: int = 4) -> None:
        self.name = name
        self._handle = handle
        self._queue: queue.Queue[object] = queue.Queue(maxsize=max_pending)
        self._error: BaseException | None = None
        self.seconds = 0.0  # wall time spent in handle()
        self.cpu_seconds = 0.0  # CPU time of this thread in handle()
        self.blocked_seconds = 0.0  # time submit() waited for a free slot: this stage was behind
        self.items = 0
        self._thread = threading.Thread(target=self._run, name=f"semreplay-{name}", daemon=True)
        self._thread.start()

    def submit(self, item: T) -> None:
        """Queue an item; wait while the queue is full; raise the worker's error if it failed."""
        self._raise_if_failed()
        t0 = time.perf_counter()
        self._queue.put(item)
        self.blocked_seconds += time.perf_counter() - t0

    def offer(self, item: T) -> bool:
        """Queue an item if there is room now; return whether it was queued (never waits)."""
        self._raise_if_failed()
        try:
            self._queue.put_nowait(item)
        except queue.Full:
            return False
        return True

    def join(self) -> None:
        """Handle every queued item, stop the thread and raise its error if it failed."""
        if self._thread.is_alive():
            self._queue.put(_STOP)
            self._thread.join()
        self._raise_if_failed()

    def _raise_if_failed(self) -> None:
        if self._error is not None:
            error, self._error = self._error, None
            raise error

    def _run(self) -> None:
        while (item := self._queue.get()) is not _STOP:
            if self._error is not None:
                continue  # drain without work after a failure; join() reports it
            t0, c0 = time.perf_counter(), time.thread_time()
            try:
                self._handle(item)  # type: ignore[arg-type]
            except BaseException as err:  # handed to the producer at its next submit/join
                self._error = err
            self.seconds += time.perf_counter() - t0
            self.cpu_seconds += time.thread_time() - c0
            self.items += 1


def prefetch(
    items: Iterator[T], *, name: str, ahead: int = 4, stop: threading.Event | None = None
) -> Generator[T, None, None]:
    """Yield `items`, produced on a thread of their own up to `ahead` items in advance.

    The producer's errors are raised here, in order. Closing the generator early (an error or
    Ctrl-C in the consumer) sets `stop` (which a producer waiting for input, such as a reader
    following a growing file, watches) and waits for the producer to stop at its next item.
    """
    out: queue.Queue[tuple[bool, object]] = queue.Queue(maxsize=ahead)
    closed = threading.Event()

    def put(done: bool, value: object) -> bool:
        while not closed.is_set():
            try:
                out.put((done, value), timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def produce() -> None:
        try:
            for item in items:
                if not put(False, item):
                    return
        except BaseException as err:  # handed to the consumer in order
            put(True, err)
            return
        put(True, _STOP)

    thread = threading.Thread(target=produce, name=f"semreplay-{name}", daemon=True)
    thread.start()
    try:
        while True:
            done, value = out.get()
            if not done:
                yield value  # type: ignore[misc]
                continue
            if isinstance(value, BaseException):
                raise value
            return
    finally:
        closed.set()
        if stop is not None:
            stop.set()
        thread.join()
