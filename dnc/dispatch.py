"""Dispatch requests: put a released revision on a machine, exactly once per idempotency key.

A dispatch is recorded before anything is sent. A revision that calls other programs
(M98 P, G65 P, G66 P) brings their released revisions along, sent first
(dnc.dependencies); a request whose revision calls a program with no released revision is
refused before anything is recorded. The transfer worker then moves it through
pending -> transferring -> verifying -> done, or to failed after its retries; every step is
committed, so a host killed mid-dispatch finds the row where it left it and carries on.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime

from sqlalchemy import bindparam, insert, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session, sessionmaker

from dnc import models as m
from dnc.checker import machine_check
from dnc.content import read_text
from dnc.db import transaction
from dnc.dependencies import LibraryPrograms, dependencies
from dnc.errors import (
    Conflict,
    IdempotencyMismatch,
    InvalidUpload,
    NotForMachine,
    NotFound,
    WorkflowError,
)
from dnc.events import record
from dnc.posting import (
    GCODE,
    SOURCE_KINDS,
    MachineConfigs,
    default_machine_configs,
    posted_for,
    store_derived,
)

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
    derived_id: int | None = None  # an APT/CL revision: the G-code posted for the machine


def request_hash(revision_id: int, machine: str, mode: str, start: bool) -> str:
    body = json.dumps(
        {"revision_id": revision_id, "machine": machine, "mode": mode, "start": start},
        sort_keys=True,
    )
    return hashlib.sha256(body.encode()).hexdigest()


@dataclass(frozen=True, slots=True)
class DispatchRequest:
    key: str
    revision_id: int
    machine: str
    mode: str = "memory"
    start: bool = False


def create_dispatches(
    s: Session, requests: list[DispatchRequest], *, requested_by: str, now: datetime
) -> list[tuple[int, bool]]:
    """The dispatch for each request's key, created where new: [(dispatch id, created)].

    Runs inside the caller's transaction so the scheduler creates allocations and their
    dispatches atomically. Core statements, one per kind for the whole batch (existing keys,
    revisions, machines, the insert): a tick makes dozens at once, and a unit of work per
    dispatch was most of the tick. No event is written here; the caller records its own.
    """
    existing = (
        {r.idempotency_key: r for r in s.execute(_BY_KEYS, dict(keys=[r.key for r in requests]))}
        if requests
        else {}
    )
    new: dict[str, tuple[DispatchRequest, dict]] = {}  # by key; the first request of a key
    for req in requests:
        _check_request(req.mode, req.key)
        digest = request_hash(req.revision_id, req.machine, req.mode, req.start)
        if req.key in existing:
            _same_request(existing[req.key], digest, req.key)
        elif req.key in new:
            if new[req.key][1]["request_hash"] != digest:
                raise IdempotencyMismatch(
                    f"Idempotency-Key {req.key!r} appears twice in one batch with different "
                    "requests"
                )
        else:
            new[req.key] = (req, _new_row(req, digest, requested_by, now))
    ids: dict[str, int] = {}
    if new:
        _check_targets(s, [req for req, _ in new.values()])
        made = s.execute(_INSERT_MANY, [row for _, row in new.values()]).scalars().all()
        ids = dict(zip(new, made, strict=True))
    out = []
    for req in requests:
        if req.key in existing:
            out.append((existing[req.key].id, False))
        else:
            out.append((ids[req.key], req.key in new))
            new.pop(req.key, None)  # a key's later requests in the batch found it made
    return out


def _check_request(mode: str, key: str) -> None:
    if mode not in MODES:
        raise InvalidUpload(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
    if not key or len(key) > 128:
        raise InvalidUpload("an idempotency key of 1..128 characters is required")


def _new_row(req: DispatchRequest, digest: str, requested_by: str, now: datetime) -> dict:
    """The dispatches row of a new request."""
    return dict(
        idempotency_key=req.key,
        request_hash=digest,
        revision_id=req.revision_id,
        machine=req.machine,
        mode=req.mode,
        start=req.start,
        state=PENDING,
        attempts=0,
        bytes_sent=0,
        verified=None,
        error=None,
        requested_by=requested_by,
        created_at=now,
        updated_at=now,
        derived_id=None,
    )


def _check_target(s: Session, revision_id: int, machine: str) -> str:
    """The revision exists and is released, and the machine is known (one query); returns
    the revision's kind."""
    found = s.execute(_TARGET, dict(revision_id=revision_id, machine=machine)).one_or_none()
    status = None if found is None else found.status
    _refuse_target(revision_id, status, machine, found is not None and found.machine_id is not None)
    return found.kind


