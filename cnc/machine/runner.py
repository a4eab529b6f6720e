"""Realtime: a machine's lockstep core paced to the wall clock, lateness measured."""

from __future__ import annotations

import gc
import threading
import time
from array import array

from drives.realtime import RealtimeProcess, ThreadScheduling, request_fifo, sleep_until
from drives.realtime import rt_priority_from_env as drives_rt_priority

# the fast clock: a machine in a cycle runs at FAST_SPEED x real time (as fast as the CPU
# allows), an idle one at IDLE_SPEED: it has nothing to hurry for and leaves the CPU to the
# machines that cut (on a small host three free-running machines share one core)
FAST_SPEED = 1000.0
IDLE_SPEED = 4.0
BUSY = frozenset({"ACTIVE", "INTERRUPTED", "FEED_HOLD", "OPTIONAL_STOP", "PROGRAM_STOPPED"})

#: spin this long before a deadline instead of sleeping. A cycle is late only when its work
#: ends after the next slot, which a plain sleep's wake-up error (50-100 us) never causes,
#: while a spin costs its length in CPU every cycle (12 % of a core per machine at 2 ms
#: for the drives' 250 us): with several machines on one host that CPU is what they wait
#: for. So none by default; a lone machine that wants a precise wake-up can ask for one.
SPIN_S = 0.0

#: environment variable read by a runner given no rt_priority (0 or unset = off)
RT_PRIORITY_ENV = "FMSCELL_MACHINE_RT_PRIORITY"


class SampleRing:
    """The last `size` samples (seconds) in an array allocated once.

    A runner records two samples every IPO cycle for as long as the cell runs; as lists of
    floats (32 bytes a sample, trimmed from 200 000 to 100 000) they held about 13 MB per
    machine and kept the host's RSS climbing for minutes. Here: 8 bytes a sample, all of it
    allocated at the start."""

    def __init__(self, size: int = 100_000) -> None:
        self.size = size
        self._values = array("d", bytes(8 * size))
        self._count = 0

    def append(self, value: float) -> None:
        self._values[self._count % self.size] = value
        self._count += 1

    def __len__(self) -> int:
        return min(self._count, self.size)

    def __iter__(self):
        return iter(self._values[: len(self)])


def rt_priority_from_env(environ=None) -> int:
    """The SCHED_FIFO priority `FMSCELL_MACHINE_RT_PRIORITY` asks for; ValueError names it."""
    return drives_rt_priority(environ, RT_PRIORITY_ENV)


#: while a realtime runner is idle (no program running), the old generation of the garbage
#: collector, which the pacing never collects in a cycle's slack, is collected this often:
#: a long-running machine process must not keep its cyclic garbage forever, and a late
#: cycle of an idle machine costs nothing (its axes stand still)
OLD_GENERATION_EVERY_S = 60.0


