"""Model-based test: random machine events against the real scheduler and transfer worker.

A hypothesis state machine plays a cell of three simulated machines (part counter, cycle,
selected program, alarms, E-stop, contact, process kills and restarts, an operator's own
program) under the real `Scheduler` (and so the pure allocation core) and the real
`TransferWorker` on SQLite, with a DNC client and a cycle start that act on the simulated
machines. After every step:

- one program per machine: at most one active allocation on a machine;
- no part made twice: parts made of a job's program never exceed its quantity;
- parts counted = parts made, once the host has seen every counter (no machine holding a
  finished part behind lost contact);
- nothing stuck: after the worker and a tick have run, no allocation is `running`, nor
  `dispatched` with its dispatch finished, on a machine that is READY, idle and healthy.

At the end every machine is brought back and the jobs run out: every allocation must then be
final (`completed`, `rerouted` or `failed`) and every job not cancelled completed.
"""

from __future__ import annotations

import shutil
import tempfile
from collections import Counter
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

from hypothesis import settings
from hypothesis import strategies as st
from hypothesis.stateful import (
    RuleBasedStateMachine,
    initialize,
    invariant,
    precondition,
    rule,
)
from sqlalchemy import text

from dnc.allocation import FINAL
from dnc.db import make_engine, migrate, session_factory
from dnc.jobs import Jobs, Scheduler
from dnc.library import Library
from dnc.scheduler import ALARM, BUSY, IDLE, OFFLINE, MachineView
from dnc.transfer import SendResult, TransferError, canonical_text, sha256_text
from dnc.transfer_worker import RetryPolicy, TransferWorker

from .conftest import fake_checker

T0 = datetime(2026, 11, 21, 8, 0, tzinfo=UTC)
NAMES = ("mill1", "mill2", "mill3")
LOST_S = 30.0
OPERATOR_PROGRAM = "O9999"
_TEMPLATE: dict[str, Path] = {}
# a database per example: in memory-backed /dev/shm where there is one (fsyncs are most of
# an example's time on a disk)
_SCRATCH = "/dev/shm" if Path("/dev/shm").is_dir() else None


class HostDied(BaseException):
    """The host process is killed (not an error the worker may catch)."""


class StartRefused(RuntimeError):
    """The machine refused cycle start (as server.host.StartRefused): nothing ran."""

    refused = True


@dataclass
class SimMachine:
    """What the control does, as far as the host can see it through its faces."""

    alive: bool = True
    connected: bool = True
    offline_s: float = 0.0
    in_cycle: bool = False
    program: str = ""
    count: int = 0
    alarm: str | None = None  # stops the cycle
    lube_low: bool = False  # FAULT-level, the machine cuts on
    estop: bool = False
    memory: set[int] = field(default_factory=set)
    unseen: bool = False  # a part counted that no tick has looked at yet
    # A run stopped (reset, alarm, E-stop) that no tick has looked at yet. The host sees the
    # machine as its status at each tick (0.5 s): a reset and an operator's own program run
    # to its end between two ticks would look like our part; an operator needs longer than
    # a tick to start another program, so the model lets one start only after a look.
    stop_unseen: bool = False
    die_on_start: bool = False  # the host is killed right after pressing cycle start
    alarm_in_transfer: bool = False  # a stopping alarm arrives while a program is loading

    def healthy_idle(self) -> bool:
        return (
            self.alive
            and self.connected
            and not self.in_cycle
            and self.alarm is None
            and not self.estop
            and not self.lube_low
        )

    def view(self, name: str) -> MachineView:
        if not self.connected:
            state = OFFLINE
        elif self.alarm is not None or self.estop or self.lube_low:
            state = ALARM
        elif self.in_cycle:
            state = BUSY
        else:
            state = IDLE
        fault = self.alarm or ("plc_cond FAULT lube_level_low" if self.lube_low else None)
        return MachineView(
            name,
            "mill",
            state,
            self.count,
            connected=self.connected,
            offline_s=self.offline_s,
            in_cycle=self.in_cycle,
            program=self.program,
            estop=self.estop,
            alarm=fault,
        )