def _check_targets(s: Session, requests: list[DispatchRequest]) -> None:
    """`_check_target` for a batch: one query for the revisions, one for the machines."""
    revisions = dict(
        s.execute(_REVISION_STATES, dict(ids=sorted({r.revision_id for r in requests}))).all()
    )
    known = set(s.scalars(_KNOWN_MACHINES, dict(names=sorted({r.machine for r in requests}))))
    for req in requests:
        status = revisions.get(req.revision_id)
        _refuse_target(req.revision_id, status, req.machine, req.machine in known)


def _refuse_target(revision_id: int, status: str | None, machine: str, known: bool) -> None:
    """A dispatch needs an existing, released revision and a registered machine."""
    if status is None:
        raise NotFound(f"no revision with id {revision_id}")
    if status != "released":
        raise WorkflowError(
            f"revision {revision_id} is {status}; only a released revision can be dispatched"
        )
    if not known:
        raise NotFound(f"unknown machine {machine!r}")


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
        self,
        sessions: sessionmaker[Session],
        *,
        now: Callable[[], datetime] | None = None,
        machine_configs: MachineConfigs = default_machine_configs,
    ) -> None:
        self._sessions = sessions
        self._now = now or (lambda: datetime.now(UTC))
        self._machine_configs = machine_configs  # posting APT/CL revisions (dnc/posting.py)

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
        """Record a dispatch; the same key with the same request returns the first one.

        Core statements on the tables, no ORM objects: this is the first of the four short
        transactions every dispatch makes, and twenty of them arrive at once.

        An APT/CL revision is posted for the machine here, and the posted G-code stored as a
        derived revision in the dispatch's own transaction: a post the machine cannot run
        (`PostRefused`, with the line and why) leaves nothing behind. A G-code revision is
        checked against the machine's own axes (`NotForMachine`: a mill3 sent an A word).
        """
        _check_request(mode, key)
        self._check_for_machine(revision_id, machine)
        try:
            return self._request(key, revision_id, machine, mode, start, requested_by)
        except _PostedConcurrently:
            pass  # once more: the derived revision is there now
        try:
            return self._request(key, revision_id, machine, mode, start, requested_by)
        except _PostedConcurrently:
            raise Conflict(
                f"dispatch of revision {revision_id} to {machine} collided twice with "
                "concurrent posts of it; retry with the same Idempotency-Key"
            ) from None

    def _request(
        self, key: str, revision_id: int, machine: str, mode: str, start: bool, requested_by: str
    ) -> tuple[DispatchInfo, bool]:
        digest = request_hash(revision_id, machine, mode, start)
        try:
            with transaction(self._sessions) as s:
                existing = s.execute(_BY_KEY, dict(key=key)).one_or_none()
                if existing is not None:
                    _same_request(existing, digest, key)
                    return dispatch_info(existing), False
                kind = _check_target(s, revision_id, machine)
                # every program it calls has a released revision, or nothing is recorded
                dependencies(s, revision_id)
                now = self._now()
                req = DispatchRequest(key, revision_id, machine, mode, start)
                row = _new_row(req, digest, requested_by, now)
                if kind in SOURCE_KINDS:
                    rev, _, posted = posted_for(s, revision_id, machine, self._machine_configs)
                    derived = store_derived(s, rev, posted, actor=requested_by, now=now)
                    row["derived_id"] = derived.id
                row["id"] = s.execute(_INSERT, row).scalar_one()
                info = DispatchInfo(**{k: row[k] for k in DispatchInfo.__slots__})
                _record_dispatch_event(s, info, requested_by, "dispatch.request", now)
                return info, True
        except IntegrityError:
            # A concurrent request with the same key won the insert: answer with its row.
            # No such row: the constraint that failed was another one, which is the error.
            with transaction(self._sessions) as s:
                existing = s.execute(_BY_KEY, dict(key=key)).one_or_none()
                if existing is None:
                    if _is_source(s, revision_id):
                        raise _PostedConcurrently from None  # its derived revision: again
                    raise
                _same_request(existing, digest, key)
                return dispatch_info(existing), False

    def get(self, dispatch_id: int) -> DispatchInfo:
        with transaction(self._sessions) as s:
            row = s.get(m.Dispatch, dispatch_id)
            if row is None:
                raise NotFound(f"no dispatch with id {dispatch_id}")
            return dispatch_info(row)

    def list(
        self,
        *,
        machine: str | None = None,
        state: str | None = None,
        before: int | None = None,
        limit: int = 100,
    ) -> list[DispatchInfo]:
        """Dispatches newest first, of `machine` and in `state` if given, with ids below
        `before` (the page after a cursor) if given."""
        stmt = select(m.Dispatch).order_by(m.Dispatch.id.desc()).limit(limit)
        if before is not None:
            stmt = stmt.where(m.Dispatch.id < before)
        if machine:
            stmt = stmt.where(m.Dispatch.machine == machine)
        if state:
            stmt = stmt.where(m.Dispatch.state == state)
        with transaction(self._sessions) as s:
            return [dispatch_info(r) for r in s.scalars(stmt)]

    def _check_for_machine(self, revision_id: int, machine: str) -> None:
        """A G-code revision passed the upload check for its kind, whose machines may have
        more axes than this one (dnc.checker): checked here with the machine's own
        configuration when the host has it, refused with the first error's line."""
        with transaction(self._sessions) as s:
            rev = s.get(m.Revision, revision_id)
            mach = s.scalar(select(m.Machine).where(m.Machine.name == machine))
            if rev is None or mach is None or rev.kind != GCODE:
                return  # an unknown target is refused by the request; a source is posted
            config = self._machine_configs(mach.name, mach.kind)
            if config is None:
                return
            kind = s.get(m.Program, rev.program_id).machine_kind
            text = read_text(s, rev.sha256)
        errors = machine_check(text, kind, config, programs=LibraryPrograms(self._sessions, kind))
        if errors:
            e = errors[0]
            axes = " ".join(config.axes)
            raise NotForMachine(
                f"revision {revision_id} line {e['line']}, column {e['col']}: {e['message']} "
                f"({machine} is a {mach.kind} with axes {axes})",
                line=e["line"],
                column=e["col"],
                reason=e["message"],
                machine=machine,
                axes=list(config.axes),
            )


