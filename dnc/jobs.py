"""The FMS job queue and the scheduler tick (the shell around dnc.scheduler.decide)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime

from sqlalchemy import bindparam, func, insert, select, update
from sqlalchemy.orm import Session, sessionmaker

from dnc import models as m
from dnc.allocation import DEFAULT_LOST_CONTACT_S, dispatch_phase
from dnc.db import transaction
from dnc.dependencies import dependencies
from dnc.dispatch import FAILED, DispatchRequest, create_dispatches
from dnc.errors import InvalidUpload, NoMachineCanRun, NotFound, WorkflowError
from dnc.events import record, record_many
from dnc.requirements import Needs, Offer, refusal, revision_needs, why_none
from dnc.rules import rule_named
from dnc.scheduler import (
    IDLE,
    Allocate,
    AllocationState,
    Complete,
    Decisions,
    Fail,
    Interrupt,
    JobState,
    MachineView,
    MarkRunning,
    Note,
    Reroute,
    decide,
)

QUEUED, RUNNING, INTERRUPTED, COMPLETED, CANCELLED = (
    "queued",
    "running",
    "interrupted",
    "completed",
    "cancelled",
)
OPEN_STATES = (QUEUED, RUNNING, INTERRUPTED)
ACTIVE_ALLOCATIONS = ("dispatched", "running")
# the allocations a tick steps: the active ones and the interrupted ones whose part waits
STEPPED_ALLOCATIONS = (*ACTIVE_ALLOCATIONS, "interrupted")


@dataclass(frozen=True, slots=True)
class JobInfo:
    id: int
    revision_id: int
    quantity: int
    done: int
    priority: int
    due_at: datetime | None
    machine_kind: str
    machine_group: str | None
    cycle_time_s: float
    status: str
    created_at: datetime
    updated_at: datetime
    # what a machine must be and have to make its parts ({"kinds", "axes"}); None: queued
    # before the host knew (its machine kind alone)
    needs: dict[str, list[str]] | None = None


class Jobs:
    def __init__(
        self, sessions: sessionmaker[Session], *, now: Callable[[], datetime] | None = None
    ) -> None:
        self._sessions = sessions
        self._now = now or (lambda: datetime.now(UTC))

    def create(
        self,
        *,
        revision_id: int,
        quantity: int,
        due_at: datetime | None = None,
        priority: int = 0,
        machine_group: str | None = None,
        cycle_time_s: float = 60.0,
        actor: str = "unknown",
    ) -> JobInfo:
        if quantity < 1:
            raise InvalidUpload(f"quantity must be at least 1, got {quantity}")
        if cycle_time_s <= 0:
            raise InvalidUpload(f"cycle_time_s must be > 0, got {cycle_time_s}")
        if due_at is not None and due_at.tzinfo is None:
            raise InvalidUpload("due_at must carry a time zone (e.g. 2026-11-21T16:00:00Z)")
        now = self._now()
        with transaction(self._sessions) as s:
            rev = s.get(m.Revision, revision_id)
            if rev is None:
                raise NotFound(f"no revision with id {revision_id}")
            if rev.status != "released":
                raise WorkflowError(
                    f"revision {revision_id} is {rev.status}; jobs need a released revision"
                )
            # a subprogram not released: refused now, not per part
            called = dependencies(s, revision_id)
            kind = s.get(m.Program, rev.program_id).machine_kind
            needs = _needs(s, rev, kind, called)
            job = m.Job(
                revision_id=revision_id,
                quantity=quantity,
                done=0,
                priority=priority,
                due_at=due_at,
                machine_kind=kind,
                machine_group=machine_group,
                cycle_time_s=cycle_time_s,
                status=QUEUED,
                needs=needs.as_data(),
                created_at=now,
                updated_at=now,
            )
            s.add(job)
            s.flush()
            record(
                s,
                now=now,
                actor=actor,
                action="job.create",
                entity="job",
                entity_id=job.id,
                revision_id=revision_id,
                quantity=quantity,
            )
            return job_info(job)

    def cancel(self, job_id: int, *, actor: str = "unknown") -> JobInfo:
        """Stop allocating new parts; parts already running on a machine finish normally.

        The next scheduler tick calls off the job's allocations whose program has not been
        started (their dispatches with them), which frees their machines."""
        now = self._now()
        with transaction(self._sessions) as s:
            job = s.get(m.Job, job_id, with_for_update=True)
            if job is None:
                raise NotFound(f"no job with id {job_id}")
            if job.status in (COMPLETED, CANCELLED):
                raise WorkflowError(f"job {job_id} is already {job.status}")
            job.status, job.updated_at = CANCELLED, now
            record(s, now=now, actor=actor, action="job.cancel", entity="job", entity_id=job.id)
            return job_info(job)

    def get(self, job_id: int) -> JobInfo:
        with transaction(self._sessions) as s:
            job = s.get(m.Job, job_id)
            if job is None:
                raise NotFound(f"no job with id {job_id}")
            return job_info(job)

    def list(
        self, *, status: str | None = None, after_id: int = 0, limit: int = 100
    ) -> list[JobInfo]:
        stmt = select(m.Job).where(m.Job.id > after_id).order_by(m.Job.id).limit(limit)
        if status:
            stmt = stmt.where(m.Job.status == status)
        with transaction(self._sessions) as s:
            return [job_info(j) for j in s.scalars(stmt)]

    def allocations(self, job_id: int) -> list[dict]:
        with transaction(self._sessions) as s:
            rows = s.scalars(
                select(m.Allocation).where(m.Allocation.job_id == job_id).order_by(m.Allocation.id)
            )
            return [
                dict(
                    id=a.id,
                    machine=a.machine,
                    status=a.status,
                    dispatch_id=a.dispatch_id,
                    reason=a.reason,
                    note=a.note,
                    rerouted_to=a.rerouted_to,
                )
                for a in rows
            ]

    def decisions(self, *, job_id: int | None = None) -> list[dict]:
        stmt = select(m.Decision).order_by(m.Decision.id)
        if job_id is not None:
            stmt = stmt.where(m.Decision.job_id == job_id)
        with transaction(self._sessions) as s:
            return [
                dict(
                    at=d.at,
                    rule=d.rule,
                    action=d.action,
                    job_id=d.job_id,
                    machine=d.machine,
                    reason=d.reason,
                )
                for d in s.scalars(stmt)
            ]


class Scheduler:
    """Each tick rebuilds its view from the database, decides, and applies in one transaction."""

    def __init__(
        self,
        sessions: sessionmaker[Session],
        machine_status: Callable[[], list[MachineView]],
        *,
        rule: str = "fifo",
        now: Callable[[], datetime] | None = None,
        lost_contact_s: float = DEFAULT_LOST_CONTACT_S,
    ) -> None:
        if not lost_contact_s > 0:
            raise ValueError(f"lost_contact_s must be > 0, got {lost_contact_s}")
        self._sessions = sessions
        self._status = machine_status
        self.lost_contact_s = lost_contact_s
        self.rule_name = rule.lower()
        self._rule = rule_named(rule)
        # a setup-aware rule also sees what each free machine last ran (dnc/rules.py)
        self._setup_aware = bool(getattr(self._rule, "setup_aware", False))
        self._now = now or (lambda: datetime.now(UTC))

    def tick(self) -> Decisions:
        # A dispatch the tick calls off may have moved on to `starting` since it was read
        # (the transfer worker claims its start in a transaction of its own): then the whole
        # tick is rolled back and decided again from the new state.
        for _ in range(_RACE_RETRIES):
            try:
                return self._tick()
            except _DispatchMovedOn:
                continue
        return self._tick()

    def _tick(self) -> Decisions:
        now = self._now()
        with transaction(self._sessions) as s:
            # Core reads and writes on the tables, a statement per kind of row for the whole
            # tick: ORM objects for a thousand jobs and a unit of work per dispatch were most
            # of a tick's time.
            jobs = s.execute(_OPEN_JOBS).all()
            allocs = s.execute(_STEPPED).all()
            # The machines are looked at after the database is read: a dispatch read as
            # done was confirmed running before it was written, so the look that follows
            # shows the cycle, its part or its end, never the moment before the start.
            machines = self._status()
            last = self._last_programs(s, machines) if self._setup_aware else {}
            decisions = decide(
                [
                    JobState(
                        j.id,
                        j.machine_kind,
                        j.machine_group,
                        j.quantity,
                        j.done,
                        j.priority,
                        j.created_at,
                        j.due_at,
                        j.cycle_time_s,
                        j.status == CANCELLED,
                        _program(j.number),
                        Needs.from_data(j.needs, j.machine_kind) if j.needs else None,
                    )
                    for j in jobs
                ],
                [
                    AllocationState(
                        a.id,
                        a.job_id,
                        a.machine,
                        a.parts_at_start,
                        a.status == "running",
                        a.dispatch_state == FAILED,
                        dispatch=dispatch_phase(a.dispatch_state, a.dispatch_error),
                        program=_program(a.number),
                        state=a.status,
                        note=a.note or "",
                    )
                    for a in allocs
                ],
                machines,
                self._rule,
                self.rule_name,
                now,
                lost_contact_s=self.lost_contact_s,
                last_programs=last,
            )
            _Tick(s, self.rule_name, now, jobs, allocs).apply(decisions)
        return decisions

    def _last_programs(self, s: Session, machines: list[MachineView]) -> dict[str, str]:
        """What each free machine that reports no program last ran, by the host's history."""
        out = {}
        for mach in machines:
            if mach.state == IDLE and not mach.program:
                number = s.execute(_LAST_ALLOCATED, {"b_machine": mach.name}).scalar()
                if number is not None:
                    out[mach.name] = _program(number)
        return out


