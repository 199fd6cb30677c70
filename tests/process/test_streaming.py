"""A stage thread behind a bounded queue: order, back-pressure, offer without waiting, errors."""

from __future__ import annotations

import threading
from collections.abc import Iterator

import pytest

from process.errors import StageError
from process.streaming import Worker, prefetch


def test_items_are_handled_in_order_and_offer_refuses_when_the_queue_is_full() -> None:
    release = threading.Event()
    seen: list[int] = []

    def handle(item: int) -> None:
        release.wait(timeout=10)
        seen.append(item)

    worker: Worker[int] = Worker("test", handle, max_pending=2)
    assert worker.offer(0)  # taken by the thread, which then waits
    while worker._queue.qsize():  # until the thread holds item 0
        pass
    assert worker.offer(1) and worker.offer(2)
    assert not worker.offer(3)  # no room: refused at once, never queued
    release.set()
    worker.join()
    assert seen == [0, 1, 2] and worker.items == 3


def test_a_failing_stage_raises_in_the_producer() -> None:
    def handle(item: int) -> None:
        raise StageError(f"item {item} failed")

    worker: Worker[int] = Worker("test", handle)
    worker.submit(7)
    with pytest.raises(StageError, match="item 7 failed"):
        worker.join()


def test_prefetch_yields_in_order_and_raises_the_producers_error_in_place() -> None:
    def items() -> Iterator[int]:
        yield from range(5)
        raise StageError("frame 5 is damaged")

    got: list[int] = []
    with pytest.raises(StageError, match="frame 5 is damaged"):
        for item in prefetch(items(), name="test", ahead=2):
            got.append(item)
    assert got == [0, 1, 2, 3, 4]


def test_closing_prefetch_early_stops_the_producer_and_sets_stop() -> None:
    stop = threading.Event()
    produced: list[int] = []

    def items() -> Iterator[int]:  # like a follower: at the end, waits for input until stop
        for i in range(1000):
            produced.append(i)
            yield i
        stop.wait(timeout=30)

    stream = prefetch(items(), name="test", ahead=2, stop=stop)
    assert next(stream) == 0
    stream.close()  # the consumer failed or was interrupted
    assert stop.is_set() and len(produced) <= 5  # the producer stopped at once, ahead <= 2
