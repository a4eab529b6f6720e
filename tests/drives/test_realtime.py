"""The realtime pacing helpers: process settings, GC in the slack, absolute deadlines."""

from __future__ import annotations

import gc
import sys

import pytest

from drives.realtime import (
    FORCED_THRESHOLD,
    RT_CPU_ENV,
    RT_PRIORITY_ENV,
    SWITCH_INTERVAL_S,
    YOUNG_THRESHOLD,
    Pacer,
    RealtimeProcess,
)


@pytest.fixture
def realtime():
    threshold, interval = gc.get_threshold(), sys.getswitchinterval()
    RealtimeProcess.acquire()
    try:
        yield
    finally:
        RealtimeProcess.release()
    assert gc.get_threshold() == threshold
    assert sys.getswitchinterval() == interval


def test_settings_hold_while_any_user_remains_and_are_restored_after_the_last(realtime):
    assert gc.get_threshold()[0] == FORCED_THRESHOLD  # the pacers collect before this
    assert gc.get_freeze_count() > 0  # setup's objects left the collector
    assert sys.getswitchinterval() <= SWITCH_INTERVAL_S
    RealtimeProcess.acquire()  # a second shell
    RealtimeProcess.release()
    assert gc.get_threshold()[0] == FORCED_THRESHOLD and RealtimeProcess.active()


class FakeGc:
    """The collector as `collect_in_slack` sees it: a pending count and collect(gen)."""

    def __init__(self, pending: int) -> None:
        self.pending = pending
        self.collected: list[int] = []
        self.now = 0.0  # the clock the collections are timed with
        self.duration_s = [0.1e-3, 0.3e-3]  # what a young / middle collection takes

    def clock(self) -> float:
        return self.now

    def get_count(self) -> tuple[int, int, int]:
        return (self.pending, 0, 0)

    def collect(self, generation: int) -> int:
        self.collected.append(generation)
        self.pending = 0
        self.now += self.duration_s[generation]
        return 0


@pytest.fixture
def fake_gc(monkeypatch):
    # Other tests' realtime threads may collect too: the policy is checked on a stand-in.
    import drives.realtime as rt

    fake = FakeGc(0)
    monkeypatch.setattr(rt, "gc", fake)
    monkeypatch.setattr(rt, "_clock", fake.clock)
    monkeypatch.setattr(RealtimeProcess, "_users", 1)
    monkeypatch.setattr(RealtimeProcess, "_young_collections", 0)
    monkeypatch.setattr(RealtimeProcess, "middle_durations_s", [])
    monkeypatch.setattr(RealtimeProcess, "middle_postponed", 0)
    monkeypatch.setattr(RealtimeProcess, "collections", [0, 0])
    monkeypatch.setattr(RealtimeProcess, "forced_collections", 0)
    return fake


def test_young_collection_waits_for_slack(fake_gc):
    fake_gc.pending = YOUNG_THRESHOLD - 1
    RealtimeProcess.collect_in_slack(1.0)  # nothing due yet
    fake_gc.pending = 2 * YOUNG_THRESHOLD
    RealtimeProcess.collect_in_slack(0.0)  # due, but no slack: it waits
    assert fake_gc.collected == []
    RealtimeProcess.collect_in_slack(0.3e-3)
    assert fake_gc.collected == [0]
    assert RealtimeProcess.collections == [1, 0]


def collect_due(slack_s: float, fake_gc: FakeGc, times: int = 1) -> None:
    for _ in range(times):
        fake_gc.pending = YOUNG_THRESHOLD
        RealtimeProcess.collect_in_slack(slack_s)


def test_middle_generation_every_tenth_time_needs_more_slack_and_never_the_old(fake_gc):
    collect_due(0.3e-3, fake_gc, 9)
    collect_due(0.3e-3, fake_gc)  # the 10th is a middle one: not enough slack, a young one
    assert fake_gc.collected == [0] * 10 and RealtimeProcess.middle_postponed == 1
    collect_due(0.6e-3, fake_gc)  # still due, and now the slack holds it
    assert fake_gc.collected == [0] * 10 + [1]
    assert RealtimeProcess.collections == [10, 1]
    collect_due(1.0, fake_gc, 200)
    assert 2 not in fake_gc.collected


def test_a_middle_collection_longer_than_the_slack_waits_for_a_slack_that_holds_it(fake_gc):
    fake_gc.duration_s[1] = 1.4e-3  # long-lived objects of the shells fill the middle generation
    collect_due(0.8e-3, fake_gc, 10)  # the first one is a guess: the minimum slack held it
    assert fake_gc.collected == [0] * 9 + [1]
    assert RealtimeProcess.middle_durations_s == [pytest.approx(1.4e-3)]
    collect_due(0.8e-3, fake_gc, 50)  # a 1 ms cycle's slack never holds 1.25 x 1.4 ms
    assert fake_gc.collected[10:] == [0] * 50
    assert RealtimeProcess.middle_postponed == 41
    collect_due(1.8e-3, fake_gc)  # a longer slack (a slower IPO cycle) does
    assert fake_gc.collected[-1] == 1


