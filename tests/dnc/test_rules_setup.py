"""The setup-aware dispatch rule `same_program_first`, the rule chosen per cell, and the
rule through the real scheduler. Orders are worked out by hand in the comments."""

from __future__ import annotations

from dataclasses import replace
from datetime import UTC, datetime, timedelta

import pytest

from cnc.config import ConfigError
from dnc.jobs import Jobs, Scheduler
from dnc.rules import RULES, SameProgramFirst, critical_ratio, edd, fifo, rule_named, spt
from dnc.scheduler import Allocate, JobState, MachineView, decide
from server.config import load_cell_config
from tests.dnc.test_jobs import worker_started
from tests.dnc.test_rules_scheduler import jv

T0 = datetime(2026, 11, 21, 8, 0, tzinfo=UTC)


def pjv(id, program, **kw):
    return replace(jv(id, **kw), program=program)


# FIFO 1 2 3 4; SPT 4 (10 s) 2 (30 s) 1 (600 s) 3 (1800 s); EDD 3 (due 20) 2 (60) 1 (300) 4 (none)
JOBS = [
    pjv(1, "O1000", created=0, due=300, remaining=10, cycle=60),
    pjv(2, "O2000", created=1, due=60, remaining=1, cycle=30),
    pjv(3, "O1000", created=2, due=20, remaining=30, cycle=60),
    pjv(4, "O3000", created=3, due=None, remaining=2, cycle=5),
]


@pytest.mark.parametrize(
    "then, held, order",
    [
        (fifo, "O1000", [1, 3, 2, 4]),  # O1000's jobs (1, 3) first, each group in FIFO order
        (fifo, "O2000", [2, 1, 3, 4]),
        (fifo, "O3000", [4, 1, 2, 3]),
        (fifo, "O9999", [1, 2, 3, 4]),  # no waiting job's program on it: FIFO exactly
        (fifo, None, [1, 2, 3, 4]),  # a machine with no history: FIFO exactly
        (spt, "O1000", [1, 3, 4, 2]),  # 1 (600 s) before 3 (1800 s), then SPT's 4, 2
        (spt, "O2000", [2, 4, 1, 3]),
        (spt, None, [4, 2, 1, 3]),
        (edd, "O1000", [3, 1, 2, 4]),  # 3 (due 20) before 1 (due 300), then EDD's 2, 4
        (edd, "O3000", [4, 3, 2, 1]),
    ],
)
def test_same_program_first_orders(then, held, order):
    assert [r.job.id for r in SameProgramFirst(then)(JOBS, T0, held)] == order


def test_ties_within_the_held_program_go_by_the_base_rule_then_the_job_id():
    jobs = [
        pjv(6, "O1000", created=0),
        pjv(5, "O1000", created=0),  # same queue time as 6: the lower id first
        pjv(7, "O2000", created=-1),  # queued earliest, but not the program on the machine
    ]
    assert [r.job.id for r in SameProgramFirst()(jobs, T0, "O1000")] == [5, 6, 7]
    assert [r.job.id for r in SameProgramFirst()(jobs, T0, None)] == [7, 5, 6]


def test_a_priority_class_still_beats_the_program_on_the_machine():
    jobs = JOBS + [pjv(9, "O2000", prio=5, created=99)]
    ranked = SameProgramFirst()(jobs, T0, "O1000")
    assert [r.job.id for r in ranked] == [9, 1, 3, 2, 4]
    assert ranked[0].reason == (
        "priority 5; not the program on the machine (O1000); FIFO: queued 2026-11-21T09:39:00+00:00"
    )


def test_reasons_say_whether_the_machine_holds_the_program():
    held = SameProgramFirst()(JOBS, T0, "O1000")
    assert held[0].reason == (
        "same program O1000 already on the machine: no setup change; "
        "FIFO: queued 2026-11-21T08:00:00+00:00"
    )
    assert held[2].reason.startswith("not the program on the machine (O1000); FIFO: queued")
    unknown = SameProgramFirst(edd)(JOBS, T0, None)
    assert unknown[0].reason.startswith(
        "no program known on the machine; EDD: due 2026-11-21T08:20"
    )


def test_without_a_machine_it_is_its_base_rule():
    # called as any rule (jobs, now): nothing is known of the machine
    assert [r.job.id for r in SameProgramFirst(spt)(JOBS, T0)] == [r.job.id for r in spt(JOBS, T0)]


