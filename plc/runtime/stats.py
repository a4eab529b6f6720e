"""Scan statistics: execution time and wake-up lateness, min/mean/max/p99, overruns."""

from __future__ import annotations

from array import array
from collections.abc import Iterator
from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class Summary:
    count: int
    min: float
    mean: float
    max: float
    p99: float


class Window:
    """The last `size` samples, oldest first, in one array of doubles allocated up front.

    A `deque(maxlen=...)` of floats grows by a float object (24 bytes) and a slot per sample
    until it is full: 10 000 scans at the realtime scan rate take minutes to an hour, so a
    host running three machines grew for that long (about 2 MB). This one takes its full size
    (8 bytes a sample) at once and never grows."""

    __slots__ = ("_data", "_next", "_len")

    def __init__(self, size: int) -> None:
        if size < 1:
            raise ValueError(f"scan statistics window must be >= 1 scan, got {size}")
        self._data = array("d", bytes(8 * size))
        self._next = 0  # where the next sample goes
        self._len = 0

    @property
    def size(self) -> int:
        return len(self._data)

    def append(self, value: float) -> None:
        data, i = self._data, self._next
        data[i] = value
        i += 1
        self._next = 0 if i == len(data) else i
        if self._len < len(data):
            self._len += 1

    def __len__(self) -> int:
        return self._len

    def __iter__(self) -> Iterator[float]:
        data, n = self._data, self._len
        start = (self._next - n) % len(data)
        for k in range(n):
            yield data[(start + k) % len(data)]

    def __getitem__(self, index: int) -> float:
        """One sample by position, oldest 0, newest -1 (as a list or deque)."""
        n = self._len
        if not -n <= index < n:
            raise IndexError(f"scan statistics window index {index} out of range ({n} samples)")
        if index < 0:
            index += n
        return self._data[(self._next - n + index) % len(self._data)]


def _summary(samples: Window, count: int, total: float, lo: float, hi: float) -> Summary:
    if not samples:
        return Summary(0, 0.0, 0.0, 0.0, 0.0)
    ordered = sorted(samples)
    p99 = ordered[min(len(ordered) - 1, int(0.99 * len(ordered)))]
    return Summary(count, lo, total / count, hi, p99)


class ScanStats:
    """Running figures over every scan; p99 over the last `window` scans (bounded memory)."""

    def __init__(self, window: int = 10_000) -> None:
        self.exec_us = Window(window)
        self.late_ms = Window(window)
        self.count = 0
        self.overruns = 0
        self.missed = 0
        self._exec_sum = self._late_sum = 0.0
        self._exec_min = self._late_min = float("inf")
        self._exec_max = self._late_max = 0.0

    def record(self, exec_us: float, late_ms: float, overrun: bool) -> None:
        self.count += 1
        self.exec_us.append(exec_us)
        self.late_ms.append(late_ms)
        self._exec_sum += exec_us
        self._late_sum += late_ms
        self._exec_min = min(self._exec_min, exec_us)
        self._exec_max = max(self._exec_max, exec_us)
        self._late_min = min(self._late_min, late_ms)
        self._late_max = max(self._late_max, late_ms)
        if overrun:
            self.overruns += 1

    def execution(self) -> Summary:
        """Scan execution time in µs."""
        return _summary(self.exec_us, self.count, self._exec_sum, self._exec_min, self._exec_max)

    def lateness(self) -> Summary:
        """Wake-up lateness against the scan deadline in ms (0 in lockstep)."""
        return _summary(self.late_ms, self.count, self._late_sum, self._late_min, self._late_max)

    def as_dict(self) -> dict:
        e, la = self.execution(), self.lateness()
        return {
            "scans": self.count,
            "overruns": self.overruns,
            "missed": self.missed,
            "exec_us": {"min": e.min, "mean": e.mean, "max": e.max, "p99": e.p99},
            "late_ms": {"min": la.min, "mean": la.mean, "max": la.max, "p99": la.p99},
        }
