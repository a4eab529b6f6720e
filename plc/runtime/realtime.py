"""What keeps a Python scan thread on time next to busy threads in the same process.

Measured cause of late scans under Modbus load (bench/bench_plc_lateness.py, docs/ladder.md
§7): not garbage collection (2 young collections in 10 s, 0.25 ms at most) but two waits
after the scan's timer fires: (1) for a CPU, when the box is busy, and (2) for the GIL, held
by the Modbus face's thread, which may itself be waiting for a CPU while holding it. A
shorter GIL switch interval shortens (2) only while the holder is running.

Remedies, all opt-in per deployment:

* `ScanGate`: the runner announces each scan's deadline; a cooperating thread (the Modbus
  face) that finds itself within `guard_s` of the deadline steps aside, i.e. waits without
  the GIL until that scan has published. Cost: the face pauses about guard + scan time once
  per period, and only while it is busy. It cannot help when the OS deschedules the face
  while it holds the GIL *before* its check; hence the third remedy.
* `rt_priority`: SCHED_FIFO for the scan thread (as OpenPLC's runtime and LinuxCNC's RT
  threads have), so its timer wake-up preempts ordinary processes: remedy for (1). Needs
  CAP_SYS_NICE (root in most containers has it); refused, the scan runs as before and the
  runner says so.
* SCHED_FIFO for the face's thread, below the scan's (`ModbusFace.start_in_thread(
  rt_priority=...)`), so ordinary processes cannot deschedule it while it holds the GIL.

Measured effect of each and together: docs/ladder.md, "Staying on time beside a busy Modbus
face".
"""

from __future__ import annotations

import math
import os
import threading
from collections.abc import Callable

#: Environment variable read by `RealtimeRunner` when no `rt_priority` is given, so
#: `fmscell plc run` (and any other host of a runner) can ask for SCHED_FIFO without a flag.
RT_PRIORITY_ENV = "FMSCELL_PLC_RT_PRIORITY"

#: Default guard: the face steps aside this long before each deadline, at most 7 % of the
#: period. 0.3 ms was measured too short on the 2-core box (the face thread, descheduled
#: with the GIL held, reaches its next check too late); 0.7 ms held p99 < 0.35 ms there.
DEFAULT_GUARD_S = 0.0007
GUARD_SHARE_OF_PERIOD = 0.07


class ScanGate:
    """The next scan's deadline, published by the scan thread for the threads beside it.

    Times are seconds on the runner's clock, which is `time.monotonic` unless a test
    injects another. `step_aside_at` is the time from which a cooperating thread should
    call `step_aside()` (infinity while no scan is pending, e.g. during a scan).
    """

    def __init__(self, guard_s: float = DEFAULT_GUARD_S, max_hold_s: float = 0.003) -> None:
        if not 0 <= guard_s < 1 or not 0 < max_hold_s < 1:
            raise ValueError(
                f"ScanGate: guard_s {guard_s!r} must be in [0, 1) s and max_hold_s "
                f"{max_hold_s!r} in (0, 1) s"
            )
        self.guard_s = guard_s
        self.max_hold_s = max_hold_s
        self.due = math.inf
        self.step_aside_at = math.inf
        self.scans = 0  # scans passed since the gate was made
        self.holds = 0  # times a thread stepped aside
        self.hold_timeouts = 0  # ... and gave up after max_hold_s without seeing the scan
        self._cond = threading.Condition(threading.Lock())

    # -- the scan thread -------------------------------------------------------------------

    def announce(self, due: float) -> None:
        """The next scan is due at `due` (called before the scan thread goes to sleep)."""
        self.due = due
        self.step_aside_at = due - self.guard_s

    def passed(self) -> None:
        """The announced scan has published: release whoever stepped aside for it."""
        with self._cond:
            self.scans += 1
            self.due = self.step_aside_at = math.inf
            self._cond.notify_all()

    def close(self) -> None:
        """No more scans (runner stopped): release waiters, never hold again."""
        self.passed()

    # -- a thread beside the scan ----------------------------------------------------------

    def should_step_aside(self, now: float) -> bool:
        return now >= self.step_aside_at

    def step_aside(self, now: float) -> bool:
        """If a scan is due within the guard at `now`, wait (the GIL released) until it has
        passed, at most `max_hold_s`. True if the thread waited for a scan that passed,
        False if there was nothing to wait for or the hold timed out."""
        with self._cond:
            if now < self.step_aside_at:  # the scan passed between the caller's check and here
                return False
            ticket = self.scans
            self.holds += 1
            if self._cond.wait_for(lambda: self.scans != ticket, self.max_hold_s):
                return True
            self.hold_timeouts += 1
            return False


def guard_for_period(period_ms: float) -> float:
    """The default guard for a scan period, in seconds."""
    return min(DEFAULT_GUARD_S, GUARD_SHARE_OF_PERIOD * period_ms / 1000.0)


def rt_priority_from_env(environ: dict[str, str] | None = None) -> int:
    """SCHED_FIFO priority asked for by `FMSCELL_PLC_RT_PRIORITY` (0, the default, = off)."""
    raw = (os.environ if environ is None else environ).get(RT_PRIORITY_ENV, "").strip()
    if not raw:
        return 0
    try:
        value = int(raw)
    except ValueError:
        raise ValueError(f"{RT_PRIORITY_ENV}={raw!r}: not an integer (0 = off, 1..99)") from None
    check_rt_priority(value, RT_PRIORITY_ENV)
    return value


def check_rt_priority(value: int, where: str = "rt_priority") -> None:
    if not 0 <= value <= 99:
        raise ValueError(f"{where}={value}: SCHED_FIFO priorities are 1..99 (0 = off)")


def _set_fifo(priority: int) -> None:
    # pid 0 = the calling thread on Linux (a thread's scheduling policy is its own)
    os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))


def promote_current_thread(
    priority: int, setter: Callable[[int], None] | None = None
) -> tuple[bool, str]:
    """Ask SCHED_FIFO `priority` for the calling thread. Returns (granted, description);
    a refusal (no privilege, no such policy on this OS) is reported, never raised."""
    if priority == 0:
        return False, "SCHED_OTHER (rt_priority 0)"
    if setter is None:
        if not hasattr(os, "sched_setscheduler"):
            return False, f"SCHED_OTHER (SCHED_FIFO {priority} not available on this OS)"
        setter = _set_fifo
    try:
        setter(priority)
    except OSError as exc:
        reason = exc.strerror or type(exc).__name__
        return False, f"SCHED_OTHER (SCHED_FIFO {priority} refused: {reason})"
    return True, f"SCHED_FIFO {priority}"
