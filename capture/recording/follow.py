"""Read a recording while it is still being written: reads wait for bytes that are not there yet.

The writer closes a chunk at least every second (RECORDING.md), so a reader that waits at the
end of the file sees whole chunks arrive. MCAP's stream reader asks for exact record lengths;
`GrowingFile.read` returns them once written, and returns short (the reader's end of stream)
when the file has not grown for `idle_s` seconds, or when `stop` is set (Ctrl-C). A finished
recording ends by itself: the stream reader stops after the footer.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any, Final, cast

from mcap.stream_reader import StreamReader

logger = logging.getLogger(__name__)

_POLL_S: Final = 0.02


class GrowingFile:
    """A binary file whose reads wait for the writer, up to an idle timeout."""

    def __init__(self, path: Path, *, idle_s: float, stop: threading.Event | None = None) -> None:
        self.path = path
        self.idle_s = idle_s
        self.stop = stop or threading.Event()
        self._file: IO[bytes] = path.open("rb")
        self._grew_mono = time.monotonic()
        self._size = path.stat().st_size

    def read(self, size: int = -1) -> bytes:
        """Return `size` bytes once written; fewer only when the writer went idle or stop is set."""
        if size < 0:
            return self._file.read()
        parts = [self._file.read(size)]
        missing = size - len(parts[0])
        while missing > 0 and self._wait():
            more = self._file.read(missing)
            parts.append(more)
            missing -= len(more)
        return b"".join(parts)

    def seek(self, offset: int, whence: int = 0) -> int:
        """Move the read position (as a file)."""
        return self._file.seek(offset, whence)

    def tell(self) -> int:
        """Return the read position."""
        return self._file.tell()

    def close(self) -> None:
        """Close the file."""
        self._file.close()

    def _wait(self) -> bool:
        """Sleep until the file grows; return False when it stayed idle too long or stop is set."""
        while not self.stop.is_set():
            size = self.path.stat().st_size
            now = time.monotonic()
            if size != self._size:
                self._size, self._grew_mono = size, now
                return True
            if now - self._grew_mono > self.idle_s:
                return False
            time.sleep(_POLL_S)
        return False


def follow_records(stream: GrowingFile, path: Path) -> Iterator[Any]:
    """Yield the records of a file being written as they arrive.

    The stream ends at the footer, when the writer stays idle, or at a record that cannot be
    read (a damaged or half-written chunk: what came before it is kept).
    """
    stream.seek(0)
    try:
        yield from StreamReader(cast(IO[bytes], stream)).records
    except Exception as err:  # the idle end (a short read) or a damaged chunk: no common base
        logger.debug("followed recording ends (%s): %s", err, path)