class _DispatchMovedOn(Exception):
    """A dispatch to call off was no longer pending, transferring or verifying."""


_RACE_RETRIES = 3


class _Tick:
    """Writes one tick's decisions: rows gathered per kind, then one statement per kind.

    Decision, audit and outbox rows keep the order the actions came in (allocations first),
    and all of them are written in the tick's transaction.
    """

    def __init__(self, s: Session, rule: str, now: datetime, jobs, allocs) -> None:
        self.s, self.rule, self.now = s, rule, now
        self.jobs = {j.id: j for j in jobs}
        self.allocs = {a.id: a for a in allocs}
        self.done = {j.id: j.done for j in jobs}
        self.decisions: list[dict] = []
        self.events: list[tuple[str, str, int | None, dict]] = []

    def apply(self, decisions: Decisions) -> None:
        s = self.s
        # Dispatches called off first: if one has moved on meanwhile, nothing of the tick
        # is written and it is decided again.
        self._call_off([a for a in decisions.of(Interrupt) if a.cancel_dispatch])
        new_active, new_ids = self._allocate(decisions.of(Allocate))
        ended, alloc_updates = set(), []

        def end(alloc_id: int, status: str, **values) -> None:
            row = dict(b_id=alloc_id, b_status=status, b_ended=self.now)
            alloc_updates.append(row | {"b_rerouted": values.get("rerouted_to")})

        notes = []
        for action in decisions.actions:
            if isinstance(action, Complete):
                alloc = self.allocs[action.allocation_id]
                job = self.jobs[action.job_id]
                ended.add(alloc.id)
                end(alloc.id, "completed")
                self.done[job.id] = min(job.quantity, self.done[job.id] + action.parts)
                self._decision(
                    "complete", job.id, alloc.machine, f"part counter of {alloc.machine} advanced"
                )
            elif isinstance(action, Interrupt):
                alloc = self.allocs[action.allocation_id]
                ended.add(alloc.id)
                end(alloc.id, "interrupted")
                self._decision("interrupt", action.job_id, alloc.machine, action.reason)
                self.events.append(
                    (
                        "job.interrupt",
                        "job",
                        action.job_id,
                        dict(machine=alloc.machine, reason=action.reason, allocation_id=alloc.id),
                    )
                )
            elif isinstance(action, Reroute):
                alloc = self.allocs[action.allocation_id]
                to = new_ids[action.to]
                end(alloc.id, "rerouted", rerouted_to=to)
                self._decision(
                    "reroute", action.job_id, alloc.machine, f"part rerouted to allocation {to}"
                )
            elif isinstance(action, Fail):
                alloc = self.allocs[action.allocation_id]
                end(alloc.id, "failed")
                self._decision("fail", action.job_id, alloc.machine, action.reason)
            elif isinstance(action, Note):
                alloc = self.allocs[action.allocation_id]
                notes.append(dict(b_id=alloc.id, b_note=action.text))
                self._decision("note", action.job_id, alloc.machine, action.text)
            elif isinstance(action, MarkRunning):
                alloc_updates.append(
                    dict(
                        b_id=action.allocation_id, b_status="running", b_ended=None, b_rerouted=None
                    )
                )
        if alloc_updates:
            s.execute(_SET_ALLOCATION, alloc_updates)
        if notes:
            s.execute(_SET_NOTE, notes)
        done_updates = [
            dict(b_id=i, b_done=done) for i, done in self.done.items() if done != self.jobs[i].done
        ]
        if done_updates:
            s.execute(_SET_DONE, done_updates)
        active = {
            a.job_id
            for a in self.allocs.values()
            if a.id not in ended and a.status in ACTIVE_ALLOCATIONS
        } | new_active
        self._settle_job_states(active)
        if self.decisions:
            s.execute(_INSERT_DECISION, self.decisions)
        record_many(s, now=self.now, actor="scheduler", entries=self.events)

    def _call_off(self, interrupts: list[Interrupt]) -> None:
        """Fail the dispatches of allocations interrupted before their program started, so
        the transfer worker can never start them (its start is conditional on the state)."""
        interrupts = [a for a in interrupts if self.allocs[a.allocation_id].dispatch_id]
        if not interrupts:
            return
        rows = [
            dict(
                b_id=self.allocs[a.allocation_id].dispatch_id,
                b_now=self.now,
                b_error=f"called off: allocation {a.allocation_id} interrupted ({a.reason})",
            )
            for a in interrupts
        ]
        for row, action in zip(rows, interrupts, strict=True):
            if self.s.execute(_CALL_OFF, row).first() is None:
                raise _DispatchMovedOn(row["b_id"])
            alloc = self.allocs[action.allocation_id]
            self.events.append(
                (
                    "dispatch.failed",
                    "dispatch",
                    row["b_id"],
                    dict(machine=alloc.machine, state=FAILED, error=row["b_error"]),
                )
            )

    def _allocate(self, actions: list[Allocate]) -> tuple[set[int], list[int]]:
        """Allocations and their dispatches for the whole tick; returns the jobs allocated
        and the new allocations' ids in the order of the actions."""
        if not actions:
            return set(), []
        s, now = self.s, self.now
        # The n-th allocation of a job gets key job-<id>-allocation-<n>: unique, and the same
        # again if a tick rolled back by a crash is taken up after a restart.
        counts = dict(
            s.execute(_ALLOCATION_COUNTS, dict(ids=sorted({a.job_id for a in actions}))).all()
        )
        requests = []
        for action in actions:
            counts[action.job_id] = counts.get(action.job_id, 0) + 1
            requests.append(
                DispatchRequest(
                    key=f"job-{action.job_id}-allocation-{counts[action.job_id]}",
                    revision_id=self.jobs[action.job_id].revision_id,
                    machine=action.machine,
                    mode="memory",
                    start=True,
                )
            )
        dispatches = create_dispatches(s, requests, requested_by="scheduler", now=now)
        rows = [
            dict(
                job_id=action.job_id,
                machine=action.machine,
                parts_at_start=action.part_count,
                status="dispatched",
                dispatch_id=dispatch_id,
                reason=action.reason,
                created_at=now,
                ended_at=None,
            )
            for action, (dispatch_id, _) in zip(actions, dispatches, strict=True)
        ]
        alloc_ids = s.execute(_INSERT_ALLOCATION, rows).scalars().all()
        for action, row, alloc_id in zip(actions, rows, alloc_ids, strict=True):
            self._decision("allocate", action.job_id, action.machine, action.reason)
            self.events.append(
                (
                    "job.allocate",
                    "job",
                    action.job_id,
                    dict(
                        machine=action.machine,
                        allocation_id=alloc_id,
                        dispatch_id=row["dispatch_id"],
                        reason=action.reason,
                    ),
                )
            )
        return {a.job_id for a in actions}, list(alloc_ids)

    def _settle_job_states(self, active: set[int]) -> None:
        """Each job's status from its parts: completed, running, interrupted or queued."""
        s, now = self.s, self.now
        # Whether an idle job was ever interrupted is asked once for all open jobs (the
        # interruptions of jobs long closed stay out of it).
        interrupted = set(s.scalars(_INTERRUPTED_OPEN_JOBS))
        updates = []
        for job in self.jobs.values():
            if job.status == CANCELLED:
                continue
            done = self.done[job.id]
            if done >= job.quantity:
                status = COMPLETED
            elif job.id in active:
                status = RUNNING
            elif job.id in interrupted:
                status = INTERRUPTED
            else:
                status = QUEUED
            if status != job.status:
                updates.append(dict(b_id=job.id, b_status=status, b_updated=now))
                self.events.append(
                    (f"job.{status}", "job", job.id, dict(done=done, quantity=job.quantity))
                )
        if updates:
            s.execute(_SET_JOB_STATUS, updates)

    def _decision(self, action: str, job_id: int, machine: str, reason: str) -> None:
        self.decisions.append(
            dict(
                at=self.now,
                rule=self.rule,
                action=action,
                job_id=job_id,
                machine=machine,
                reason=reason,
            )
        )


