"""The realtime shell: a thread that paces `Runtime.scan` to the wall clock.

Time handed to the scan is the deadline's time (k x period), so timers count in whole
periods exactly as in lockstep; lateness (wake-up minus deadline) is measured and reported.
Missed deadlines are skipped (counted in `stats.missed`), never caught up in a burst.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable

from plc.runtime.core import Runtime


class RealtimeRunner:
    """Scans `runtime` every `period_ms` on its own thread until `stop()`."""

    def __init__(
        self,
        runtime: Runtime,
        period_ms: float | None = None,
        *,
        switch_interval: float | None = 0.0005,
        clock_ns: Callable[[], int] = time.monotonic_ns,
    ) -> None:
        self.runtime = runtime
        self.period_ms = float(period_ms or runtime.config.period_ms)
        self.switch_interval = switch_interval
        self.clock_ns = clock_ns
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.error: BaseException | None = None

    def start(self) -> None:
        if self._thread is not None:
            raise RuntimeError("runner already started")
        if self.switch_interval is not None:
            # a short GIL switch interval keeps the scan thread's wake-up lateness low
            # while other threads (Modbus) are busy; see the anchor measurements
            sys.setswitchinterval(min(sys.getswitchinterval(), self.switch_interval))
        self._thread = threading.Thread(target=self._loop, name="plc-scan", daemon=True)
        self._thread.start()

    def stop(self, timeout: float = 2.0) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)
        self.runtime.close()

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def _loop(self) -> None:
        period_ns = int(self.period_ms * 1e6)
        start = self.clock_ns()
        k = 0
        try:
            while not self._stop.is_set():
                deadline = start + k * period_ns
                now = self.clock_ns()
                while now < deadline:  # an early wake-up waits again
                    if self._stop.wait((deadline - now) / 1e9):
                        return
                    now = self.clock_ns()
                behind = (now - deadline) // period_ns
                if behind > 0:  # skip whole missed periods
                    self.runtime.stats.missed += int(behind)
                    k += int(behind)
                    deadline = start + k * period_ns
                late_ms = (now - deadline) / 1e6
                self.runtime.scan(int(round(k * self.period_ms)), late_ms)
                k += 1
        except BaseException as exc:  # surfaced to the caller through .error
            self.error = exc
