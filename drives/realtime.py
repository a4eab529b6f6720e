"""Pacing for the realtime shells: absolute deadlines, sleep then spin, the GC in the slack.

Three things made a 1 ms cycle late on an otherwise idle machine, measured with
`bench/bench_drives_realtime.py`:

* the cyclic garbage collector: a young collection (~0.1 ms) every few cycles, a middle one
  (~1 ms) every ~10 of those, and now and then a full one through every object of the
  process (the canopen object dictionaries of every node: tens of ms). Python starts them
  on allocation counts, i.e. in the middle of a cycle's work;
* `time.sleep` wakes up late (timer slack, scheduler), by 50-100 us typically and by far
  more when the machine is busy;
* the GIL's switch interval (5 ms by default): another Python thread that holds the GIL
  delays a realtime thread by up to that long.

`RealtimeProcess` takes the collector out of the cycles while any realtime shell runs: it
collects once and freezes what exists after setup (`gc.freeze`: the long-lived object
dictionaries are never traversed again), raises the automatic collector's threshold to
FORCED_THRESHOLD allocations and lets the pacers collect the young generation in the slack
before a deadline as soon as YOUNG_THRESHOLD are pending (the middle one every 10th time,
when the slack holds what it measured to take: see `collect_in_slack`). While the pacers
run, the automatic collector never triggers; if they stop (an idle axis group that was
never closed) it still does, at the higher threshold, so memory stays bounded. The old
generation is not collected in the slack: its size is unknown (in a host that was busy
before, a full collection takes 100s of ms), so cyclic garbage that survives a young
collection may wait until the last shell stops. It also shortens the switch interval. Both
are process-wide settings, so they are reference-counted and restored when the last shell
stops.

`Pacer` waits for absolute deadlines: it sleeps until `spin_s` before the deadline and
spins the rest (calling `sleep(0)`, which releases the GIL but returns at once), so the
wake-up error is the spin loop's, not the timer's.

What none of that helps against is the OS giving the CPU to another task at the deadline.
With that done, the few late cycles that remain are the OS's (measured per late cycle from
`/proc/thread-self/schedstat`, see docs/drives.md): with ordinary scheduling the pacing
thread sat on the run queue for as long as it was late (another task kept the CPU until its
slice ended, on a tick: 4 ms at HZ=250), while the cycle's own work stays under 0.8 ms, no
collection, page fault or other thread of ours in them; a no-work pacer, even one in C,
misses slots the same way on the same box.

Opt-in, as LinuxCNC's RT threads and the PLC's scan thread do: a pacer with `rt_priority` N
(or `FMSCELL_DRIVES_RT_PRIORITY=N` in the environment) asks SCHED_FIFO N for the thread that
paces, on its first wait, and with `cpu` C (or `FMSCELL_DRIVES_RT_CPU=C`, as LinuxCNC's
RTAPI_CPU_NUMBER) pins it to CPU C, which pays on a CPU kept free for it (`isolcpus=`).
Both need privileges (CAP_SYS_NICE) or a valid CPU; a refusal is reported in
`Pacer.scheduling`, never raised, and the shell runs as it can. What SCHED_FIFO cannot fix is
a kernel that does not preempt kernel code (`preempt=none`) or a hypervisor that takes the
vCPU: a real-time kernel (PREEMPT_RT, or at least `preempt=full`) is the user's part.
"""

from __future__ import annotations

import gc
import os
import sys
import threading
import time

#: spin this long before a deadline instead of sleeping (covers the usual sleep overshoot)
SPIN_S = 250e-6
#: GIL switch interval while realtime shells run (CPython's default is 5 ms)
SWITCH_INTERVAL_S = 0.0005
#: collect the youngest generation once this many container allocations are pending
YOUNG_THRESHOLD = 700
#: the automatic collector's threshold meanwhile (it runs only if the pacers do not)
FORCED_THRESHOLD = 50 * YOUNG_THRESHOLD
#: slack needed before a deadline to start a young / middle collection (at least)
SLACK_FOR_GENERATION_S = (0.2e-3, 0.5e-3)
#: a middle collection also needs this much more slack than its recent measured durations
MIDDLE_MARGIN = 1.25


_clock = time.perf_counter  # times the collections (replaceable for tests)


