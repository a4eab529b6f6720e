"""Issue 14 items 1, 2 and 6 through the real scheduler and transfer worker (SQLite and
PostgreSQL): a reset or a restarted control frees the machine, cancelling a job frees it, a
FAULT while the machine cuts on is noted and the part counted once, a dispatch called off is
never started, a lost machine's part is rerouted, a host killed in cycle start makes no part
twice."""

from __future__ import annotations

import pytest
from sqlalchemy import text

from dnc.dispatch import Dispatches
from dnc.jobs import Jobs, Scheduler
from dnc.transfer_worker import RetryPolicy, TransferWorker

from .test_allocation_model import T0, FakeClient, HostDied, SimMachine

NAMES = ("mill1", "mill2")


class Rig:
    """Two simulated mills, the real scheduler and transfer worker, one job's program."""

    def __init__(self, sessions, library, quantity: int, *, lost_contact_s: float = 30.0):
        self.sessions = sessions
        self.machines = {n: SimMachine() for n in NAMES}
        self.ports = {7200 + i: n for i, n in enumerate(NAMES)}
        for port, name in self.ports.items():
            library.register_machine(name, "mill", dnc_address=f"127.0.0.1:{port}")
        _, rev = library.create_program(number=101, name="p", text="%\nO0101\nG0 X0\nM30\n%\n")
        library.release(rev.id, approver="a", comment="ok")
        self.revision = rev.id
        self.jobs = Jobs(sessions, now=lambda: T0)
        self.job = self.jobs.create(revision_id=rev.id, quantity=quantity).id
        self.started: list[str] = []
        self.lost_contact_s = lost_contact_s
        self.new_host()

    def new_host(self):
        self.scheduler = Scheduler(
            self.sessions,
            lambda: [m.view(n) for n, m in self.machines.items()],
            now=lambda: T0,
            lost_contact_s=self.lost_contact_s,
        )
        self.worker = TransferWorker(
            self.sessions,
            client_factory=lambda host, port, profile: FakeClient(self, self.ports[port]),
            starter=self.start,
            retry=RetryPolicy(max_attempts=2, base_s=0.0, cap_s=0.0),
            now=lambda: T0,
        )

    def start(self, name, number):
        m = self.machines[name]
        if not m.healthy_idle() or number not in m.memory:
            raise RuntimeError(f"{name}: cycle start refused")
        self.started.append(name)
        before, m.in_cycle, m.program = m.count, True, f"O{number:04d}"
        if m.die_on_start:
            m.die_on_start = False
            raise HostDied
        return before

    def round(self):
        """The host's loops once: scheduler tick, transfer worker, scheduler tick."""
        self.scheduler.tick()
        self.worker.run_once()
        self.scheduler.tick()

    def finish(self, name):
        m = self.machines[name]
        assert m.in_cycle, f"{name} is not cutting"
        m.in_cycle, m.count = False, m.count + 1

    def allocs(self):
        return [(a["machine"], a["status"]) for a in self.jobs.allocations(self.job)]

    def reasons(self, action):
        return [d["reason"] for d in self.jobs.decisions(job_id=self.job) if d["action"] == action]


@pytest.fixture
def rig(sessions, library):
    return lambda quantity, **kw: Rig(sessions, library, quantity, **kw)


def test_operator_reset_of_a_cutting_machine_ends_its_allocation_and_reroutes_the_part(rig):
    r = rig(2)
    r.round()
    assert r.allocs() == [("mill1", "running"), ("mill2", "running")]
    r.machines["mill1"].in_cycle = False  # RESET at mill1's panel: READY, idle, no part
    r.finish("mill2")
    r.round()
    assert r.allocs()[:2] == [("mill1", "rerouted"), ("mill2", "completed")]
    assert any("cycle on mill1 ended without a part" in why for why in r.reasons("interrupt"))
    r.round()
    for name in NAMES:
        if r.machines[name].in_cycle:
            r.finish(name)
    r.round()
    job = r.jobs.get(r.job)
    assert (job.status, job.done) == ("completed", 2)
    assert len(r.started) == 3  # two parts, one started again after the reset


def test_a_restarted_machine_control_frees_its_allocation(rig):
    r = rig(1)
    r.machines["mill1"].count = 7  # parts made before
    r.machines["mill2"].estop = True  # out of the way
    r.round()
    assert r.allocs() == [("mill1", "running")]
    r.machines["mill1"] = SimMachine()  # process killed and restarted: counter 0, no program
    r.scheduler.tick()
    assert r.allocs() == [("mill1", "interrupted")]
    assert "part counter of mill1 went back from 7 to 0" in r.reasons("interrupt")[0]
    r.round()  # the part goes to the machine again (it is READY and idle)
    r.finish("mill1")
    r.round()
    assert r.allocs() == [("mill1", "rerouted"), ("mill1", "completed")]
    assert r.jobs.get(r.job).done == 1


def test_cancelling_a_job_frees_the_machines_its_parts_were_waiting_for(rig):
    r = rig(3)
    r.scheduler.tick()  # allocated, programs not yet sent
    r.jobs.cancel(r.job)
    r.scheduler.tick()
    assert r.allocs() == [("mill1", "failed"), ("mill2", "failed")]
    assert r.worker.run_once() == []  # nothing left to send, nothing started
    assert r.started == []
    states = {d.state for d in Dispatches(r.sessions).list()}
    assert states == {"failed"}
    # the machines take the next job at once
    other = r.jobs.create(revision_id=r.revision, quantity=1)
    r.scheduler.tick()
    assert [a["status"] for a in r.jobs.allocations(other.id)] == ["dispatched"]


