"""Scan statistics: execution time and wake-up lateness, min/mean/max/p99, overruns."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class Summary:
    count: int
    min: float
    mean: float
    max: float
    p99: float


def _summary(samples: deque[float], count: int, total: float, lo: float, hi: float) -> Summary:
    if not samples:
        return Summary(0, 0.0, 0.0, 0.0, 0.0)
    ordered = sorted(samples)
    p99 = ordered[min(len(ordered) - 1, int(0.99 * len(ordered)))]
    return Summary(count, lo, total / count, hi, p99)


class ScanStats:
    """Running figures over every scan; p99 over the last `window` scans (bounded memory)."""

    def __init__(self, window: int = 10_000) -> None:
        self.exec_us: deque[float] = deque(maxlen=window)
        self.late_ms: deque[float] = deque(maxlen=window)
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
