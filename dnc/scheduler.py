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

from dataclasses import dataclass, field
from datetime import datetime

from dnc.rules import JobView, Rule

IDLE, BUSY, ALARM, OFFLINE = "idle", "busy", "alarm", "offline"


@dataclass(frozen=True, slots=True)
class MachineView:
    name: str
    kind: str
    state: str  # idle | busy | alarm | offline (from the monitoring model)
    part_count: int
    groups: tuple[str, ...] = ()


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


@dataclass(frozen=True, slots=True)
class AllocationState:
    id: int
    job_id: int
    machine: str
    parts_at_start: int  # the machine's part counter when the allocation was made
    running: bool  # the machine has been seen busy with it
    dispatch_failed: bool = False


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
) -> Decisions:
    out = Decisions()
    by_name = {m.name: m for m in machines}
    busy_machines: set[str] = set()
    active_parts: dict[int, int] = {}
    done_now: dict[int, int] = {j.id: j.done for j in jobs}

    for alloc in allocations:
        mach = by_name.get(alloc.machine)
        if mach is None or mach.state == OFFLINE:
            # Lost contact is not a failure: the machine keeps running the program in its
            # memory and we resynchronise its part counter when it answers again.
            busy_machines.add(alloc.machine)
            active_parts[alloc.job_id] = active_parts.get(alloc.job_id, 0) + 1
            continue
        if mach.part_count > alloc.parts_at_start:
            out.actions.append(Complete(alloc.id, alloc.job_id, 1))
            done_now[alloc.job_id] = done_now.get(alloc.job_id, 0) + 1
            if mach.state == BUSY:
                busy_machines.add(mach.name)
            continue
        if mach.state == ALARM or alloc.dispatch_failed:
            why = (
                f"machine {mach.name} raised an alarm"
                if mach.state == ALARM
                else f"dispatch to {mach.name} failed"
            )
            out.actions.append(Interrupt(alloc.id, alloc.job_id, why))
            busy_machines.add(mach.name)
            continue
        if mach.state == BUSY and not alloc.running:
            out.actions.append(MarkRunning(alloc.id))
        busy_machines.add(mach.name)
        active_parts[alloc.job_id] = active_parts.get(alloc.job_id, 0) + 1

    def remaining(job: JobState) -> int:
        return job.quantity - done_now[job.id] - active_parts.get(job.id, 0)

    waiting = [j for j in jobs if not j.cancelled and remaining(j) > 0]
    idle = sorted(
        (m for m in machines if m.state == IDLE and m.name not in busy_machines),
        key=lambda m: m.name,
    )
    # The rule ranks the jobs once per class of machine (kind and groups) per tick; each
    # idle machine of the class then takes the best-ranked job that still has parts left.
    rankings: dict[tuple[str, tuple[str, ...]], list] = {}
    by_id = {j.id: j for j in waiting}
    for mach in idle:
        key = (mach.kind, mach.groups)
        if key not in rankings:
            eligible = [
                JobView(j.id, j.priority, j.created_at, j.due_at, remaining(j), j.cycle_time_s)
                for j in waiting
                if j.machine_kind == mach.kind
                and (j.machine_group is None or j.machine_group in mach.groups)
            ]
            rankings[key] = rule(eligible, now) if eligible else []
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
            break
    return out