def test_a_fault_while_the_machine_cuts_on_is_noted_and_the_part_counted_once(rig):
    r = rig(1)
    r.machines["mill2"].estop = True
    r.round()
    r.machines["mill1"].lube_low = True  # FAULT lube_level_low; the cycle goes on
    r.round()
    r.round()
    assert r.allocs() == [("mill1", "running")]
    notes = r.reasons("note")
    assert notes == ["alarm while cutting on: plc_cond FAULT lube_level_low"]  # once
    assert r.jobs.allocations(r.job)[0]["note"] == notes[0]
    r.machines["mill2"].estop = False
    r.round()  # mill2 is idle and healthy, but there is no part left for it
    assert r.allocs() == [("mill1", "running")] and r.started == ["mill1"]
    r.finish("mill1")
    r.round()
    job = r.jobs.get(r.job)
    assert (job.status, job.done, r.started) == ("completed", 1, ["mill1"])


def test_a_dispatch_called_off_during_its_transfer_is_never_started(rig):
    r = rig(1)
    r.machines["mill2"].estop = True
    r.machines["mill1"].alarm_in_transfer = True  # alarm + a tick while the tape runs in
    r.scheduler.tick()
    r.worker.run_once()
    assert r.started == []
    assert r.allocs() == [("mill1", "interrupted")]
    (dispatch,) = Dispatches(r.sessions).list()
    assert dispatch.state == "failed" and dispatch.error.startswith("called off: allocation")
    r.worker.run_once()  # never taken up again
    assert r.started == [] and Dispatches(r.sessions).get(dispatch.id).state == "failed"


def test_the_start_is_refused_to_an_allocation_no_longer_active(rig, sessions):
    r = rig(1)
    r.machines["mill2"].estop = True
    r.scheduler.tick()
    # the allocation ended and its dispatch still verifying (as a tick racing the worker
    # between its two transactions would leave them): the start's claim must refuse
    with sessions() as s, s.begin():
        s.execute(text("UPDATE allocations SET status = 'interrupted'"))
        s.execute(text("UPDATE dispatches SET state = 'verifying'"))
    from dnc.transfer_worker import _START

    with sessions() as s, s.begin():
        claimed = s.execute(
            _START,
            dict(
                dispatch_id=1,
                state="starting",
                updated_at=T0,
                bytes_sent=0,
                verified=True,
                error=None,
            ),
        ).first()
    assert claimed is None


def test_a_lost_machine_keeps_its_part_within_the_time_out_and_loses_it_after(rig):
    r = rig(1, lost_contact_s=30.0)
    r.machines["mill2"].estop = True
    r.round()
    lost = r.machines["mill1"]
    lost.alive = lost.connected = False
    lost.offline_s = 29.0
    r.scheduler.tick()
    assert r.allocs() == [("mill1", "running")]
    lost.offline_s = 31.0
    r.machines["mill2"].estop = False
    r.round()
    assert r.allocs() == [("mill1", "rerouted"), ("mill2", "running")]
    assert "contact with mill1 lost for 31 s (time-out 30 s)" in r.reasons("interrupt")[0]
    r.finish("mill2")
    r.round()
    assert r.jobs.get(r.job).done == 1


def test_a_host_killed_in_cycle_start_makes_no_part_twice(rig):
    r = rig(1)
    r.machines["mill2"].estop = True
    r.machines["mill1"].die_on_start = True
    r.scheduler.tick()
    with pytest.raises(HostDied):
        r.worker.run_once()
    r.new_host()  # the restarted host fails the dispatch caught in `starting` ...
    r.machines["mill2"].estop = False
    r.round()
    # ... but mill1 took the start and is cutting the part: it stays the allocation's
    assert r.allocs() == [("mill1", "running")]
    assert r.started == ["mill1"]
    r.finish("mill1")
    r.round()
    job = r.jobs.get(r.job)
    assert (job.status, job.done, r.started) == ("completed", 1, ["mill1"])


def test_a_start_claimed_between_the_ticks_read_and_write_wins_and_the_tick_decides_again(
    rig, sessions
):
    """The other order of the race: the worker claims the start (commits `starting`) after
    the tick read the dispatch as `verifying` and before it calls the dispatch off. The
    tick's conditional call-off finds it moved on, the tick is rolled back and decided again:
    the allocation waits for the start's outcome instead of being interrupted."""
    r = rig(1)
    r.machines["mill2"].estop = True
    r.scheduler.tick()
    with sessions() as s, s.begin():
        s.execute(text("UPDATE dispatches SET state = 'verifying'"))
    r.machines["mill1"].alarm = "servo FAULT 2101"  # would interrupt a part not yet started
    looks = []

    def machines_while_the_worker_claims():
        if not looks:  # first look: the worker's claim lands now, in its own transaction
            with sessions() as s, s.begin():
                s.execute(text("UPDATE dispatches SET state = 'starting'"))
        looks.append(1)
        return [m.view(n) for n, m in r.machines.items()]

    tick = Scheduler(sessions, machines_while_the_worker_claims, now=lambda: T0)
    tick.tick()
    assert len(looks) == 2  # decided twice
    assert r.allocs() == [("mill1", "dispatched")]
    assert Dispatches(sessions).list()[0].state == "starting"
    assert r.reasons("interrupt") == []