_JOBS = m.Job.__table__
_ALLOCATIONS = m.Allocation.__table__
_DISPATCHES = m.Dispatch.__table__
_REVISIONS = m.Revision.__table__
_PROGRAMS = m.Program.__table__
# Cancelled jobs stay in view only while a part of theirs is still on a machine.
_OPEN_JOBS = (
    select(
        _JOBS.c.id,
        _JOBS.c.revision_id,
        _JOBS.c.machine_kind,
        _JOBS.c.machine_group,
        _JOBS.c.quantity,
        _JOBS.c.done,
        _JOBS.c.priority,
        _JOBS.c.created_at,
        _JOBS.c.due_at,
        _JOBS.c.cycle_time_s,
        _JOBS.c.status,
        _JOBS.c.needs,
        # a subquery, not a join: FOR UPDATE locks the jobs only, never revisions or programs
        select(_PROGRAMS.c.number)
        .join(_REVISIONS, _REVISIONS.c.program_id == _PROGRAMS.c.id)
        .where(_REVISIONS.c.id == _JOBS.c.revision_id)
        .scalar_subquery()
        .label("number"),
    )
    .where(
        _JOBS.c.status.in_(OPEN_STATES)
        | _JOBS.c.id.in_(
            select(_ALLOCATIONS.c.job_id).where(_ALLOCATIONS.c.status.in_(ACTIVE_ALLOCATIONS))
        )
    )
    .order_by(_JOBS.c.id)
    .with_for_update()
)
# The allocations a tick steps, with their dispatch's state and their program's number.
_STEPPED = (
    select(
        _ALLOCATIONS.c.id,
        _ALLOCATIONS.c.job_id,
        _ALLOCATIONS.c.machine,
        _ALLOCATIONS.c.parts_at_start,
        _ALLOCATIONS.c.status,
        _ALLOCATIONS.c.dispatch_id,
        _ALLOCATIONS.c.note,
        _DISPATCHES.c.state.label("dispatch_state"),
        _DISPATCHES.c.error.label("dispatch_error"),
        _PROGRAMS.c.number,
    )
    .select_from(
        _ALLOCATIONS.outerjoin(_DISPATCHES, _DISPATCHES.c.id == _ALLOCATIONS.c.dispatch_id)
        .outerjoin(_REVISIONS, _REVISIONS.c.id == _DISPATCHES.c.revision_id)
        .outerjoin(_PROGRAMS, _PROGRAMS.c.id == _REVISIONS.c.program_id)
    )
    .where(_ALLOCATIONS.c.status.in_(STEPPED_ALLOCATIONS))
    .order_by(_ALLOCATIONS.c.id)
)
# The program of a machine's last allocation (what a setup-aware rule takes a machine that
# reports no selected program to hold): an index seek on (machine, id), however long the
# history.
_LAST_ALLOCATED = (
    select(_PROGRAMS.c.number)
    .select_from(
        _ALLOCATIONS.join(_DISPATCHES, _DISPATCHES.c.id == _ALLOCATIONS.c.dispatch_id)
        .join(_REVISIONS, _REVISIONS.c.id == _DISPATCHES.c.revision_id)
        .join(_PROGRAMS, _PROGRAMS.c.id == _REVISIONS.c.program_id)
    )
    .where(_ALLOCATIONS.c.machine == bindparam("b_machine"))
    .order_by(_ALLOCATIONS.c.id.desc())
    .limit(1)
)
_CALL_OFF = (
    update(_DISPATCHES)
    .where(
        _DISPATCHES.c.id == bindparam("b_id"),
        _DISPATCHES.c.state.in_(("pending", "transferring", "verifying")),
    )
    .values(state=FAILED, error=bindparam("b_error"), updated_at=bindparam("b_now"))
    .returning(_DISPATCHES.c.id)
)
_ALLOCATION_COUNTS = (
    select(_ALLOCATIONS.c.job_id, func.count())
    .where(_ALLOCATIONS.c.job_id.in_(bindparam("ids", expanding=True)))
    .group_by(_ALLOCATIONS.c.job_id)
)
_INTERRUPTED_OPEN_JOBS = (
    select(_ALLOCATIONS.c.job_id)
    .distinct()
    .join(_JOBS, _JOBS.c.id == _ALLOCATIONS.c.job_id)
    .where(_ALLOCATIONS.c.status.in_((INTERRUPTED, "rerouted")), _JOBS.c.status.in_(OPEN_STATES))
)
_INSERT_ALLOCATION = insert(_ALLOCATIONS).returning(_ALLOCATIONS.c.id, sort_by_parameter_order=True)
_INSERT_DECISION = insert(m.Decision.__table__)
_SET_ALLOCATION = (
    update(_ALLOCATIONS)
    .where(_ALLOCATIONS.c.id == bindparam("b_id"))
    .values(
        status=bindparam("b_status"),
        ended_at=bindparam("b_ended"),
        rerouted_to=bindparam("b_rerouted"),
    )
)
_SET_NOTE = (
    update(_ALLOCATIONS)
    .where(_ALLOCATIONS.c.id == bindparam("b_id"))
    .values(note=bindparam("b_note"))
)
_SET_DONE = update(_JOBS).where(_JOBS.c.id == bindparam("b_id")).values(done=bindparam("b_done"))
_SET_JOB_STATUS = (
    update(_JOBS)
    .where(_JOBS.c.id == bindparam("b_id"))
    .values(status=bindparam("b_status"), updated_at=bindparam("b_updated"))
)


