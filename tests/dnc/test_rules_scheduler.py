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
    with pytest.raises(ValueError) as refused:
        rule_named("lifo")
    assert str(refused.value) == (
        "unknown dispatch rule 'lifo'; known rules: fifo, spt, edd, cr, same_program_first "
        "(a setup-aware one may fall back to another: 'same_program_first then edd')"
    )


def test_edd_reason_names_the_due_date():
    ranked = edd(JOBS, T0)
    assert ranked[0].reason == "EDD: due 2026-11-21T08:20:00+00:00"
    assert ranked[-1].reason == "EDD: due never"


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


# -- boundaries a mutation of dnc/rules.py would cross (issue 14, test strength) -------------


@pytest.mark.parametrize("rule", [fifo, spt, edd, critical_ratio])
def test_priority_one_is_a_class_above_zero_and_named_in_the_reason(rule):
    # the smallest priority that is not the default: `priority > 1` or `priority >= 0`
    # would treat it wrongly
    jobs = [jv(1, created=0, due=1, remaining=1), jv(2, prio=1, created=99, remaining=99)]
    ranked = rule(jobs, T0)
    assert [r.job.id for r in ranked] == [2, 1]
    assert ranked[0].reason.startswith("priority 1; ")
    assert not ranked[1].reason.startswith("priority")  # priority 0 is not shown
    negative = rule([jv(1, prio=-1), jv(2, created=5)], T0)
    assert [r.job.id for r in negative] == [2, 1]  # below the default class
    assert negative[1].reason.startswith("priority -1; ")


def test_zero_processing_time_ranks_by_slack_without_dividing_by_zero():
    # zero remaining (or a zero cycle time) makes the processing time 0: CR is the slack
    # itself, and SPT ranks it first
    jobs = [
        jv(1, due=60, remaining=0, cycle=60.0),  # slack 3600 s
        jv(2, due=30, remaining=5, cycle=0.0),  # slack 1800 s
        jv(3, due=120, remaining=1, cycle=1.0),  # 1 s, slack 7200 s -> CR 7200
    ]
    cr = critical_ratio(jobs, T0)
    assert [(r.job.id, r.key) for r in cr] == [(2, 1800.0), (1, 3600.0), (3, 7200.0)]
    late = critical_ratio([jv(1, due=-10, remaining=0)], T0)[0]
    assert late.key == -600.0 and late.reason == "CR: critical ratio -600 (late)"
    s = spt(jobs, T0)
    assert [(r.job.id, r.key) for r in s] == [(1, 0.0), (2, 0.0), (3, 1.0)]
    assert s[0].reason == "SPT: remaining processing time 0.0 s (0 x 60.0 s)"


@pytest.mark.parametrize(
    "due_min, late",
    [(9, True), (10, False), (11, False)],  # 600 s of work: due in 10 min is CR exactly 1.0
)
def test_critical_ratio_of_exactly_one_is_on_time(due_min, late):
    (ranked,) = critical_ratio([jv(1, due=due_min, remaining=10, cycle=60.0)], T0)
    assert ranked.key == pytest.approx(due_min / 10)
    assert ranked.reason.endswith(" (late)") is late
    if due_min == 10:
        assert ranked.key == 1.0 and ranked.reason == "CR: critical ratio 1"


@pytest.mark.parametrize("rule", [fifo, spt, edd, critical_ratio])
def test_equal_keys_are_ordered_by_job_id_whatever_the_input_order(rule):
    same = [jv(i, created=0, due=60, remaining=2, cycle=30.0) for i in (7, 3, 5)]
    for jobs in (same, same[::-1], [same[1], same[0], same[2]]):
        assert [r.job.id for r in rule(jobs, T0)] == [3, 5, 7]
    # and the id only breaks ties: a better key wins over a lower id
    better = jv(9, created=-1, due=20, remaining=1, cycle=30.0)
    assert rule([*same, better], T0)[0].job.id == 9
    # within a priority class too, and never across classes
    mixed = [jv(8, prio=1, created=0, due=60, remaining=2, cycle=30.0), *same]
    assert [r.job.id for r in rule(mixed, T0)] == [8, 3, 5, 7]


def test_jobs_without_due_date_go_last_under_edd_and_cr_in_id_order():
    jobs = [jv(4), jv(2), jv(3, due=600)]
    for rule in (edd, critical_ratio):
        ranked = rule(jobs, T0)
        assert [r.job.id for r in ranked] == [3, 2, 4]
        assert ranked[1].key == float("inf")
    assert edd(jobs, T0)[1].reason == "EDD: due never"


def test_a_short_processing_time_divides_the_slack():
    # 0.5 s of work due in 1 min: CR 120, not the slack of 60 s (only 0 s is special)
    (ranked,) = critical_ratio([jv(1, due=1, remaining=1, cycle=0.5)], T0)
    assert ranked.key == 120.0


@pytest.mark.parametrize("rule", [fifo, spt, edd, critical_ratio])
def test_every_priority_is_its_own_class(rule):
    jobs = [jv(1, prio=1), jv(2, prio=2, created=9, remaining=9), jv(3, prio=7, created=99)]
    assert [r.job.id for r in rule(jobs, T0)] == [3, 2, 1]
