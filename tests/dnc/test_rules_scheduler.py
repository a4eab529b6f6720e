"""Dispatch rules and the scheduler's pure core, table-driven."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

import pytest

from dnc.rules import JobView, critical_ratio, edd, fifo, rule_named, spt
from dnc.scheduler import (
    Allocate,
    AllocationState,
    Complete,
    Interrupt,
    JobState,
    MachineView,
    MarkRunning,
    decide,
)

T0 = datetime(2026, 11, 21, 8, 0, tzinfo=UTC)


def jv(id, *, prio=0, created=0, due=None, remaining=1, cycle=60.0):
    return JobView(
        id,
        prio,
        T0 + timedelta(minutes=created),
        None if due is None else T0 + timedelta(minutes=due),
        remaining,
        cycle,
    )


JOBS = [
    jv(1, created=0, due=300, remaining=10, cycle=60),  # 600 s, slack 18000 s -> CR 30
    jv(2, created=1, due=60, remaining=1, cycle=30),  # 30 s, slack 3600 -> CR 120
    jv(3, created=2, due=20, remaining=30, cycle=60),  # 1800 s, slack 1200 -> CR 0.67
    jv(4, created=3, due=None, remaining=2, cycle=5),  # 10 s, no due date
]


@pytest.mark.parametrize(
    "rule, order",
    [
        (fifo, [1, 2, 3, 4]),
        (spt, [4, 2, 1, 3]),
        (edd, [3, 2, 1, 4]),
        (critical_ratio, [3, 1, 2, 4]),
    ],
)
def test_rule_orders(rule, order):
    assert [r.job.id for r in rule(JOBS, T0)] == order


def test_priority_class_beats_every_rule():
    jobs = JOBS + [jv(9, prio=5, created=99, remaining=100)]
    for rule in (fifo, spt, edd, critical_ratio):
        first = rule(jobs, T0)[0]
        assert first.job.id == 9 and first.reason.startswith("priority 5; ")


def test_reasons_name_the_rule_and_figures():
    assert critical_ratio(JOBS, T0)[0].reason == "CR: critical ratio 0.667 (late)"
    assert spt(JOBS, T0)[0].reason == "SPT: remaining processing time 10.0 s (2 x 5.0 s)"


def test_unknown_rule_is_refused():
    assert rule_named("EDD") is edd
    with pytest.raises(ValueError, match="unknown dispatch rule 'lifo'; known rules: fifo"):
        rule_named("lifo")


def job(id, qty=4, done=0, kind="mill", group=None, cancelled=False, created=0):
    return JobState(
        id, kind, group, qty, done, 0, T0 + timedelta(minutes=created), None, 60.0, cancelled
    )


def mach(name, state="idle", count=0, kind="mill", groups=()):
    return MachineView(name, kind, state, count, groups)


def test_quantity_spreads_over_every_idle_eligible_machine():
    d = decide(
        [job(1)], [], [mach("mill1"), mach("mill2"), mach("lathe1", kind="lathe")], fifo, "fifo", T0
    )
    assert [(a.job_id, a.machine) for a in d.of(Allocate)] == [(1, "mill1"), (1, "mill2")]
    assert "FIFO chose job 1 for idle mill1 (rank 1 of 1 eligible)" in d.of(Allocate)[0].reason


def test_no_more_parts_allocated_than_remain():
    d = decide([job(1, qty=3, done=2)], [], [mach("mill1"), mach("mill2")], fifo, "fifo", T0)
    assert len(d.of(Allocate)) == 1


def test_part_counter_completes_the_allocation():
    allocs = [AllocationState(10, 1, "mill1", parts_at_start=7, running=True)]
    d = decide([job(1, qty=1)], allocs, [mach("mill1", "idle", 8)], fifo, "fifo", T0)
    assert d.of(Complete) == [Complete(10, 1, 1)] and d.of(Allocate) == []


def test_alarm_interrupts_and_the_part_is_rerouted_in_the_same_tick():
    allocs = [
        AllocationState(10, 1, "mill1", 0, running=True),
        AllocationState(11, 1, "mill2", 0, running=True),
    ]
    machines = [mach("mill1", "alarm"), mach("mill2", "busy"), mach("mill3", "idle")]
    d = decide([job(1, qty=2)], allocs, machines, fifo, "fifo", T0)
    assert d.of(Interrupt) == [Interrupt(10, 1, "machine mill1 raised an alarm")]
    assert [(a.job_id, a.machine) for a in d.of(Allocate)] == [(1, "mill3")]


def test_offline_machine_keeps_its_allocation():
    allocs = [AllocationState(10, 1, "mill1", 0, running=True)]
    d = decide([job(1, qty=1)], allocs, [mach("mill1", "offline"), mach("mill2")], fifo, "fifo", T0)
    assert d.actions == []


def test_machine_seen_busy_marks_the_allocation_running():
    allocs = [AllocationState(10, 1, "mill1", 0, running=False)]
    d = decide([job(1, qty=1)], allocs, [mach("mill1", "busy")], fifo, "fifo", T0)
    assert d.actions == [MarkRunning(10)]


def test_failed_dispatch_interrupts():
    allocs = [AllocationState(10, 1, "mill1", 0, running=False, dispatch_failed=True)]
    d = decide([job(1, qty=1)], allocs, [mach("mill1", "idle")], fifo, "fifo", T0)
    assert d.of(Interrupt) == [Interrupt(10, 1, "dispatch to mill1 failed")]


def test_group_and_cancel_limit_eligibility():
    jobs = [job(1, group="cellA"), job(2, cancelled=True)]
    d = decide(
        jobs,
        [],
        [mach("mill1", groups=("cellB",)), mach("mill2", groups=("cellA",))],
        fifo,
        "fifo",
        T0,
    )
    assert [(a.job_id, a.machine) for a in d.of(Allocate)] == [(1, "mill2")]
