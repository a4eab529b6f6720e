"""The FMS scheduler's pure core: from the cell's state, decide what happens next.

One tick = read everything (jobs, active allocations, machines' status) -> `decide()` ->
apply the returned actions in one transaction. Because the tick rebuilds its view from the
database every time and `decide()` is a pure function of that view, a host that restarts
loses nothing: the next tick sees the same state and takes up where the last one stopped.

An allocation is one part of a job on one machine: one program run, ended by M30 and counted
by the machine's part counter. Allocating part by part spreads a job over every eligible
idle machine and makes rerouting after an alarm exact: only the interrupted part goes back.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from datetime import datetime

from dnc.allocation import (
    ACTIVE,
    COMPLETED,
    DEFAULT_LOST_CONTACT_S,
    DISPATCHED,
    INTERRUPTED,
    RUNNING,
    START_FAILED,
    STARTED,
    Alloc,
    Look,
    settle,
    step,
)
from dnc.requirements import Needs
from dnc.rules import JobView, Rule

IDLE, BUSY, ALARM, OFFLINE = "idle", "busy", "alarm", "offline"


@dataclass(frozen=True, slots=True)
class MachineView:
    name: str
    kind: str
    state: str  # idle | busy | alarm | offline (from the monitoring model)
    part_count: int
    groups: tuple[str, ...] = ()
    # What the allocation state machine looks at (dnc.allocation.Look); None = derive it
    # from `state` (busy = in cycle; offline = contact lost).
    connected: bool | None = None
    offline_s: float = 0.0
    in_cycle: bool | None = None
    program: str | None = None
    estop: bool = False
    alarm: str | None = None  # a FAULT-level alarm's text ("" if unknown); None = none
    warnings: tuple[str, ...] = ()
    axes: tuple[str, ...] = ()  # its configured axes (X Y Z A); () = not known

    def look(self) -> Look:
        alarm = self.alarm if self.alarm is not None else ("" if self.state == ALARM else None)
        return Look(
            connected=self.state != OFFLINE if self.connected is None else self.connected,
            offline_s=self.offline_s,
            in_cycle=self.state == BUSY if self.in_cycle is None else self.in_cycle,
            program=self.program,
            part_count=self.part_count,
            alarm=alarm,
            estop=self.estop,
            warnings=self.warnings,
        )


@dataclass(frozen=True, slots=True)
class JobState:
    id: int
    machine_kind: str
    machine_group: str | None
    quantity: int
    done: int
    priority: int
    created_at: datetime
    due_at: datetime | None
    cycle_time_s: float
    cancelled: bool = False
    program: str | None = None  # O1234: the program the job's parts run
    # what a machine must be and have to run its program; None = its machine kind alone
    needs: Needs | None = None

    def runs_on(self, machine: MachineView) -> bool:
        """Whether the machine can make its parts: its program's needs (kind, axes) and
        the job's machine group."""
        if self.machine_group is not None and self.machine_group not in machine.groups:
            return False
        if self.needs is None:
            return self.machine_kind == machine.kind
        return self.needs.met_by(machine.kind, machine.axes)


@dataclass(frozen=True, slots=True)
class AllocationState:
    id: int
    job_id: int
    machine: str
    parts_at_start: int  # the machine's part counter when the allocation was made
    running: bool  # the machine has been seen busy with it
    dispatch_failed: bool = False
    # The dispatch's phase (dnc.allocation.DISPATCH_PHASES); None = derive it from
    # `dispatch_failed` (failed, else started).
    dispatch: str | None = None
    program: str | None = None  # O1234: the program the allocation runs
    state: str | None = None  # None = running/dispatched from `running`; or "interrupted"
    note: str = ""  # the last note recorded on it

    def alloc(self, job_open: bool) -> Alloc:
        phase = self.dispatch or (START_FAILED if self.dispatch_failed else STARTED)
        state = self.state or (RUNNING if self.running else DISPATCHED)
        return Alloc(state, self.machine, self.parts_at_start, phase, self.program, job_open)


@dataclass(frozen=True, slots=True)
class Allocate:
    job_id: int
    machine: str
    part_count: int
    reason: str


@dataclass(frozen=True, slots=True)
class MarkRunning:
    allocation_id: int


@dataclass(frozen=True, slots=True)
class Complete:
    allocation_id: int
    job_id: int
    parts: int


@dataclass(frozen=True, slots=True)
class Interrupt:
    allocation_id: int
    job_id: int
    reason: str
    cancel_dispatch: bool = False  # its program was never started: call the dispatch off


@dataclass(frozen=True, slots=True)
class Reroute:
    """An interrupted allocation's part goes to this tick's `to`-th Allocate."""

    allocation_id: int
    job_id: int
    to: int


@dataclass(frozen=True, slots=True)
class Fail:
    allocation_id: int
    job_id: int
    reason: str


@dataclass(frozen=True, slots=True)
class Note:
    """Recorded on the allocation (an alarm or warning while the machine cut on)."""

    allocation_id: int
    job_id: int
    text: str


@dataclass
class Decisions:
    actions: list = field(default_factory=list)

    def of(self, kind: type) -> list:
        return [a for a in self.actions if isinstance(a, kind)]