def _needs(s: Session, rev: m.Revision, kind: str, called: list) -> Needs:
    """What a machine must be and have to run the revision and the programs it calls
    (dnc/requirements.py); refused (NoMachineCanRun) when no registered machine of the
    cell can. A host with no machines registered yet (`fmscell dnc` before its cell is
    known) does not judge."""
    called_axes = [s.get(m.Revision, d.revision_id).axes for d in called]
    needs = revision_needs(rev.kind, kind, rev.post_kinds, rev.axes, called_axes)
    offers = [
        Offer(x.name, x.kind, tuple(x.axes or ()))
        for x in s.scalars(select(m.Machine).order_by(m.Machine.name))
    ]
    if offers and not any(refusal(needs, o) is None for o in offers):
        raise NoMachineCanRun(
            f"revision {rev.id}: {why_none(needs, offers)}",
            pointer="#/revision_id",
            needs=needs.as_data(),
            machines={o.name: refusal(needs, o) for o in offers},
        )
    return needs


def _program(number: int | None) -> str | None:
    """The name a machine reports a program by (O1234)."""
    return f"O{number:04d}" if number is not None else None


def job_info(j: m.Job) -> JobInfo:
    return JobInfo(
        j.id,
        j.revision_id,
        j.quantity,
        j.done,
        j.priority,
        j.due_at,
        j.machine_kind,
        j.machine_group,
        j.cycle_time_s,
        j.status,
        j.created_at,
        j.updated_at,
        dict(j.needs) if j.needs else None,
    )