@pytest.mark.parametrize(
    "name, then",
    [
        ("same_program_first", fifo),
        ("same_program_first then edd", edd),
        ("Same_Program_First THEN SPT", spt),
    ],
)
def test_rule_named_with_a_fallback(name, then):
    rule = rule_named(name)
    assert isinstance(rule, SameProgramFirst) and rule.then is then


@pytest.mark.parametrize(
    "name, says",
    [
        (
            "lifo",
            "unknown dispatch rule 'lifo'; known rules: fifo, spt, edd, cr, same_program_first",
        ),
        ("same_program_first then lifo", "unknown dispatch rule 'same_program_first then lifo'"),
        ("edd then fifo", "only a setup-aware rule (same_program_first) falls back"),
        (
            "same_program_first then same_program_first",
            "the rule after 'then' must be one of fifo, spt, edd, cr",
        ),
    ],
)
def test_bad_rule_names_are_refused_saying_what_is_known(name, says):
    with pytest.raises(ValueError, match=says.replace("(", r"\(").replace(")", r"\)")):
        rule_named(name)


def test_the_rules_a_setup_aware_rule_may_fall_back_to_are_exactly_the_plain_ones():
    # the whole message: a list that also named same_program_first would still match a prefix
    with pytest.raises(ValueError) as refused:
        rule_named("same_program_first then same_program_first")
    assert str(refused.value) == (
        "dispatch rule 'same_program_first then same_program_first': the rule after 'then' "
        "must be one of fifo, spt, edd, cr"
    )


def test_a_refused_fallback_names_every_setup_aware_rule(monkeypatch):
    """With two setup-aware rules, the refusal lists both, comma-separated."""
    monkeypatch.setitem(RULES, "same_fixture_first", SameProgramFirst(spt))
    with pytest.raises(ValueError) as refused:
        rule_named("edd then fifo")
    assert str(refused.value) == (
        "dispatch rule 'edd then fifo': only a setup-aware rule (same_program_first, "
        "same_fixture_first) falls back to another with 'then'"
    )


def test_the_base_rules_key_and_reason_pass_through_with_the_setup_case():
    """The base rule's key (SPT's processing time) is kept on each ranked job and written in
    its reason; the base rule is asked at the same `now` (CR's slack is counted from it)."""
    ranked = SameProgramFirst(spt)(JOBS, T0, "O1000")
    assert [(r.job.id, r.key) for r in ranked] == [(1, 600.0), (3, 1800.0), (4, 10.0), (2, 30.0)]
    assert ranked[0].reason == (
        "same program O1000 already on the machine: no setup change; "
        "SPT: remaining processing time 600.0 s (10 x 60.0 s)"
    )
    cr = SameProgramFirst(critical_ratio)(JOBS, T0, "O2000")
    # job 2: due in 3600 s, 30 s of work left: CR 120; job 3: 1200 s / 1800 s: 0.667, late
    assert [(r.job.id, r.key) for r in cr][:3] == [(2, 120.0), (3, 1200.0 / 1800.0), (1, 30.0)]
    assert cr[1].reason == "not the program on the machine (O2000); CR: critical ratio 0.667 (late)"


# ------------------------------------------------------------------ the scheduler's core


def job(id, program, created):
    return JobState(
        id, "mill", None, 1, 0, 0, T0 + timedelta(minutes=created), None, 60.0, program=program
    )


def idle(name, program=None):
    return MachineView(name, "mill", "idle", 0, program=program)


WAITING = [job(1, "O1000", 0), job(2, "O2000", 1), job(3, "O1000", 2)]


def chosen(decisions):
    return [(a.machine, a.job_id) for a in decisions.of(Allocate)]


def test_decide_gives_each_machine_the_job_of_the_program_it_holds():
    machines = [idle("mill1", "O2000"), idle("mill2", ""), idle("mill3")]
    last = {"mill2": "O1000"}  # mill2 does not report a program; its last allocation ran O1000
    got = decide(
        WAITING, [], machines, SameProgramFirst(), "same_program_first", T0, last_programs=last
    )
    # mill1 holds O2000 -> job 2; mill2 last ran O1000 -> job 1; mill3 knows nothing -> FIFO,
    # job 1 taken -> job 3
    assert chosen(got) == [("mill1", 2), ("mill2", 1), ("mill3", 3)]
    assert got.of(Allocate)[0].reason.startswith(
        "SAME_PROGRAM_FIRST chose job 2 for idle mill1 (rank 1 of 3 eligible): "
        "same program O2000 already on the machine: no setup change; FIFO"
    )
    # FIFO on the same cell: the machines in name order take the jobs in queue order
    plain = decide(WAITING, [], machines, fifo, "fifo", T0, last_programs=last)
    assert chosen(plain) == [("mill1", 1), ("mill2", 2), ("mill3", 3)]


