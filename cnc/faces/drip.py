"""The drip-feed (BTR) buffer between the DNC port and the NC: bounded, thread-safe.

The DNC port puts blocks in as they arrive; the NC takes them out as it executes. The
buffer's byte capacity is what the port's XOFF protects: above the high-water mark the port
stops reading and sends XOFF, below the low-water mark it sends XON. Memory therefore stays
bounded however long the program is.
"""

from __future__ import annotations

import threading
from collections import deque


class DripBuffer:
    END = None  # marker returned by take() once the tape's closing % has been taken

    def __init__(
        self, capacity_bytes: int = 4096, low_water: float = 0.25, high_water: float = 0.75
    ):
        if capacity_bytes < 256:
            raise ValueError("drip-feed buffer must hold at least 256 bytes")
        self.capacity = capacity_bytes
        self.low = int(capacity_bytes * low_water)
        self.high = int(capacity_bytes * high_water)
        self._blocks: deque[str] = deque()
        self._bytes = 0
        self._ended = False
        self._aborted: str | None = None
        self._lock = threading.Lock()
        self.blocks_in = 0
        self.blocks_out = 0
        self.max_fill = 0

    @property
    def fill(self) -> int:
        with self._lock:
            return self._bytes

    def above_high_water(self) -> bool:
        return self.fill >= self.high

    def below_low_water(self) -> bool:
        return self.fill <= self.low

    def put(self, block: str) -> None:
        """Add one block. The port keeps the buffer within capacity by flow control; a
        sender that ignores XOFF overruns it, which is reported, not absorbed."""
        size = len(block) + 1
        with self._lock:
            if self._bytes + size > self.capacity:
                raise OverflowError(
                    f"drip-feed buffer overrun: {self._bytes + size} > {self.capacity} bytes "
                    "(the sender ignored XOFF)"
                )
            self._blocks.append(block)
            self._bytes += size
            self.blocks_in += 1
            self.max_fill = max(self.max_fill, self._bytes)

    def end(self) -> None:
        with self._lock:
            self._ended = True

    def abort(self, reason: str) -> None:
        with self._lock:
            self._aborted = reason

    @property
    def aborted(self) -> str | None:
        with self._lock:
            return self._aborted

    def take(self) -> str | None | bool:
        """The next block; `False` when none is there yet (NC waits), `None` at the end."""
        with self._lock:
            if self._blocks:
                block = self._blocks.popleft()
                self._bytes -= len(block) + 1
                self.blocks_out += 1
                return block
            return self.END if self._ended else False
