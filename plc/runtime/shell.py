"""The realtime shell: a thread that paces `Runtime.scan` to the wall clock.

Time handed to the scan is the deadline's time (k x period), so timers count in whole
periods exactly as in lockstep; lateness (wake-up minus deadline) is measured and reported.
Missed deadlines are skipped (counted in `stats.missed`), never caught up in a burst.

Staying on time beside busy threads (see plc/runtime/realtime.py): the runner announces every
deadline on its `gate` (a `ScanGate`) so that a face built with `scan_gate=runner.gate`
steps aside before each scan, and with `rt_priority` (or FMSCELL_PLC_RT_PRIORITY) it asks
SCHED_FIFO for the scan thread.
"""

from __future__ import annotations

import logging
import sys
import threading
import time
from collections.abc import Callable

from plc.runtime.core import Runtime
from plc.runtime.realtime import (
    ScanGate,
    check_rt_priority,
    guard_for_period,
    promote_current_thread,
    rt_priority_from_env,
)

log = logging.getLogger("plc.runtime")


class RealtimeRunner:
    """Scans `runtime` every `period_ms` on its own thread until `stop()`.

    `rt_priority`: SCHED_FIFO priority for the scan thread (1..99; 0 = ordinary scheduling;
    None = FMSCELL_PLC_RT_PRIORITY, default 0). A refusal is logged and shown in
    `scheduling`; the PLC runs anyway. `gate_guard_s`: how long before each deadline the
    threads using `gate` step aside (None: 0.7 ms, at most 7 % of the period).
    """

    def __init__(
        self,
        runtime: Runtime,
        period_ms: float | None = None,
        *,
        switch_interval: float | None = 0.0005,
        clock_ns: Callable[[], int] = time.monotonic_ns,
        rt_priority: int | None = None,
        gate_guard_s: float | None = None,
        promote: Callable[[int], tuple[bool, str]] = promote_current_thread,
    ) -> None:
        self.runtime = runtime
        self.period_ms = float(period_ms or runtime.config.period_ms)
        self.switch_interval = switch_interval
        self.clock_ns = clock_ns
        if rt_priority is None:
            rt_priority = rt_priority_from_env()
        check_rt_priority(rt_priority)
        self.rt_priority = rt_priority
        self._promote = promote
        #: what the scan thread got: "SCHED_FIFO 20", "SCHED_OTHER (... refused: ...)"
        self.scheduling = "not started"
        self.gate = ScanGate(
            guard_for_period(self.period_ms) if gate_guard_s is None else gate_guard_s
        )
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._started = threading.Event()
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
        self._started.wait(5.0)  # `scheduling` is known when start() returns

    def stop(self, timeout: float = 2.0) -> None:
        self._stop.set()
        self.gate.close()
        if self._thread is not None:
            self._thread.join(timeout)
        self.runtime.close()

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def _loop(self) -> None:
        try:
            granted, self.scheduling = self._promote(self.rt_priority)
            if self.rt_priority and not granted:
                log.warning("PLC scan thread: %s", self.scheduling)
        finally:
            self._started.set()
        period_ns = int(self.period_ms * 1e6)
        gate = self.gate
        start = self.clock_ns()
        k = 0
        try:
            while not self._stop.is_set():
                deadline = start + k * period_ns
                gate.announce(deadline / 1e9)
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
                try:
                    self.runtime.scan(int(round(k * self.period_ms)), late_ms)
                finally:
                    gate.passed()
                k += 1
        except BaseException as exc:  # surfaced to the caller through .error
            self.error = exc
        finally:
            gate.close()