def test_the_program_the_machine_reports_wins_over_its_history():
    machines = [idle("mill1", "O2000")]
    got = decide(
        WAITING,
        [],
        machines,
        SameProgramFirst(),
        "same_program_first",
        T0,
        last_programs={"mill1": "O1000"},
    )
    assert chosen(got) == [("mill1", 2)]


# ------------------------------------------------------------------ through the real scheduler


class Cell:
    """Two mills whose monitoring reports no program (None): what a setup-aware rule knows
    of them is the allocation history only."""

    def __init__(self):
        self.m = {n: MachineView(n, "mill", "idle", 0) for n in ("mill1", "mill2")}

    def set(self, name, state, count=None):
        old = self.m[name]
        self.m[name] = MachineView(name, "mill", state, old.part_count if count is None else count)

    def __call__(self):
        return list(self.m.values())


def _released(library, number):
    text = f"%\nO{number}\nG0 X0\nM30\n%\n"
    _, rev = library.create_program(number=number, name=f"part {number}", text=text)
    library.release(rev.id, approver="ann", comment="ok")
    return rev.id


@pytest.mark.parametrize(
    "rule, second_tick",
    [
        # mill2 made a part of job B (O2000); its allocation history says so
        ("same_program_first", [("mill1", "A"), ("mill2", "B")]),
        # FIFO: job A was queued first, and has a part for each mill
        ("fifo", [("mill1", "A"), ("mill2", "A")]),
    ],
)
def test_the_scheduler_sends_a_machine_the_program_it_last_ran(
    library, sessions, rule, second_tick
):
    for name in ("mill1", "mill2"):
        library.register_machine(name, "mill")
    a_rev, b_rev = _released(library, 1000), _released(library, 2000)
    jobs, cell = Jobs(sessions, now=lambda: T0), Cell()
    b = jobs.create(revision_id=b_rev, quantity=2)
    sched = Scheduler(sessions, cell, rule=rule, now=lambda: T0)
    cell.set("mill1", "busy")  # busy with something else: mill2 takes B's first part
    sched.tick()
    assert [x["machine"] for x in jobs.allocations(b.id)] == ["mill2"]
    worker_started(sessions)
    cell.set("mill2", "busy")
    sched.tick()
    # job A is older than B (queued an hour before it, say by another host's clock)
    a = Jobs(sessions, now=lambda: T0 - timedelta(hours=1)).create(revision_id=a_rev, quantity=2)
    cell.set("mill2", "idle", 1)  # the part is made
    cell.set("mill1", "idle")
    decisions = sched.tick()  # counts mill2's part, then gives both mills a part
    assert jobs.get(b.id).done == 1
    names = {a.id: "A", b.id: "B"}
    assert [(x.machine, names[x.job_id]) for x in decisions.of(Allocate)] == second_tick
    recorded = [d for d in jobs.decisions() if d["action"] == "allocate"][-1]
    assert recorded["rule"] == rule and recorded["machine"] == "mill2"
    if rule == "same_program_first":
        assert "same program O2000 already on the machine" in recorded["reason"]


# ------------------------------------------------------------------ chosen per cell


def _cell(**host):
    return {"machines": {"mill1": {"base": "mill3"}}, "host": host}


def test_the_cell_file_chooses_the_rule_and_the_cell_uses_it():
    from server.cell import Cell as ServerCell

    assert load_cell_config(_cell()).host.dispatch_rule == "fifo"
    cfg = load_cell_config(_cell(dispatch_rule="same_program_first then edd"))
    assert ServerCell(cfg).rule == "same_program_first then edd"
    assert ServerCell(cfg, rule="spt").rule == "spt"  # an explicit rule wins


def test_an_unknown_rule_in_the_cell_file_says_where_and_what_is_known():
    with pytest.raises(ConfigError) as exc:
        load_cell_config(_cell(dispatch_rule="lifo"))
    assert str(exc.value).endswith(
        "host.dispatch_rule: unknown dispatch rule 'lifo'; known rules: fifo, spt, edd, cr,"
        " same_program_first (a setup-aware one may fall back to another:"
        " 'same_program_first then edd')"
    )