class RealtimeProcess:
    """Process-wide realtime settings, reference-counted by the shells that need them."""

    _lock = threading.Lock()
    _users = 0
    _saved_switch: float | None = None
    _saved_threshold: tuple[int, ...] | None = None
    _young_collections = 0  # since the last middle collection
    middle_durations_s: list[float] = []  # the last three middle collections' (s)
    collections = [0, 0]  # collections run in the slack: young, middle
    middle_postponed = 0  # middle collections due that no slack could hold (a young one ran)
    forced_collections = 0  # collections that could not wait for slack

    @classmethod
    def acquire(cls) -> None:
        """First user: collect, freeze the survivors, the automatic collector's threshold
        up, short switch interval."""
        with cls._lock:
            cls._users += 1
            if cls._users > 1:
                return
            gc.collect()
            gc.freeze()  # setup's objects (object dictionaries, EDS) leave the collector
            cls._young_collections, cls.middle_durations_s = 0, []  # a new middle generation
            cls._saved_threshold = gc.get_threshold()
            gc.set_threshold(FORCED_THRESHOLD, *cls._saved_threshold[1:])
            cls._saved_switch = sys.getswitchinterval()
            sys.setswitchinterval(min(cls._saved_switch, SWITCH_INTERVAL_S))

    @classmethod
    def release(cls) -> None:
        """Last user gone: the collector and the switch interval as they were."""
        with cls._lock:
            if cls._users == 0:
                return
            cls._users -= 1
            if cls._users:
                return
            if cls._saved_threshold is not None:
                gc.set_threshold(*cls._saved_threshold)
                cls._saved_threshold = None
            gc.unfreeze()
            if cls._saved_switch is not None:
                sys.setswitchinterval(cls._saved_switch)
                cls._saved_switch = None

    @classmethod
    def active(cls) -> bool:
        return cls._users > 0

    @classmethod
    def collect_in_slack(cls, slack_s: float) -> None:
        """Run the collection that is due if `slack_s` (time to the next deadline) allows.

        A middle collection after every 9 young ones (CPython's own ratio), when the slack
        holds it: its cost is the objects that survived the young collections since the
        last one, which the shells' own long-lived objects can make longer than a whole
        cycle (1.3-2.1 ms measured, for 0 objects freed), so it needs MIDDLE_MARGIN times
        the shortest of its last three durations. Until a slack holds it, the young
        collection runs instead and the middle one stays due. A young collection waits for
        its slack, unless FORCED_THRESHOLD allocations are pending.
        """
        if cls._users == 0:
            return
        pending = gc.get_count()[0]
        if pending < YOUNG_THRESHOLD:
            return
        generation = 0
        if cls._young_collections >= 9:
            durations = cls.middle_durations_s
            need = max(SLACK_FOR_GENERATION_S[1], MIDDLE_MARGIN * min(durations, default=0.0))
            if slack_s >= need:
                generation = 1
            else:
                cls.middle_postponed += 1
        if generation == 0 and slack_s < SLACK_FOR_GENERATION_S[0]:
            if pending < FORCED_THRESHOLD:
                return  # wait for a cycle with more slack
            cls.forced_collections += 1
        started = _clock()
        gc.collect(generation)
        if generation:
            cls.middle_durations_s = [*cls.middle_durations_s[-2:], _clock() - started]
            cls._young_collections = 0
        else:
            cls._young_collections += 1
        cls.collections[generation] += 1


#: environment variable read by a Pacer given no rt_priority (0 or unset = off)
RT_PRIORITY_ENV = "FMSCELL_DRIVES_RT_PRIORITY"
#: environment variable read by a Pacer given no cpu: pin the pacing thread to this CPU
RT_CPU_ENV = "FMSCELL_DRIVES_RT_CPU"


def rt_priority_from_env(environ=None, variable: str = RT_PRIORITY_ENV) -> int:
    """The SCHED_FIFO priority `variable` (`FMSCELL_DRIVES_RT_PRIORITY`) asks for;
    ValueError names it."""
    raw = (os.environ if environ is None else environ).get(variable, "").strip()
    if not raw:
        return 0
    if not raw.isdigit() or not 0 <= int(raw) <= 99:
        raise ValueError(f"{variable}={raw!r}: must be an integer 0..99 (0 = off)")
    return int(raw)


def rt_cpu_from_env(environ=None) -> int | None:
    """The CPU `FMSCELL_DRIVES_RT_CPU` pins the pacing thread to (unset = no pinning)."""
    raw = (os.environ if environ is None else environ).get(RT_CPU_ENV, "").strip()
    if not raw:
        return None
    if not raw.isdigit():
        raise ValueError(f"{RT_CPU_ENV}={raw!r}: must be a CPU number (0, 1, ...)")
    return int(raw)


def pin_to_cpu(cpu: int) -> str:
    """Pin the calling thread to `cpu` (Linux: pid 0 is the calling thread); returns what
    it got, a refusal included."""
    try:
        os.sched_setaffinity(0, {cpu})
    except (OSError, AttributeError) as exc:
        why = getattr(exc, "strerror", None) or "not available on this OS"
        return f"any CPU (CPU {cpu} refused: {why})"
    return f"CPU {cpu}"


