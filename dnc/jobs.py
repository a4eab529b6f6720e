"""The FMS job queue and the scheduler tick (the shell around dnc.scheduler.decide)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime

from sqlalchemy import func, select
from sqlalchemy.orm import Session, sessionmaker

from dnc import models as m
from dnc.db import transaction
from dnc.dispatch import FAILED, create_dispatch
from dnc.errors import InvalidUpload, NotFound, WorkflowError
from dnc.events import record
from dnc.rules import rule_named
from dnc.scheduler import (
    Allocate,
    AllocationState,
    Complete,
    Decisions,
    Interrupt,
    JobState,
    MachineView,
    MarkRunning,
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
            kind = s.get(m.Program, rev.program_id).machine_kind
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
        """Stop allocating new parts; parts already running on a machine finish normally."""
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
    ) -> None:
        self._sessions = sessions
        self._status = machine_status
        self.rule_name = rule.lower()
        self._rule = rule_named(rule)
        self._now = now or (lambda: datetime.now(UTC))

    def tick(self) -> Decisions:
        machines = self._status()
        now = self._now()
        with transaction(self._sessions) as s:
            # Cancelled jobs stay in view only while a part of theirs is still on a machine.
            running_jobs = select(m.Allocation.job_id).where(
                m.Allocation.status.in_(ACTIVE_ALLOCATIONS)
            )
            jobs = s.scalars(
                select(m.Job)
                .where(m.Job.status.in_(OPEN_STATES) | m.Job.id.in_(running_jobs))
                .order_by(m.Job.id)
                .with_for_update()
            ).all()
            allocs = s.scalars(
                select(m.Allocation).where(m.Allocation.status.in_(ACTIVE_ALLOCATIONS))
            ).all()
            failed = {
                d.id
                for d in s.scalars(
                    select(m.Dispatch).where(
                        m.Dispatch.id.in_([a.dispatch_id for a in allocs if a.dispatch_id]),
                        m.Dispatch.state == FAILED,
                    )
                )
            }
            decisions = decide(
                [_job_state(j) for j in jobs],
                [
                    AllocationState(
                        a.id,
                        a.job_id,
                        a.machine,
                        a.parts_at_start,
                        a.status == "running",
                        a.dispatch_id in failed,
                    )
                    for a in allocs
                ],
                machines,
                self._rule,
                self.rule_name,
                now,
            )
            by_job = {j.id: j for j in jobs}
            by_alloc = {a.id: a for a in allocs}
            self._allocate(s, decisions.of(Allocate), by_job, now)
            for action in decisions.actions:
                self._apply(s, action, by_job, by_alloc, now)
            self._settle_job_states(s, jobs, now)
        return decisions

    def _allocate(self, s: Session, actions: list[Allocate], by_job, now: datetime) -> None:
        """Allocations and their dispatches for a whole tick, in two flushes."""
        if not actions:
            return
        made = []
        # The n-th allocation of a job gets key job-<id>-allocation-<n>: unique, and the same
        # again if a tick rolled back by a crash is taken up after a restart.
        counts = dict(
            s.execute(
                select(m.Allocation.job_id, func.count())
                .where(m.Allocation.job_id.in_({a.job_id for a in actions}))
                .group_by(m.Allocation.job_id)
            ).all()
        )
        with s.no_autoflush:
            for action in actions:
                job = by_job[action.job_id]
                counts[job.id] = counts.get(job.id, 0) + 1
                dispatch, _ = create_dispatch(
                    s,
                    key=f"job-{job.id}-allocation-{counts[job.id]}",
                    revision_id=job.revision_id,
                    machine=action.machine,
                    mode="memory",
                    start=True,
                    requested_by="scheduler",
                    now=now,
                    flush=False,
                )
                made.append((action, job, dispatch))
        s.flush()
        allocations = [
            m.Allocation(
                job_id=job.id,
                machine=action.machine,
                parts_at_start=action.part_count,
                status="dispatched",
                dispatch_id=dispatch.id,
                reason=action.reason,
                created_at=now,
            )
            for action, job, dispatch in made
        ]
        s.add_all(allocations)
        s.flush()
        for (action, job, dispatch), alloc in zip(made, allocations, strict=True):
            self._decision(
                s, now, self.rule_name, "allocate", job.id, action.machine, action.reason
            )
            record(
                s,
                now=now,
                actor="scheduler",
                action="job.allocate",
                entity="job",
                entity_id=job.id,
                machine=action.machine,
                allocation_id=alloc.id,
                dispatch_id=dispatch.id,
                reason=action.reason,
            )

    def _apply(self, s: Session, action, by_job, by_alloc, now: datetime) -> None:
        """Completions, interruptions and running marks (allocations are made in bulk)."""
        rule = self.rule_name
        if isinstance(action, Complete):
            alloc, job = by_alloc[action.allocation_id], by_job[action.job_id]
            alloc.status, alloc.ended_at = "completed", now
            job.done = min(job.quantity, job.done + action.parts)
            self._decision(
                s,
                now,
                rule,
                "complete",
                job.id,
                alloc.machine,
                f"part counter of {alloc.machine} advanced",
            )
        elif isinstance(action, Interrupt):
            alloc, job = by_alloc[action.allocation_id], by_job[action.job_id]
            alloc.status, alloc.ended_at = "interrupted", now
            self._decision(s, now, rule, "interrupt", job.id, alloc.machine, action.reason)
            record(
                s,
                now=now,
                actor="scheduler",
                action="job.interrupt",
                entity="job",
                entity_id=job.id,
                machine=alloc.machine,
                reason=action.reason,
            )
        elif isinstance(action, MarkRunning):
            by_alloc[action.allocation_id].status = "running"

    def _settle_job_states(self, s: Session, jobs, now: datetime) -> None:
        ids = [j.id for j in jobs]
        active = {
            a.job_id
            for a in s.scalars(
                select(m.Allocation).where(
                    m.Allocation.job_id.in_(ids), m.Allocation.status.in_(ACTIVE_ALLOCATIONS)
                )
            )
        }
        interrupted = {
            a.job_id
            for a in s.scalars(
                select(m.Allocation).where(
                    m.Allocation.job_id.in_(ids), m.Allocation.status == "interrupted"
                )
            )
        }
        for job in jobs:
            if job.status == CANCELLED:
                continue
            if job.done >= job.quantity:
                status = COMPLETED
            elif job.id in active:
                status = RUNNING
            elif job.id in interrupted:
                status = INTERRUPTED
            else:
                status = QUEUED
            if status != job.status:
                job.status, job.updated_at = status, now
                record(
                    s,
                    now=now,
                    actor="scheduler",
                    action=f"job.{status}",
                    entity="job",
                    entity_id=job.id,
                    done=job.done,
                    quantity=job.quantity,
                )

    @staticmethod
    def _decision(s: Session, now, rule, action, job_id, machine, reason) -> None:
        s.add(
            m.Decision(
                at=now, rule=rule, action=action, job_id=job_id, machine=machine, reason=reason
            )
        )


def _job_state(j: m.Job) -> JobState:
    return JobState(
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
    )


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
    )