class _PostedConcurrently(Exception):
    """A concurrent dispatch stored the derived revision this one was about to: the request
    runs again and finds it."""


def _is_source(s: Session, revision_id: int) -> bool:
    return s.scalar(_IS_SOURCE, dict(revision_id=revision_id)) in SOURCE_KINDS


def _record_dispatch_event(
    s: Session, row: m.Dispatch | DispatchInfo, actor: str, action: str, now: datetime
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


_DISPATCHES = m.Dispatch.__table__
_BY_KEY = select(_DISPATCHES).where(_DISPATCHES.c.idempotency_key == bindparam("key"))
_INSERT = insert(_DISPATCHES).returning(_DISPATCHES.c.id)
# Several rows in one statement, their ids handed back in the order of the rows.
_INSERT_MANY = insert(_DISPATCHES).returning(_DISPATCHES.c.id, sort_by_parameter_order=True)
_BY_KEYS = select(_DISPATCHES).where(
    _DISPATCHES.c.idempotency_key.in_(bindparam("keys", expanding=True))
)
_IS_SOURCE = select(m.Revision.__table__.c.kind).where(
    m.Revision.__table__.c.id == bindparam("revision_id")
)
_REVISION_STATES = select(m.Revision.__table__.c.id, m.Revision.__table__.c.status).where(
    m.Revision.__table__.c.id.in_(bindparam("ids", expanding=True))
)
_KNOWN_MACHINES = select(m.Machine.__table__.c.name).where(
    m.Machine.__table__.c.name.in_(bindparam("names", expanding=True))
)
_TARGET = select(
    m.Revision.__table__.c.status,
    m.Revision.__table__.c.kind,
    select(m.Machine.__table__.c.id)
    .where(m.Machine.__table__.c.name == bindparam("machine"))
    .scalar_subquery()
    .label("machine_id"),
).where(m.Revision.__table__.c.id == bindparam("revision_id"))


def dispatch_info(r: m.Dispatch) -> DispatchInfo:
    """From an ORM row or a Core row of the dispatches table."""
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
        r.derived_id,
    )