class FakeClient:
    def __init__(self, model: CellModel, name: str) -> None:
        self.model, self.name = model, name

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def _machine(self) -> SimMachine:
        m = self.model.machines[self.name]
        if not (m.alive and m.connected):
            raise TransferError("connect", f"{self.name}: no answer")
        return m

    def send_program(self, program: str, *, number: int) -> SendResult:
        m = self._machine()
        if m.alarm_in_transfer:
            # an alarm while the tape runs in, and the scheduler ticks meanwhile: the
            # allocation is interrupted and its dispatch called off under the worker's feet
            m.alarm_in_transfer = False
            m.alarm = "servo FAULT 2101 following error"
            m.in_cycle = False
            self.model.scheduler.tick()
        m.memory.add(number)
        sha = sha256_text(canonical_text(program))
        return SendResult(number, len(program), sha, len(program), 0)

    def punch_sha256(self, number: int, *, expected: str) -> str:
        if number not in self._machine().memory:
            raise TransferError("verify", f"O{number:04d} not in memory")
        return expected


class CellModel(RuleBasedStateMachine):
    def __init__(self) -> None:
        super().__init__()
        self.dir = Path(tempfile.mkdtemp(prefix="alloc-model-", dir=_SCRATCH))
        db = self.dir / "cell.db"
        shutil.copy(_template(), db)
        self.engine = make_engine(f"sqlite:///{db}")
        self.sessions = session_factory(self.engine)
        self.machines = {n: SimMachine() for n in NAMES}
        self.made: Counter[str] = Counter()  # parts made per job program
        self.jobs_api = Jobs(self.sessions, now=lambda: T0)
        self.jobs: dict[str, int] = {}  # program -> job id
        self.quantity: dict[str, int] = {}
        self.cancelled: set[str] = set()
        self.new_host()

    # ------------------------------------------------------------------ the host
    def new_host(self) -> None:
        """A host process: nothing carried over but the database."""
        self.scheduler = Scheduler(self.sessions, self.views, now=lambda: T0, lost_contact_s=LOST_S)
        self.worker = TransferWorker(
            self.sessions,
            client_factory=lambda host, port, profile: FakeClient(self, port_names[port]),
            starter=self.start,
            retry=RetryPolicy(max_attempts=3, base_s=0.0, cap_s=0.0),
            now=lambda: T0,
            part_counter=self.part_count,
        )

    def part_count(self, name: str) -> int | None:
        m = self.machines[name]
        return m.count if m.alive and m.connected else None

    def views(self) -> list[MachineView]:
        return [m.view(n) for n, m in self.machines.items()]

    def start(self, name: str, number: int) -> None:
        m = self.machines[name]
        if not m.healthy_idle() or number not in m.memory:
            raise StartRefused(f"{name}: cycle start refused")
        before = m.count
        m.in_cycle, m.program = True, f"O{number:04d}"
        if m.die_on_start:
            m.die_on_start = False
            raise HostDied
        return before

    @initialize(quantities=st.lists(st.integers(1, 4), min_size=1, max_size=3))
    def jobs_queued(self, quantities):
        lib = Library(self.sessions, checker=fake_checker)
        for n, name in enumerate(NAMES):
            port_names[7100 + n] = name
            lib.register_machine(name, "mill", dnc_address=f"127.0.0.1:{7100 + n}")
        for i, qty in enumerate(quantities):
            number = 101 + i
            _, rev = lib.create_program(
                number=number, name=f"p{number}", text=f"%\nO{number:04d}\nG0 X0\nM30\n%\n"
            )
            lib.release(rev.id, approver="a", comment="ok")
            job = self.jobs_api.create(revision_id=rev.id, quantity=qty)
            self.jobs[f"O{number:04d}"] = job.id
            self.quantity[f"O{number:04d}"] = qty

    # ------------------------------------------------------------------ host rules
    @rule()
    def tick(self):
        self.scheduler.tick()
        for m in self.machines.values():
            if m.connected:
                m.unseen = m.stop_unseen = False

    @rule()
    def work(self):
        try:
            self.worker.run_once()
        except HostDied:
            self.new_host()

    @rule()
    def host_restart(self):
        self.new_host()

    @rule(name=st.sampled_from(NAMES))
    def host_dies_at_next_cycle_start(self, name):
        self.machines[name].die_on_start = True

    @rule(name=st.sampled_from(NAMES))
    def alarm_while_the_program_loads(self, name):
        self.machines[name].alarm_in_transfer = True

    @rule()
    def settle(self):
        """The worker and a tick run: nothing may then be stuck on a healthy idle machine."""
        self.work()
        self.tick()
        with self.engine.connect() as conn:
            rows = conn.execute(
                text(
                    "SELECT a.id, a.machine, a.status, d.state FROM allocations a "
                    "JOIN dispatches d ON d.id = a.dispatch_id "
                    "WHERE a.status IN ('running', 'dispatched')"
                )
            ).all()
        for row in rows:
            if self.machines[row.machine].healthy_idle():
                assert row.status != "running", f"stuck running on idle {row.machine}: {row}"
                assert row.state not in ("done", "failed"), f"stuck on idle: {row}"

    @rule(program=st.sampled_from(["O0101", "O0102", "O0103"]))
    def cancel(self, program):
        if program in self.jobs and program not in self.cancelled:
            status = self.jobs_api.get(self.jobs[program]).status
            if status not in ("completed", "cancelled"):
                self.jobs_api.cancel(self.jobs[program])
                self.cancelled.add(program)

    # ------------------------------------------------------------------ machine rules
    @rule(name=st.sampled_from(NAMES))
    def cycle_end(self, name):
        m = self.machines[name]
        if m.alive and m.in_cycle:
            m.in_cycle, m.count, m.unseen = False, m.count + 1, True
            if m.program in self.jobs:
                self.made[m.program] += 1

    @rule(name=st.sampled_from(NAMES))
    def reset(self, name):
        m = self.machines[name]
        if m.alive:
            m.stop_unseen = m.stop_unseen or m.in_cycle
            m.in_cycle, m.alarm = False, None

    @rule(name=st.sampled_from(NAMES))
    def stopping_alarm(self, name):
        m = self.machines[name]
        if m.alive:
            m.stop_unseen = m.stop_unseen or m.in_cycle
            m.alarm, m.in_cycle = "servo FAULT 2101 following error", False

    @rule(name=st.sampled_from(NAMES), low=st.booleans())
    def lube_level(self, name, low):
        self.machines[name].lube_low = low  # FAULT, but the machine cuts on

    @rule(name=st.sampled_from(NAMES), pressed=st.booleans())
    def emergency_stop(self, name, pressed):
        m = self.machines[name]
        if m.alive:
            m.estop = pressed
            if pressed:
                m.stop_unseen = m.stop_unseen or m.in_cycle
                m.in_cycle = False

    @rule(name=st.sampled_from(NAMES))
    def operator_runs_own_program(self, name):
        m = self.machines[name]
        if m.healthy_idle() and not m.stop_unseen:
            m.program, m.in_cycle = OPERATOR_PROGRAM, True

    @rule(name=st.sampled_from(NAMES))
    def operator_selects_another_program(self, name):
        m = self.machines[name]
        if m.alive and not m.in_cycle:
            m.program = OPERATOR_PROGRAM

    @precondition(lambda self: any(m.alive and not m.unseen for m in self.machines.values()))
    @rule(name=st.sampled_from(NAMES))
    def kill_machine_process(self, name):
        # A part finished and the process killed before the host read its counter is lost
        # with the counter (it lives in the control's memory): such kills are not played.
        m = self.machines[name]
        if m.alive and not m.unseen:
            self.machines[name] = SimMachine(alive=False, connected=False, offline_s=m.offline_s)

    @rule(name=st.sampled_from(NAMES))
    def restart_machine_process(self, name):
        m = self.machines[name]
        if not m.alive:
            self.machines[name] = SimMachine()  # a fresh control: counter 0, nothing selected

    @rule(name=st.sampled_from(NAMES))
    def lose_contact(self, name):
        m = self.machines[name]
        if m.alive:
            m.connected = False  # the machine cuts on behind the broken link

    @rule(name=st.sampled_from(NAMES))
    def contact_back(self, name):
        m = self.machines[name]
        if m.alive and not m.connected:
            m.connected, m.offline_s = True, 0.0

    @rule(seconds=st.floats(1.0, 40.0))
    def time_passes(self, seconds):
        for m in self.machines.values():
            if not m.connected:
                # A machine that cuts on behind a broken link comes back within the time-out
                # here: past it, it is taken as lost by design (docs/dnc.md).
                limit = float("inf") if not m.alive else LOST_S - 1.0
                m.offline_s = min(limit, m.offline_s + seconds)

    # ------------------------------------------------------------------ invariants
    def _allocations(self):
        with self.engine.connect() as conn:
            return conn.execute(
                text("SELECT id, job_id, machine, status FROM allocations ORDER BY id")
            ).all()

    @invariant()
    def books(self):
        if not self.jobs:
            return
        allocs = self._allocations()
        active = Counter(a.machine for a in allocs if a.status in ("dispatched", "running"))
        assert max(active.values(), default=0) <= 1, f"two programs on a machine: {allocs}"
        all_seen = not any(m.unseen for m in self.machines.values())
        for program, job_id in self.jobs.items():
            made, qty = self.made[program], self.quantity[program]
            assert made <= qty, f"job {program}: {made} parts made of {qty}"
            done = self.jobs_api.get(job_id).done
            assert done <= made, f"job {program}: {done} counted, {made} made"
            if all_seen:
                assert done == made, f"job {program}: {done} counted, {made} made"

    def teardown(self):
        try:
            if self.jobs:
                self._drain()
        finally:
            self.engine.dispose()
            shutil.rmtree(self.dir, ignore_errors=True)

    def _drain(self):
        """Every machine brought back and healthy; the jobs run out."""
        for _ in range(60):
            for name, m in list(self.machines.items()):
                if not m.alive:
                    self.machines[name] = m = SimMachine()
                m.connected, m.offline_s, m.alarm, m.estop, m.lube_low = (
                    True,
                    0.0,
                    None,
                    False,
                    False,
                )
                m.die_on_start = m.alarm_in_transfer = False
                if m.in_cycle:
                    self.cycle_end(name)
            self.work()
            self.tick()
            allocs = self._allocations()
            open_jobs = [
                p
                for p, j in self.jobs.items()
                if p not in self.cancelled and self.jobs_api.get(j).status != "completed"
            ]
            if not open_jobs and all(a.status in FINAL for a in allocs):
                break
        self.books()
        assert all(a.status in FINAL for a in allocs), allocs
        for program, job_id in self.jobs.items():
            job = self.jobs_api.get(job_id)
            if program not in self.cancelled:
                assert (job.status, job.done) == ("completed", job.quantity), job


