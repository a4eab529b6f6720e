"""Property test: random machine histories, restarts and crashed ticks keep the job books right."""

from __future__ import annotations

from collections import Counter
from datetime import UTC, datetime
from unittest import mock

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from sqlalchemy import text

from dnc.db import make_engine, migrate, session_factory
from dnc.jobs import Jobs, Scheduler
from dnc.library import Library
from dnc.scheduler import MachineView

from .conftest import fake_checker

T0 = datetime(2026, 11, 21, 8, 0, tzinfo=UTC)
MACHINES = {"mill1": (), "mill2": ("g1",), "mill3": ("g1",), "mill4": ()}
# What each machine does between two ticks.
MOVES = st.sampled_from(["finish", "finish", "busy", "idle", "alarm", "offline", "stay"])
STEPS = st.lists(
    st.tuples(
        st.tuples(*[MOVES] * len(MACHINES)),
        st.sampled_from(["tick", "tick", "tick", "restart", "crash", "fail_dispatch", "cancel"]),
    ),
    max_size=14,
)
JOBS = st.lists(
    st.tuples(st.integers(1, 5), st.sampled_from([None, "g1"]), st.integers(0, 1)),
    min_size=1,
    max_size=4,
)


class Crash(Exception):
    """The host dies in the middle of writing a tick."""


@settings(
    max_examples=20, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(jobs_spec=JOBS, steps=STEPS, rule=st.sampled_from(["fifo", "spt", "edd", "cr"]))
def test_job_books_stay_right(tmp_path_factory, jobs_spec, steps, rule):
    eng = make_engine(f"sqlite:///{tmp_path_factory.mktemp('sched') / 'sched.db'}")
    migrate(eng)
    sessions = session_factory(eng)
    lib = Library(sessions, checker=fake_checker)
    for name in MACHINES:
        lib.register_machine(name, "mill")
    _, rev = lib.create_program(number=1, name="p", text="%\nO0001\nG0 X0\nM30\n%\n")
    lib.release(rev.id, approver="a", comment="ok")
    jobs = Jobs(sessions, now=lambda: T0)
    made = [
        jobs.create(revision_id=rev.id, quantity=q, machine_group=g, priority=p)
        for q, g, p in jobs_spec
    ]
    state = {name: ["idle", 0] for name in MACHINES}

    def status():
        return [MachineView(n, "mill", s, c, MACHINES[n]) for n, (s, c) in state.items()]

    sched = Scheduler(sessions, status, rule=rule, now=lambda: T0)
    for moves, op in steps:
        for name, move in zip(MACHINES, moves, strict=True):
            if move == "finish":
                state[name] = ["idle", state[name][1] + 1]
            elif move != "stay":
                state[name][0] = move
        if op == "restart":  # a new host process: nothing carried over but the database
            sched = Scheduler(sessions, status, rule=rule, now=lambda: T0)
        elif op == "crash":
            before = _snapshot(eng)
            with mock.patch("dnc.jobs.record_many", side_effect=Crash), pytest.raises(Crash):
                sched.tick()
            assert _snapshot(eng) == before  # all of the tick or none of it
            continue
        elif op == "fail_dispatch":
            with eng.begin() as conn:
                conn.execute(
                    text(
                        "UPDATE dispatches SET state = 'failed' WHERE id = (SELECT max(id) FROM dispatches)"
                    )
                )
        elif op == "cancel" and jobs.get(made[0].id).status not in ("completed", "cancelled"):
            jobs.cancel(made[0].id)
        sched.tick()
        _check_books(eng, jobs, made, rule)
    eng.dispose()


def _snapshot(eng) -> dict:
    with eng.connect() as conn:
        return {
            t: conn.execute(text(f"SELECT * FROM {t} ORDER BY id")).all()
            for t in ("jobs", "allocations", "dispatches", "decisions", "audit_log", "outbox")
        }


def _check_books(eng, jobs: Jobs, made, rule: str) -> None:
    with eng.connect() as conn:
        allocs = conn.execute(
            text(
                "SELECT a.job_id, a.machine, a.status, d.idempotency_key FROM allocations a "
                "JOIN dispatches d ON d.id = a.dispatch_id ORDER BY a.id"
            )
        ).all()
        counts = {
            t: conn.execute(text(f"SELECT count(*) FROM {t}")).scalar_one()
            for t in ("audit_log", "outbox", "dispatches", "allocations")
        }
    active = [a for a in allocs if a.status in ("dispatched", "running")]
    # One program at a time on a machine; every allocation has its own dispatch.
    assert max(Counter(a.machine for a in active).values(), default=0) <= 1
    assert counts["dispatches"] == counts["allocations"] == len({a.idempotency_key for a in allocs})
    assert counts["audit_log"] == counts["outbox"]  # every change wrote its event
    for job in made:
        now = jobs.get(job.id)
        mine = [a for a in allocs if a.job_id == job.id]
        running = sum(a.status in ("dispatched", "running") for a in mine)
        assert now.done + running <= now.quantity  # never more parts than ordered
        assert [a.idempotency_key for a in mine] == [
            f"job-{job.id}-allocation-{n}" for n in range(1, len(mine) + 1)
        ]
        # a job cancelled with its last part on a machine keeps the part (done reaches the
        # quantity) and stays cancelled: cancelling stops new allocations, not a cut under way
        if now.status == "completed" or now.done < now.quantity:
            assert (now.status == "completed") == (now.done == now.quantity)
        else:
            assert now.status == "cancelled"
        if now.status != "cancelled" and now.done < now.quantity:
            assert (now.status == "running") == (running > 0)
        decisions = jobs.decisions(job_id=job.id)
        assert sum(d["action"] == "complete" for d in decisions) == now.done
        assert sum(d["action"] == "allocate" for d in decisions) == len(mine)
        assert all(
            d["reason"].startswith(f"{rule.upper()} chose job {job.id} for idle ")
            for d in decisions
            if d["action"] == "allocate"
        )
