"""The cell's clock modes.

`realtime`: every machine's runner paces its IPO cycles to the wall clock (speed 1).
`fast`: the runners still step each machine cycle by cycle (lockstep inside the machine) but
do not wait for the wall clock while the machine is in a cycle. An idle machine has nothing
to hurry for, so the governor lets it tick at `IDLE_SPEED` instead of burning the CPU the
busy machines need (on a small host three free-running machines share one core).
"""

from __future__ import annotations

import threading

FAST_SPEED = 1000.0
IDLE_SPEED = 4.0
BUSY = frozenset({"ACTIVE", "INTERRUPTED", "FEED_HOLD", "OPTIONAL_STOP", "PROGRAM_STOPPED"})


class FastClockGovernor:
    """Sets each in-process runner's speed from its machine's execution state."""

    def __init__(self, runners, period_s: float = 0.01) -> None:
        self.runners = list(runners)
        self.period_s = period_s
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="fast-clock", daemon=True)

    def start(self) -> FastClockGovernor:
        self._thread.start()
        return self

    def _run(self) -> None:
        while not self._stop.wait(self.period_s):
            for runner in self.runners:
                busy = runner.machine.status.execution in BUSY
                runner.speed = FAST_SPEED if busy else IDLE_SPEED

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(2)
