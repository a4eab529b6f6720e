"""The realtime shell, driven by a fake monotonic clock so the test never sleeps: scan times
are the deadlines (k x period), lateness is measured, missed periods are skipped."""

from __future__ import annotations

import threading

from plc.ladder import compile_text
from plc.runtime import RealtimeRunner, Runtime, RuntimeConfig

PROGRAM = "TAG T : TIMER\nXIC %IX0.0 TON T 30\nXIC T.DN OTE %QX0.0\n"


class ScriptedClock:
    """Each call returns the next scripted time (ns); the script repeats its last value."""

    def __init__(self, times_ms: list[float]) -> None:
        self.times = [int(t * 1e6) for t in times_ms]
        self.i = 0

    def __call__(self) -> int:
        t = self.times[min(self.i, len(self.times) - 1)]
        self.i += 1
        return t


class StopAfter:
    """I/O provider that records each scan's time and stops the runner after n scans."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.now: list[int] = []
        self.done = threading.Event()
        self.runner: RealtimeRunner | None = None

    def read_inputs(self, ix, iw, now_ms):
        ix[0] = True
        self.now.append(now_ms)
        if len(self.now) >= self.n:
            self.runner._stop.set()
            self.done.set()

    def write_outputs(self, qx, qw, now_ms):
        pass


def test_runner_paces_on_deadlines_and_skips_missed_periods():
    io = StopAfter(5)
    rt = Runtime(compile_text(PROGRAM, "rt.ld"), RuntimeConfig(period_ms=10), io=io)
    # clock reads: start, then "now" before each scan (and again after a wait); after the
    # second scan the process stalls (two whole periods missed), then runs on time again
    clock = ScriptedClock([0, 0.5, 10.2, 40.0, 40.1, 50.3, 60.0])
    runner = RealtimeRunner(rt, clock_ns=clock, switch_interval=None)
    io.runner = runner
    runner.start()
    assert io.done.wait(5)
    runner.stop()
    assert runner.error is None
    assert io.now[:4] == [0, 10, 40, 50]
    assert io.now == [0, 10, 40, 50, 60]
    assert [round(x, 3) for x in rt.stats.late_ms] == [0.5, 0.2, 0.0, 0.3, 0.0]
    assert rt.stats.missed == 2
    assert rt.read("T.ACC") == 30 and rt.read("%QX0.0") is True  # timers on deadline time
