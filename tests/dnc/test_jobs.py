"""Job queue, idempotent dispatch requests and the scheduler tick against a real database."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

import pytest

from dnc.db import transaction
from dnc.dispatch import Dispatches, DispatchRequest, create_dispatches
from dnc.errors import IdempotencyMismatch, InvalidUpload, NotFound, WorkflowError
from dnc.jobs import Jobs, Scheduler
from dnc.scheduler import MachineView

PROG = "%\nO1000\nG0 X0\nM30\n%\n"
T0 = datetime(2026, 11, 21, 8, 0, tzinfo=UTC)


@pytest.fixture
def cell(library, sessions):
    for name, kind in (("mill1", "mill"), ("mill2", "mill"), ("lathe1", "lathe")):
        library.register_machine(name, kind)
    _, rev = library.create_program(number=1000, name="bracket", text=PROG)
    library.release(rev.id, approver="ann", comment="ok")
    _, draft = library.create_program(
        number=2000, name="draft", text=PROG.replace("O1000", "O2000")
    )
    return dict(released=rev.id, draft=draft.id)


class FakeCell:
    """Machine status as the monitoring model would report it."""

    def __init__(self):
        self.m = {
            "mill1": MachineView("mill1", "mill", "idle", 0),
            "mill2": MachineView("mill2", "mill", "idle", 0),
            "lathe1": MachineView("lathe1", "lathe", "idle", 0),
        }

    def set(self, name, state, count=None):
        old = self.m[name]
        self.m[name] = MachineView(
            name, old.kind, state, old.part_count if count is None else count
        )

    def finish_part(self, name):
        self.set(name, "idle", self.m[name].part_count + 1)

    def __call__(self):
        return list(self.m.values())


def worker_started(sessions):
    """What the transfer worker does for every pending dispatch: load, verify, cycle start."""
    from sqlalchemy import text

    with sessions() as s, s.begin():
        s.execute(text("UPDATE dispatches SET state = 'done' WHERE state = 'pending'"))


def test_job_needs_a_released_revision_and_sane_values(sessions, cell):
    jobs = Jobs(sessions)
    with pytest.raises(WorkflowError, match="is draft; jobs need a released revision"):
        jobs.create(revision_id=cell["draft"], quantity=1)
    with pytest.raises(InvalidUpload, match="quantity must be at least 1"):
        jobs.create(revision_id=cell["released"], quantity=0)
    with pytest.raises(InvalidUpload, match="time zone"):
        jobs.create(revision_id=cell["released"], quantity=1, due_at=datetime(2026, 12, 1))
    with pytest.raises(NotFound):
        jobs.create(revision_id=999, quantity=1)
    job = jobs.create(revision_id=cell["released"], quantity=2, due_at=T0 + timedelta(hours=4))
    assert (job.status, job.machine_kind, job.due_at) == ("queued", "mill", T0 + timedelta(hours=4))
    assert jobs.get(job.id).due_at == T0 + timedelta(hours=4)  # aware UTC back from any backend


def test_dispatch_is_idempotent_per_key(sessions, cell):
    d = Dispatches(sessions)
    first, created = d.request(key="k1", revision_id=cell["released"], machine="mill1", start=True)
    again, created_again = d.request(
        key="k1", revision_id=cell["released"], machine="mill1", start=True
    )
    assert created and not created_again and first.id == again.id and first.state == "pending"
    assert len(d.list()) == 1
    with pytest.raises(IdempotencyMismatch, match="'k1' was already used for a different request"):
        d.request(key="k1", revision_id=cell["released"], machine="mill2", start=True)


@pytest.mark.parametrize(
    "kwargs, error, message",
    [
        (dict(machine="mill1", revision="draft"), WorkflowError, "only a released revision"),
        (dict(machine="mill9", revision="released"), NotFound, "unknown machine 'mill9'"),
        (dict(machine="mill1", revision="released", mode="punch"), InvalidUpload, "mode must be"),
        (dict(machine="mill1", revision="released", key=""), InvalidUpload, "idempotency key"),
    ],
)
def test_dispatch_refusals(sessions, cell, kwargs, error, message):
    with pytest.raises(error, match=message):
        Dispatches(sessions).request(
            key=kwargs.get("key", "k"),
            revision_id=cell[kwargs["revision"]],
            machine=kwargs["machine"],
            mode=kwargs.get("mode", "memory"),
        )
    assert Dispatches(sessions).list() == []


def test_quantity_four_spreads_over_both_mills_and_completes(sessions, cell):
    jobs, status = Jobs(sessions), FakeCell()
    job = jobs.create(revision_id=cell["released"], quantity=4)
    sched = Scheduler(sessions, status, rule="fifo", now=lambda: T0)
    sched.tick()
    allocs = jobs.allocations(job.id)
    assert [a["machine"] for a in allocs] == ["mill1", "mill2"]
    assert all(a["dispatch_id"] for a in allocs)
    assert jobs.get(job.id).status == "running"
    for _ in range(2):  # both mills make a part, then take the next one
        worker_started(sessions)
        status.set("mill1", "busy")
        status.set("mill2", "busy")
        sched.tick()
        status.finish_part("mill1")
        status.finish_part("mill2")
        sched.tick()
    final = jobs.get(job.id)
    assert (final.done, final.status) == (4, "completed")
    machines = [a["machine"] for a in jobs.allocations(job.id)]
    assert sorted(machines) == ["mill1", "mill1", "mill2", "mill2"]
    assert [d["action"] for d in jobs.decisions(job_id=job.id)].count("complete") == 4
    assert len(Dispatches(sessions).list()) == 4


def test_alarm_interrupts_and_reroutes_the_remaining_quantity(sessions, cell):
    jobs, status = Jobs(sessions), FakeCell()
    status.set("mill2", "busy")  # busy with something else
    job = jobs.create(revision_id=cell["released"], quantity=2)
    sched = Scheduler(sessions, status, now=lambda: T0)
    sched.tick()
    assert [a["machine"] for a in jobs.allocations(job.id)] == ["mill1"]
    status.set("mill1", "alarm")
    status.set("mill2", "idle")
    sched.tick()
    allocs = jobs.allocations(job.id)
    assert [(a["machine"], a["status"]) for a in allocs] == [
        ("mill1", "rerouted"),
        ("mill2", "dispatched"),
    ]
    assert allocs[0]["rerouted_to"] == allocs[1]["id"]
    reasons = [d["reason"] for d in jobs.decisions(job_id=job.id)]
    assert "machine mill1 raised an alarm" in reasons
    assert f"part rerouted to allocation {allocs[1]['id']}" in reasons
    # the interrupted part's program had not been started: its dispatch is called off, so
    # the transfer worker can never start it later
    called_off = Dispatches(sessions).get(allocs[0]["dispatch_id"])
    assert called_off.state == "failed" and "called off: allocation" in called_off.error


def test_a_restarted_scheduler_rebuilds_state_and_duplicates_nothing(sessions, cell):
    jobs, status = Jobs(sessions), FakeCell()
    job = jobs.create(revision_id=cell["released"], quantity=3)
    Scheduler(sessions, status, now=lambda: T0).tick()
    status.set("mill1", "busy")
    status.set("mill2", "busy")
    restarted = Scheduler(sessions, status, now=lambda: T0)  # a new host process
    restarted.tick()
    restarted.tick()
    assert len(jobs.allocations(job.id)) == 2
    assert len(Dispatches(sessions).list()) == 2


def test_cancel_stops_new_allocations_but_lets_running_parts_finish(sessions, cell):
    jobs, status = Jobs(sessions), FakeCell()
    job = jobs.create(revision_id=cell["released"], quantity=5)
    sched = Scheduler(sessions, status, now=lambda: T0)
    sched.tick()
    worker_started(sessions)
    jobs.cancel(job.id)
    status.finish_part("mill1")
    sched.tick()
    after = jobs.get(job.id)
    assert (after.status, after.done) == ("cancelled", 1)
    assert len(jobs.allocations(job.id)) == 2
    with pytest.raises(WorkflowError, match="already cancelled"):
        jobs.cancel(job.id)


def test_edd_rule_takes_the_earliest_due_job(sessions, cell):
    jobs, status = Jobs(sessions), FakeCell()
    status.set("mill2", "busy")
    late = jobs.create(revision_id=cell["released"], quantity=1, due_at=T0 + timedelta(hours=9))
    soon = jobs.create(revision_id=cell["released"], quantity=1, due_at=T0 + timedelta(hours=1))
    Scheduler(sessions, status, rule="edd", now=lambda: T0).tick()
    assert jobs.allocations(soon.id) and not jobs.allocations(late.id)
    reason = jobs.decisions(job_id=soon.id)[0]["reason"]
    assert reason.startswith(
        "EDD chose job 2 for idle mill1 (rank 1 of 2 eligible): EDD: due 2026-11-21T09:00"
    )


def test_a_tick_writes_its_events_in_its_transaction_and_flags_them(sessions, cell):
    from sqlalchemy import event

    from dnc.events import OUTBOX_WRITTEN
    from dnc.outbox import events_after

    jobs, status = Jobs(sessions), FakeCell()
    job = jobs.create(revision_id=cell["released"], quantity=2)
    last = events_after(sessions, 0)[-1].id
    seen = []
    event.listen(sessions, "after_commit", lambda s: seen.append(s.info.get(OUTBOX_WRITTEN)))
    Scheduler(sessions, status, now=lambda: T0).tick()
    assert seen == [True]  # the event hub wakes at this commit
    topics = [(e.topic, e.payload["id"]) for e in events_after(sessions, last)]
    assert topics == [
        ("fmscell/job/allocate", job.id),
        ("fmscell/job/allocate", job.id),
        ("fmscell/job/running", job.id),
    ]


def test_batch_dispatches_reuse_keys_and_refuse_bad_targets(sessions, cell):
    first, _ = Dispatches(sessions).request(
        key="k1", revision_id=cell["released"], machine="mill1", start=True
    )
    ok = [
        DispatchRequest("k1", cell["released"], "mill1", start=True),
        DispatchRequest("k2", cell["released"], "mill2", start=True),
    ]
    with transaction(sessions) as s:
        made = create_dispatches(s, ok, requested_by="t", now=T0)
    assert made[0] == (first.id, False) and made[1][1] and made[1][0] != first.id
    for bad, error, message in [
        (DispatchRequest("k3", cell["released"], "mill9"), NotFound, "unknown machine 'mill9'"),
        (DispatchRequest("k3", cell["draft"], "mill1"), WorkflowError, "is draft; only a released"),
        (DispatchRequest("k3", 999, "mill1"), NotFound, "no revision with id 999"),
        (DispatchRequest("k1", cell["released"], "mill2"), IdempotencyMismatch, "'k1' was already"),
    ]:
        with pytest.raises(error, match=message), transaction(sessions) as s:
            create_dispatches(s, [ok[1], bad], requested_by="t", now=T0)
    assert len(Dispatches(sessions).list()) == 2
    twice = DispatchRequest("k5", cell["released"], "mill2")
    with transaction(sessions) as s:
        (a, made_a), (b, made_b) = create_dispatches(s, [twice, twice], requested_by="t", now=T0)
    assert a == b and made_a and not made_b
    other = DispatchRequest("k6", cell["released"], "mill1")
    with (
        pytest.raises(IdempotencyMismatch, match="'k6' appears twice in one batch"),
        transaction(sessions) as s,
    ):
        create_dispatches(
            s, [other, DispatchRequest("k6", cell["released"], "mill2")], requested_by="t", now=T0
        )