def request_fifo(priority: int) -> str:
    """SCHED_FIFO `priority` for the calling thread (Linux: pid 0 is the calling thread);
    returns the scheduling it runs with, a refusal included."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (OSError, AttributeError) as exc:
        why = getattr(exc, "strerror", None) or "not available on this OS"
        return f"SCHED_OTHER (SCHED_FIFO {priority} refused: {why})"
    return f"SCHED_FIFO {priority}"


class ThreadScheduling:
    """A thread's scheduling (policy, priority, CPUs) as it was before a shell promoted or
    pinned it, to put it back when the pacing ends.

    A thread left at SCHED_FIFO goes on with its other work (a summary to sort, a result to
    send, the rest of a server) at the realtime priority and holds its CPU from the shells
    that still pace. Measured with 8 machines paced at FIFO for 20 s: 0.10-0.26 % of the
    slots late or missed, the late cycles all in the first and last 0.1 s, where siblings
    collected garbage or sent their results at FIFO; 0.013-0.058 % in four runs once the
    collection ran before the promotion and each thread was put back after its last cycle.
    """

    def __init__(self) -> None:  # a snapshot of the calling thread
        self.thread = threading.current_thread()
        self.tid = threading.get_native_id()
        self.policy: tuple[int, int] | None
        try:
            self.policy = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority)
        except (OSError, AttributeError):
            self.policy = None
        self.cpus: set[int] | None
        try:
            self.cpus = os.sched_getaffinity(0)
        except (OSError, AttributeError):
            self.cpus = None

    def restore(self) -> None:
        """Put the thread back (lowering needs no privilege); nothing once it has ended, as
        its id may then name another thread."""
        if not self.thread.is_alive():
            return
        tid = 0 if self.thread is threading.current_thread() else self.tid
        try:
            if self.policy is not None:
                os.sched_setscheduler(tid, self.policy[0], os.sched_param(self.policy[1]))
            if self.cpus is not None:
                os.sched_setaffinity(tid, self.cpus)
        except OSError:
            pass  # the thread ended meanwhile: nothing left to put back


def sleep_until(deadline: float, spin_s: float = SPIN_S, clock=time.perf_counter, sleep=time.sleep):
    """Sleep until `spin_s` before `deadline` (`clock` time), then spin to it."""
    remaining = deadline - clock()
    if remaining > spin_s:
        sleep(remaining - spin_s)
    while clock() < deadline:
        sleep(0)  # releases the GIL: the bus and drive threads keep running while we spin


class Pacer:
    """Absolute deadlines every `period_s` on `clock` (perf_counter), no drift.

    `wait()` returns at the next slot (collecting garbage first when the slack allows) and
    gives its lateness; a slot that is already a whole period gone is skipped and counted.
    `rt_priority` / `cpu` (None = from the environment) are applied to the thread of the first
    wait, and `restore_scheduling()` puts that thread back when the pacing is over. `clock`,
    `sleep`, `promote` and `pin` are replaceable for tests.
    """

    def __init__(
        self,
        period_s: float,
        *,
        spin_s: float = SPIN_S,
        clock=time.perf_counter,
        sleep=time.sleep,
        rt_priority: int | None = None,
        promote=request_fifo,
        cpu: int | None = None,
        pin=pin_to_cpu,
    ) -> None:
        if not period_s > 0:
            raise ValueError(f"Pacer: period_s must be > 0, got {period_s!r}")
        if rt_priority is None:
            rt_priority = rt_priority_from_env()
        elif not 0 <= rt_priority <= 99:
            raise ValueError(f"Pacer: rt_priority must be 0..99 (0 = off), got {rt_priority!r}")
        self.rt_priority = rt_priority
        self._promote = promote
        if cpu is None:
            cpu = rt_cpu_from_env()
        elif cpu < 0:
            raise ValueError(f"Pacer: cpu must be a CPU number >= 0, got {cpu!r}")
        self.cpu = cpu
        self._pin = pin
        self.scheduling = "SCHED_OTHER"  # what the pacing thread runs with, once it waited
        self.period_s = period_s
        self.spin_s = spin_s
        self.clock = clock
        self.sleep = sleep
        self.slot: float | None = None
        self.skipped = 0
        self._saved: ThreadScheduling | None = None  # before the first wait promoted/pinned

    def wait(self) -> float:
        """Wait for the next slot; returns how late (s) it was reached."""
        period, clock = self.period_s, self.clock
        now = clock()
        if self.slot is None:  # the first wait, on the thread that will pace
            if self.rt_priority or self.cpu is not None:
                self._saved = ThreadScheduling()
            if self.rt_priority:
                self.scheduling = self._promote(self.rt_priority)
            if self.cpu is not None:
                self.scheduling += f", {self._pin(self.cpu)}"
            self.slot = now
            return 0.0
        slot = self.slot + period
        if now > slot + period:  # a whole slot missed: skip ahead, count it
            missed = int((now - slot) / period)
            self.skipped += missed
            slot += missed * period
        self.slot = slot
        RealtimeProcess.collect_in_slack(slot - now)
        sleep_until(slot, self.spin_s, clock, self.sleep)
        return clock() - slot

    def restore_scheduling(self) -> None:
        """The pacing is over: its thread back to the scheduling and CPUs it had before the
        first wait (`ThreadScheduling`); callable from any thread."""
        saved, self._saved = self._saved, None
        if saved is not None:
            saved.restore()