def test_one_slow_middle_collection_among_three_does_not_stop_them(fake_gc):
    collect_due(0.6e-3, fake_gc, 20)  # two middle collections of 0.3 ms
    fake_gc.duration_s[1] = 3e-3  # one disturbed (an interrupt burst on its CPU)
    collect_due(0.6e-3, fake_gc, 10)
    fake_gc.duration_s[1] = 0.3e-3
    collect_due(0.6e-3, fake_gc, 10)  # the shortest of the last three decides
    assert fake_gc.collected.count(1) == 4


def test_a_backlog_beyond_the_bound_is_collected_without_slack(fake_gc):
    fake_gc.pending = FORCED_THRESHOLD
    RealtimeProcess.collect_in_slack(0.0)
    assert fake_gc.collected == [0]
    assert RealtimeProcess.forced_collections == 1


def test_without_a_user_nothing_is_collected_by_the_pacers(fake_gc, monkeypatch):
    monkeypatch.setattr(RealtimeProcess, "_users", 0)
    fake_gc.pending = FORCED_THRESHOLD
    RealtimeProcess.collect_in_slack(1.0)
    assert fake_gc.collected == []


class FakeClock:
    """perf_counter stand-in: sleeping and every read move it forward."""

    def __init__(self, read_cost: float = 1e-6) -> None:
        self.now = 100.0
        self.read_cost = read_cost
        self.slept: list[float] = []

    def __call__(self) -> float:
        self.now += self.read_cost
        return self.now

    def sleep(self, seconds: float) -> None:
        if seconds == 0:  # the spin loop's GIL release: back at once
            self.now += 1e-6
            return
        self.slept.append(seconds)
        self.now += seconds + 60e-6  # the scheduler wakes us late


def test_pacer_sleeps_to_the_spin_window_then_reaches_the_slot_exactly():
    clock = FakeClock()
    pacer = Pacer(0.001, spin_s=250e-6, clock=clock, sleep=clock.sleep, rt_priority=0)
    assert pacer.wait() == 0.0
    first = pacer.slot
    for k in range(1, 6):
        lateness = pacer.wait()
        assert pacer.slot == pytest.approx(first + k * 0.001)  # absolute: no drift
        assert 0.0 <= lateness <= 2e-6  # the 60 us oversleep fell inside the spin window
    assert all(s < 0.001 - 250e-6 + 1e-9 for s in clock.slept)


def test_pacer_skips_whole_missed_slots_and_counts_them():
    clock = FakeClock()
    pacer = Pacer(0.001, clock=clock, sleep=clock.sleep, rt_priority=0)
    pacer.wait()
    first = pacer.slot
    clock.now += 0.0035  # the work of one cycle took 3.5 periods
    lateness = pacer.wait()
    assert pacer.skipped == 2  # slots 1 and 2 are gone; slot 3 runs, half a period late
    assert pacer.slot == pytest.approx(first + 0.003)
    assert lateness == pytest.approx(0.0005, abs=1e-5)


def test_pacer_refuses_a_bad_period():
    with pytest.raises(ValueError, match="period_s"):
        Pacer(0.0)


@pytest.mark.parametrize(
    ("rt_priority", "env", "promoted", "scheduling"),
    [
        (None, None, [], "SCHED_OTHER"),  # default: ordinary scheduling, nothing asked
        (None, "0", [], "SCHED_OTHER"),
        (None, "40", [40], "SCHED_FIFO 40"),  # FMSCELL_DRIVES_RT_PRIORITY
        (20, "40", [20], "SCHED_FIFO 20"),  # the argument wins over the environment
        (0, "40", [], "SCHED_OTHER"),
    ],
)
def test_pacer_asks_sched_fifo_once_on_its_first_wait(
    monkeypatch, rt_priority, env, promoted, scheduling
):
    if env is None:
        monkeypatch.delenv(RT_PRIORITY_ENV, raising=False)
    else:
        monkeypatch.setenv(RT_PRIORITY_ENV, env)
    asked: list[int] = []

    def promote(priority: int) -> str:
        asked.append(priority)
        return f"SCHED_FIFO {priority}"

    clock = FakeClock()
    pacer = Pacer(0.001, clock=clock, sleep=clock.sleep, rt_priority=rt_priority, promote=promote)
    assert asked == []  # not on the constructing thread: on the one that paces
    for _ in range(3):
        pacer.wait()
    assert asked == promoted and pacer.scheduling == scheduling


def test_pacer_refusal_is_reported_not_raised():
    pacer = Pacer(
        0.001,
        rt_priority=5,
        promote=lambda p: f"SCHED_OTHER (SCHED_FIFO {p} refused: Operation not permitted)",
    )
    pacer.wait()
    assert pacer.scheduling.startswith("SCHED_OTHER (SCHED_FIFO 5 refused")