def decide(
    jobs: list[JobState],
    allocations: list[AllocationState],
    machines: list[MachineView],
    rule: Rule,
    rule_name: str,
    now: datetime,
    *,
    lost_contact_s: float = DEFAULT_LOST_CONTACT_S,
    last_programs: Mapping[str, str] | None = None,
) -> Decisions:
    """`last_programs`: the program of each machine's last allocation, for a setup-aware
    rule when the machine does not report a selected program."""
    out = Decisions()
    by_name = {m.name: m for m in machines}
    busy_machines: set[str] = set()
    active_parts: dict[int, int] = {}
    done_now: dict[int, int] = {j.id: j.done for j in jobs}
    open_jobs = {j.id for j in jobs if not j.cancelled}
    # interrupted allocations whose part waits for a machine, oldest first, per job
    waiting_reroute: dict[int, list[AllocationState]] = {}

    def hold(alloc: AllocationState) -> None:
        busy_machines.add(alloc.machine)
        active_parts[alloc.job_id] = active_parts.get(alloc.job_id, 0) + 1

    for alloc in allocations:
        a = alloc.alloc(alloc.job_id in open_jobs)
        if a.state == INTERRUPTED:
            waiting_reroute.setdefault(alloc.job_id, []).append(alloc)
            continue
        if a.state not in ACTIVE:
            continue
        mach = by_name.get(alloc.machine)
        # a machine gone from the cell's configuration is as lost as one that stopped answering
        look = mach.look() if mach is not None else Look(connected=False, offline_s=float("inf"))
        nxt = step(a, look, lost_contact_s=lost_contact_s)
        if nxt.note and nxt.note != alloc.note:
            out.actions.append(Note(alloc.id, alloc.job_id, nxt.note))
        if nxt.state == COMPLETED:
            out.actions.append(Complete(alloc.id, alloc.job_id, nxt.parts))
            done_now[alloc.job_id] = done_now.get(alloc.job_id, 0) + nxt.parts
            if mach is not None and mach.state != IDLE:
                busy_machines.add(mach.name)
        elif nxt.state == INTERRUPTED:
            out.actions.append(Interrupt(alloc.id, alloc.job_id, nxt.reason, nxt.cancel_dispatch))
            busy_machines.add(alloc.machine)  # taken again at the next look, not this one
            waiting_reroute.setdefault(alloc.job_id, []).append(alloc)
        else:
            if nxt.state == RUNNING and a.state == DISPATCHED:
                out.actions.append(MarkRunning(alloc.id))
            hold(alloc)

    def remaining(job: JobState) -> int:
        return job.quantity - done_now[job.id] - active_parts.get(job.id, 0)

    waiting = [j for j in jobs if not j.cancelled and remaining(j) > 0]
    idle = sorted(
        (m for m in machines if m.state == IDLE and m.name not in busy_machines),
        key=lambda m: m.name,
    )
    # The rule ranks the jobs once per class of machine (kind, axes and groups) per tick, a
    # setup-aware rule once per class and program held; each idle machine of the class
    # then takes the best-ranked job that still has parts left. Only the jobs whose
    # program the machine can run (dnc/requirements.py) are eligible: a job with A words
    # never goes to a mill without the rotary table.
    setup_aware = getattr(rule, "setup_aware", False)
    rankings: dict[tuple, list] = {}
    by_id = {j.id: j for j in waiting}
    allocated = 0
    for mach in idle:
        held = (mach.program or (last_programs or {}).get(mach.name)) if setup_aware else None
        key = (mach.kind, mach.axes, mach.groups, held)
        if key not in rankings:
            eligible = [
                JobView(
                    j.id,
                    j.priority,
                    j.created_at,
                    j.due_at,
                    remaining(j),
                    j.cycle_time_s,
                    j.program,
                )
                for j in waiting
                if j.runs_on(mach)
            ]
            if not eligible:
                rankings[key] = []
            elif setup_aware:
                rankings[key] = rule(eligible, now, held)  # type: ignore[call-arg]
            else:
                rankings[key] = rule(eligible, now)
        ranking = rankings[key]
        for rank, best in enumerate(ranking, start=1):
            if remaining(by_id[best.job.id]) <= 0:
                continue
            out.actions.append(
                Allocate(
                    best.job.id,
                    mach.name,
                    mach.part_count,
                    f"{rule_name.upper()} chose job {best.job.id} for idle {mach.name} "
                    f"(rank {rank} of {len(ranking)} eligible): {best.reason}",
                )
            )
            active_parts[best.job.id] = active_parts.get(best.job.id, 0) + 1
            # the job's oldest interrupted part is the one this allocation makes again
            queue = waiting_reroute.get(best.job.id)
            if queue:
                out.actions.append(Reroute(queue.pop(0).id, best.job.id, allocated))
            allocated += 1
            break
    # Interrupted parts of a closed job have nowhere to go.
    for job_id, queue in waiting_reroute.items():
        for alloc in queue:
            if job_id not in open_jobs:
                end = settle(replace(alloc.alloc(False), state=INTERRUPTED), rerouted_to=None)
                out.actions.append(Fail(alloc.id, job_id, end.reason))
    return out