port_names: dict[int, str] = {}


def _template() -> Path:
    """One migrated database, copied for each example (migrating is most of the set-up)."""
    if "db" not in _TEMPLATE:
        path = Path(tempfile.mkdtemp(prefix="alloc-template-", dir=_SCRATCH)) / "template.db"
        engine = make_engine(f"sqlite:///{path}")
        migrate(engine)
        with engine.connect() as conn:
            conn.exec_driver_sql("PRAGMA wal_checkpoint(TRUNCATE)")
        engine.dispose()
        _TEMPLATE["db"] = path
    return _TEMPLATE["db"]


# Derandomized: the suite is deterministic, so CI runs the same 60 event sequences every
# time. Wider exploration (`--hypothesis-seed=N` with derandomize off, more examples) is how
# the sequences replayed below were found.
CellModel.TestCase.settings = settings(
    max_examples=60, stateful_step_count=40, deadline=None, derandomize=True
)
TestAllocations = CellModel.TestCase


def play(model: CellModel, *steps) -> None:
    """Replay a found sequence, checking the invariants after every step as hypothesis does."""
    model.books()
    for name, kwargs in steps:
        getattr(model, name)(**kwargs)
        model.books()


def test_host_killed_pressing_cycle_start_before_the_next_host_recovers():
    """Found with --hypothesis-seed=22: the host dies pressing cycle start on mill2 (the
    dispatch stays `starting`); the next host's scheduler ticks before its worker has
    recovered that dispatch, the machine counts the part meanwhile, and the tick waited for a
    start outcome no worker would deliver: the part counted by the machine, not by the job."""
    model = CellModel()
    try:
        play(
            model,
            ("jobs_queued", dict(quantities=[2, 2])),
            ("operator_runs_own_program", dict(name="mill1")),
            ("host_dies_at_next_cycle_start", dict(name="mill2")),
            ("tick", {}),
            ("settle", {}),  # the worker presses cycle start on mill2 and the host dies
            ("cycle_end", dict(name="mill2")),
            ("tick", {}),  # a new host's tick, its worker not run yet: the part is counted
        )
        assert model.jobs_api.get(model.jobs["O0101"]).done == 1
    finally:
        model.teardown()