@pytest.mark.parametrize("raw", ["high", "-1", "100", "1.5"])
def test_a_malformed_priority_is_refused_naming_the_variable(monkeypatch, raw):
    monkeypatch.setenv(RT_PRIORITY_ENV, raw)
    with pytest.raises(ValueError, match=f"FMSCELL_DRIVES_RT_PRIORITY={raw!r}: must be an"):
        Pacer(0.001)
    with pytest.raises(ValueError, match="rt_priority must be 0..99"):
        Pacer(0.001, rt_priority=100)


@pytest.mark.parametrize(
    ("cpu", "env", "pinned", "scheduling"),
    [
        (None, None, [], "SCHED_FIFO 7"),  # default: no pinning
        (None, "1", [1], "SCHED_FIFO 7, CPU 1"),  # FMSCELL_DRIVES_RT_CPU
        (0, "1", [0], "SCHED_FIFO 7, CPU 0"),  # the argument wins over the environment
    ],
)
def test_pacer_pins_its_thread_on_the_first_wait_when_asked(
    monkeypatch, cpu, env, pinned, scheduling
):
    if env is None:
        monkeypatch.delenv(RT_CPU_ENV, raising=False)
    else:
        monkeypatch.setenv(RT_CPU_ENV, env)
    asked: list[int] = []

    def pin(n: int) -> str:
        asked.append(n)
        return f"CPU {n}"

    clock = FakeClock()
    pacer = Pacer(
        0.001,
        clock=clock,
        sleep=clock.sleep,
        rt_priority=7,
        promote=lambda p: f"SCHED_FIFO {p}",
        cpu=cpu,
        pin=pin,
    )
    assert asked == []  # not on the constructing thread: on the one that paces
    for _ in range(3):
        pacer.wait()
    assert asked == pinned and pacer.scheduling == scheduling


def test_pinning_refusal_is_reported_not_raised(monkeypatch):
    monkeypatch.delenv(RT_PRIORITY_ENV, raising=False)
    pacer = Pacer(0.001, cpu=4096)  # no such CPU: the real call refuses it
    pacer.wait()
    assert pacer.scheduling.startswith("SCHED_OTHER, any CPU (CPU 4096 refused")


@pytest.mark.parametrize("raw", ["first", "-1", "1.5"])
def test_a_malformed_cpu_is_refused_naming_the_variable(monkeypatch, raw):
    monkeypatch.setenv(RT_CPU_ENV, raw)
    with pytest.raises(ValueError, match=f"FMSCELL_DRIVES_RT_CPU={raw!r}: must be a CPU"):
        Pacer(0.001)
    with pytest.raises(ValueError, match="cpu must be a CPU number"):
        Pacer(0.001, cpu=-2)


def test_axis_group_reports_its_pacers_scheduling(monkeypatch):
    from drives.bus import CanHub
    from drives.master import AxisConfig, AxisGroup

    monkeypatch.delenv(RT_PRIORITY_ENV, raising=False)
    hub = CanHub()
    group = AxisGroup([hub.endpoint("master")], [AxisConfig("X", 1)], ipo_cycle_s=0.001)
    try:
        assert group.scheduling == "SCHED_OTHER"
    finally:
        group.close()
        hub.close()


def _fifo_granted_or_skip(scheduling: str) -> None:
    if not scheduling.startswith("SCHED_FIFO"):
        pytest.skip(f"no realtime privilege here: {scheduling}")


def test_pacer_puts_its_thread_back_to_its_old_scheduling_and_cpus():
    """A paced thread left at SCHED_FIFO would do its later work (a summary, a result to
    send) at the realtime priority, ahead of the shells that still pace: the pacer gives
    the priority and the pinning back, from whichever thread closes it."""
    import os
    import threading

    before_cpus = os.sched_getaffinity(0)
    pacer = Pacer(0.001, rt_priority=10, cpu=min(before_cpus))
    paced, release = threading.Event(), threading.Event()
    seen: dict = {}

    def pace() -> None:
        seen["tid"] = threading.get_native_id()
        for _ in range(3):
            pacer.wait()
        seen["during"] = (os.sched_getscheduler(0), os.sched_getaffinity(0))
        paced.set()
        release.wait(10)

    thread = threading.Thread(target=pace)
    thread.start()
    try:
        assert paced.wait(10)
        _fifo_granted_or_skip(pacer.scheduling)
        assert seen["during"] == (os.SCHED_FIFO, {min(before_cpus)})
        pacer.restore_scheduling()  # from this thread, while the paced one still lives
        assert os.sched_getscheduler(seen["tid"]) == os.SCHED_OTHER
        assert os.sched_getaffinity(seen["tid"]) == before_cpus
        pacer.restore_scheduling()  # a second call has nothing left to do
    finally:
        release.set()
        thread.join(10)


def test_restoring_a_thread_that_has_ended_touches_nothing():
    """Its id may already name another thread: the snapshot does nothing then."""
    import threading

    from drives.realtime import ThreadScheduling

    taken: list[ThreadScheduling] = []
    thread = threading.Thread(target=lambda: taken.append(ThreadScheduling()))
    thread.start()
    thread.join(10)
    taken[0].policy = (99, 99)  # would raise if it were applied to anything
    taken[0].restore()
