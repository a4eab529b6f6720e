"""Dispatch requests: put a released revision on a machine, exactly once per idempotency key.

A dispatch is recorded before anything is sent. The transfer worker then moves it through
pending -> transferring -> verifying -> done, or to failed after its retries; every step is
committed, so a host killed mid-dispatch finds the row where it left it and carries on.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime

from sqlalchemy import select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session, sessionmaker

from dnc import models as m
from dnc.db import transaction
from dnc.errors import IdempotencyMismatch, InvalidUpload, NotFound, WorkflowError
from dnc.events import record

MODES = ("memory", "drip_feed")
PENDING, TRANSFERRING, VERIFYING, DONE, FAILED = (
    "pending",
    "transferring",
    "verifying",
    "done",
    "failed",
)
ACTIVE_STATES = (PENDING, TRANSFERRING, VERIFYING)


@dataclass(frozen=True, slots=True)
class DispatchInfo:
    id: int
    idempotency_key: str
    revision_id: int
    machine: str
    mode: str
    start: bool
    state: str
    attempts: int
    bytes_sent: int
    verified: bool | None
    error: str | None
    requested_by: str
    created_at: datetime
    updated_at: datetime


def request_hash(revision_id: int, machine: str, mode: str, start: bool) -> str:
    body = json.dumps(
        {"revision_id": revision_id, "machine": machine, "mode": mode, "start": start},
        sort_keys=True,
    )
    return hashlib.sha256(body.encode()).hexdigest()


def create_dispatch(
    s: Session,
    *,
    key: str,
    revision_id: int,
    machine: str,
    mode: str,
    start: bool,
    requested_by: str,
    now: datetime,
    flush: bool = True,
) -> tuple[m.Dispatch, bool]:
    """The dispatch for `key`, created if new. Returns (row, created).

    Runs inside the caller's transaction so the scheduler can create an allocation and its
    dispatch atomically.
    """
    if mode not in MODES:
        raise InvalidUpload(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
    if not key or len(key) > 128:
        raise InvalidUpload("an idempotency key of 1..128 characters is required")
    digest = request_hash(revision_id, machine, mode, start)
    existing = s.scalar(select(m.Dispatch).where(m.Dispatch.idempotency_key == key))
    if existing is not None:
        _same_request(existing, digest, key)
        return existing, False
    rev = s.get(m.Revision, revision_id)
    if rev is None:
        raise NotFound(f"no revision with id {revision_id}")
    if rev.status != "released":
        raise WorkflowError(
            f"revision {revision_id} is {rev.status}; only a released revision can be dispatched"
        )
    if s.scalar(select(m.Machine.id).where(m.Machine.name == machine)) is None:
        raise NotFound(f"unknown machine {machine!r}")
    row = m.Dispatch(
        idempotency_key=key,
        request_hash=digest,
        revision_id=revision_id,
        machine=machine,
        mode=mode,
        start=start,
        state=PENDING,
        attempts=0,
        bytes_sent=0,
        requested_by=requested_by,
        created_at=now,
        updated_at=now,
    )
    s.add(row)
    if flush:
        s.flush()
    return row, True


def _same_request(existing: m.Dispatch, digest: str, key: str) -> None:
    if existing.request_hash != digest:
        raise IdempotencyMismatch(
            f"Idempotency-Key {key!r} was already used for a different request "
            f"(dispatch {existing.id}: revision {existing.revision_id} to {existing.machine}, "
            f"mode {existing.mode}, start {existing.start})",
            dispatch_id=existing.id,
        )


class Dispatches:
    def __init__(
        self, sessions: sessionmaker[Session], *, now: Callable[[], datetime] | None = None
    ) -> None:
        self._sessions = sessions
        self._now = now or (lambda: datetime.now(UTC))

    def request(
        self,
        *,
        key: str,
        revision_id: int,
        machine: str,
        mode: str = "memory",
        start: bool = False,
        requested_by: str = "unknown",
    ) -> tuple[DispatchInfo, bool]:
        """Record a dispatch; the same key with the same request returns the first one."""
        try:
            with transaction(self._sessions) as s:
                row, created = create_dispatch(
                    s,
                    key=key,
                    revision_id=revision_id,
                    machine=machine,
                    mode=mode,
                    start=start,
                    requested_by=requested_by,
                    now=self._now(),
                )
                if created:
                    _record_dispatch_event(s, row, requested_by, "dispatch.request", self._now())
                return dispatch_info(row), created
        except IntegrityError:
            # A concurrent request with the same key won the insert: answer with its row.
            with transaction(self._sessions) as s:
                row = s.scalar(select(m.Dispatch).where(m.Dispatch.idempotency_key == key))
                _same_request(row, request_hash(revision_id, machine, mode, start), key)
                return dispatch_info(row), False

    def get(self, dispatch_id: int) -> DispatchInfo:
        with transaction(self._sessions) as s:
            row = s.get(m.Dispatch, dispatch_id)
            if row is None:
                raise NotFound(f"no dispatch with id {dispatch_id}")
            return dispatch_info(row)

    def list(self, *, machine: str | None = None, limit: int = 100) -> list[DispatchInfo]:
        stmt = select(m.Dispatch).order_by(m.Dispatch.id.desc()).limit(limit)
        if machine:
            stmt = stmt.where(m.Dispatch.machine == machine)
        with transaction(self._sessions) as s:
            return [dispatch_info(r) for r in s.scalars(stmt)]


def _record_dispatch_event(
    s: Session, row: m.Dispatch, actor: str, action: str, now: datetime
) -> None:
    record(
        s,
        now=now,
        actor=actor,
        action=action,
        entity="dispatch",
        entity_id=row.id,
        topic=f"fmscell/dispatch/{row.state}",
        revision_id=row.revision_id,
        machine=row.machine,
        mode=row.mode,
        state=row.state,
        attempts=row.attempts,
        error=row.error,
    )


def dispatch_info(r: m.Dispatch) -> DispatchInfo:
    return DispatchInfo(
        r.id,
        r.idempotency_key,
        r.revision_id,
        r.machine,
        r.mode,
        r.start,
        r.state,
        r.attempts,
        r.bytes_sent,
        r.verified,
        r.error,
        r.requested_by,
        r.created_at,
        r.updated_at,
    )