class RealtimeRunner:
    """Steps `machine` once per IPO cycle at absolute deadlines (`speed` x real time).

    A cycle is late when its work ends after the next cycle's deadline; a whole slot missed
    is skipped (counted) rather than run back to back. `pause()`, `resume()`, `step(n)` and
    `speed` are the simulation face's clock control (thread-safe).

    `idle_speed`: the fast clock. When set, `speed` applies while a program is active
    (execution in `BUSY`) and `idle_speed` otherwise (`FAST_SPEED`, `IDLE_SPEED`).

    Paced at real time (`speed` <= 1, no `idle_speed`), it paces as the drives' shells do
    (`drives.realtime`): while `run()` runs, the process's garbage collector is frozen after
    setup and collects only in the slack before a deadline (the old generation while the
    machine is idle, every OLD_GENERATION_EVERY_S), the GIL switch interval is short, and it
    sleeps to a deadline (`spin_s`, none by default, is spun). `rt_priority` N (None =
    `FMSCELL_MACHINE_RT_PRIORITY`, 0 = off) asks SCHED_FIFO N for the stepping thread, as
    LinuxCNC's servo thread has, and puts the thread back to its old scheduling when `run()`
    returns; a refusal is reported in `scheduling` and the runner goes on as it can.
    `prepare()` collects and freezes ahead of `run()`. The machine's SHDR timestamps come
    from `wall_clock` (default `time.time`, UTC) once a runner owns it. The fast clock takes none of this: it
    never sleeps while cutting, so a FIFO thread would take a whole CPU from the rest of the
    process, and the slack the collector waits for never comes.
    """

    def __init__(
        self,
        machine,
        *,
        speed: float = 1.0,
        idle_speed: float | None = None,
        rt_priority: int | None = None,
        spin_s: float = SPIN_S,
        wall_clock=time.time,
    ) -> None:
        self.spin_s = spin_s
        if rt_priority is None:
            rt_priority = rt_priority_from_env()
        elif not 0 <= rt_priority <= 99:
            raise ValueError(f"rt_priority must be 0..99 (0 = off), got {rt_priority!r}")
        self.rt_priority = rt_priority
        self.scheduling = "SCHED_OTHER"
        self.machine = machine
        self.speed = speed
        self.idle_speed = idle_speed
        self.cycles = 0
        self.error: str | None = None
        self.late_cycles = 0
        self.skipped_slots = 0
        self.old_collections = 0  # full collections run while idle (paced at real time)
        self.lateness_s = SampleRing()  # the last 100 000 cycles
        self.work_s = SampleRing()
        self._stop = threading.Event()
        self._paused = threading.Event()
        self.paused_ack = threading.Event()  # set once the loop has stopped stepping
        self._steps = 0
        self._stepped = 0  # cycles run by step() requests
        self._lock = threading.Lock()
        self._prepared = False  # RealtimeProcess held (prepare())
        machine.runner = self
        # a paced machine (real time or the fast clock) reports wall-clock (UTC) timestamps:
        # a host or an MTConnect client compares them with its own clock, and machine time
        # falls behind the wall clock whenever the machine runs slow or is paused
        machine.wall_clock = wall_clock

    @property
    def paused(self) -> bool:
        return self._paused.is_set()

    def pause(self) -> None:
        self._paused.set()

    def resume(self) -> None:
        self._paused.clear()
        self.paused_ack.clear()

    def step(self, n: int) -> int:
        """While paused: run n more cycles; returns the count to wait for (`stepped`)."""
        with self._lock:
            self._steps += n
            return self._stepped + self._steps

    @property
    def stepped(self) -> int:
        with self._lock:
            return self._stepped

    def stop(self) -> None:
        self._stop.set()

    @property
    def paced(self) -> bool:
        """Paced at real time (or slower): the realtime measures of `run()` apply."""
        return self.idle_speed is None and self.speed <= 1.0

    def prepare(self) -> None:
        """Collect the process's garbage and freeze what setup left (`RealtimeProcess`) now,
        before the first cycle. `run()` does it itself when it is not done; a host that starts
        several machines at once calls it during their setup, so no machine's first cycles
        wait for a sibling's collection (tens of ms of CPU each)."""
        if self.paced and not self._prepared:
            RealtimeProcess.acquire()
            self._prepared = True

    def run(self, duration_s: float | None = None) -> dict:
        """Run until `stop()` or `duration_s` of wall time; returns `summary()`."""
        if not self.paced:
            if self.rt_priority:
                self.scheduling = (
                    f"SCHED_OTHER (SCHED_FIFO {self.rt_priority} not applied: "
                    "the fast clock does not sleep)"
                )
            if self._prepared:  # prepared, then the clock control changed the speed
                self._prepared = False
                RealtimeProcess.release()
            self._run(duration_s, paced=False)
            return self.summary()
        # the collection first, at the ordinary priority: at FIFO it would hold the CPU from
        # the other machines' cycles; and back to that priority before the summary (sorting
        # 10^5 samples) and whatever the thread does next (ThreadScheduling)
        self.prepare()
        try:
            saved = None
            if self.rt_priority:
                saved = ThreadScheduling()
                self.scheduling = request_fifo(self.rt_priority)
            try:
                self._run(duration_s, paced=True)
            finally:
                if saved is not None:
                    saved.restore()
        finally:
            self._prepared = False
            RealtimeProcess.release()
        return self.summary()

    def _run(self, duration_s: float | None, paced: bool) -> None:
        m = self.machine
        start = time.perf_counter()
        slot = start
        old_collected = start
        while not self._stop.is_set():
            now = time.perf_counter()
            if duration_s is not None and now - start >= duration_s:
                break
            if self._paused.is_set():
                self.paused_ack.set()
                with self._lock:
                    n, self._steps = self._steps, 0
                m.service()  # face commands are taken while paused too
                if n:
                    if not self._step_safely(n):
                        break
                    with self._lock:
                        self._stepped += n
                else:
                    time.sleep(0.001)
                slot = time.perf_counter()
                continue
            speed = self.speed
            idle = m.status.execution not in BUSY
            if self.idle_speed is not None and idle:
                speed = self.idle_speed
            period = m.ipo_s / speed
            slot += period
            now = time.perf_counter()
            if now > slot + period:
                missed = int((now - slot) / period)
                self.skipped_slots += missed
                slot += missed * period
            if paced:
                if idle and now - old_collected >= OLD_GENERATION_EVERY_S:
                    gc.collect()  # idle: the old generation too (what is frozen stays out)
                    self.old_collections += 1
                    old_collected = time.perf_counter()
                else:
                    RealtimeProcess.collect_in_slack(slot - time.perf_counter())
            sleep_until(slot, self.spin_s)
            woke = time.perf_counter()
            self.lateness_s.append(woke - slot)
            if not self._step_safely(1):
                break
            self.cycles += 1
            done = time.perf_counter()
            # the cycle's own work, wake-up to done: tells a late cycle that was ours (long
            # work) from one the OS made late (a late wake-up, or descheduled mid-cycle)
            self.work_s.append(done - woke)
            if done > slot + period:
                self.late_cycles += 1

    def _step_safely(self, n: int) -> bool:
        """Step; a failure inside the machine stops the runner with the reason kept in
        `error` (and the event log) instead of killing the process with a traceback."""
        try:
            self.machine.step(n)
        except Exception as exc:
            self.error = f"{type(exc).__name__}: {exc}"
            self.machine.events.add(self.machine.t, "stopped", f"machine stopped: {self.error}")
            return False
        return True

    def summary(self) -> dict:
        lat = sorted(self.lateness_s)
        work = sorted(self.work_s)

        def p(q: float, values: list[float] = lat) -> float:
            return values[min(len(values) - 1, int(q * len(values)))] * 1e3 if values else 0.0

        return {
            "cycles": self.cycles,
            "late_cycles": self.late_cycles,
            "late_fraction": self.late_cycles / self.cycles if self.cycles else 0.0,
            "skipped_slots": self.skipped_slots,
            "lateness_ms_p50": p(0.5),
            "lateness_ms_p99": p(0.99),
            "lateness_ms_max": lat[-1] * 1e3 if lat else 0.0,
            "work_ms_p50": p(0.5, work),
            "work_ms_p99": p(0.99, work),
            "work_ms_max": work[-1] * 1e3 if work else 0.0,
            "error": self.error,
            "scheduling": self.scheduling,
            "old_generation_collections": self.old_collections,
        }
