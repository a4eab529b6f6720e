"""Executing dispatches: transfer, verify, start; retries with backoff; a recorded outcome.

Every state change is its own committed transaction with its audit entry and event, so a
host killed at any point finds each dispatch in the state it reached:

    pending -> transferring -> verifying -> starting -> done
                    \\-> pending (retry after backoff) -> ... -> failed

On restart, a dispatch caught in `transferring` or `verifying` is simply run again: loading
the same program again is harmless and verification compares content hashes. One caught in
`starting` is NOT started again (that could make a part twice): it is marked failed with a
message telling the operator to check the machine, which the scheduler then sees.
"""

from __future__ import annotations

import logging
import threading
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta

from sqlalchemy import bindparam, exists, or_, select, update
from sqlalchemy.orm import Session, sessionmaker

from dnc import models as m
from dnc.checker import machine_check
from dnc.content import read_text
from dnc.db import transaction
from dnc.dependencies import Dependency, LibraryPrograms, MissingDependency, dependencies
from dnc.dispatch import DONE, FAILED, PENDING, TRANSFERRING, VERIFYING, dispatch_info
from dnc.errors import DncError
from dnc.events import record
from dnc.posting import (
    GCODE,
    SOURCE_KINDS,
    MachineConfigs,
    default_machine_configs,
    posted_for,
    store_derived,
)
from dnc.transfer import (
    CHUNK,
    DncClient,
    TransferError,
    canonical_text,
    iter_blocks,
    sha256_text,
)

log = logging.getLogger(__name__)
STARTING = "starting"

ClientFactory = Callable[[str, int, dict], DncClient]
Starter = Callable[[str, int], "int | None"]
"""(machine name, program number) -> the machine's part counter just before cycle start was
pressed (None if unknown): cycle start through the machine's remote panel. The counter is
written as the allocation's baseline with the confirmed start, so a part an operator made
between the allocation and the start is never counted as the allocation's."""


@dataclass(frozen=True, slots=True)
class RetryPolicy:
    max_attempts: int = 5
    base_s: float = 1.0
    cap_s: float = 60.0

    def delay(self, attempts: int) -> timedelta:
        return timedelta(seconds=min(self.cap_s, self.base_s * 2 ** max(0, attempts - 1)))


def _default_client(host: str, port: int, profile: dict) -> DncClient:
    return DncClient(
        host,
        port,
        parity=bool(profile.get("parity", False)),
        timeout_s=float(profile.get("timeout_s", 10.0)),
        xoff_timeout_s=float(profile.get("xoff_timeout_s", 30.0)),
        chunk=int(profile.get("chunk", CHUNK)),
        secret=profile.get("secret"),
    )


class TransferWorker:
    def __init__(
        self,
        sessions: sessionmaker[Session],
        *,
        client_factory: ClientFactory = _default_client,
        starter: Starter | None = None,
        retry: RetryPolicy | None = None,
        now: Callable[[], datetime] | None = None,
        part_counter: Callable[[str], int | None] | None = None,
        machine_configs: MachineConfigs = default_machine_configs,
    ) -> None:
        self._sessions = sessions
        self.machine_configs = machine_configs  # posting APT/CL revisions (dnc/posting.py)
        self._client = client_factory
        self._starter = starter
        # The machine's part counter as the host sees it (None: unknown). Read before the
        # start is claimed and written as the allocation's baseline with the claim, so a
        # host killed between pressing cycle start and confirming it leaves a baseline that
        # does not count an operator's earlier part as the job's.
        self._part_counter = part_counter
        self.retry = retry or RetryPolicy()
        self._now = now or (lambda: datetime.now(UTC))
        self._recovered = False
        # content sha256 -> sha256 of the form a machine stores it in. Dispatching one
        # revision to twenty machines decodes it once, not twenty times.
        self._stored_sha = _Memo(4096)
        # content sha256 -> text: content never changes under its sha256, so a text read
        # once stays right; twenty dispatches of one revision read it once.
        self._texts = _Memo(TEXT_CACHE_CHARS, weight=len)

    def recover(self) -> int:
        """After a restart: requeue interrupted transfers, fail interrupted starts."""
        now = self._now()
        with transaction(self._sessions) as s:
            rows = s.scalars(
                select(m.Dispatch).where(m.Dispatch.state.in_((TRANSFERRING, VERIFYING, STARTING)))
            ).all()
            for row in rows:
                if row.state == STARTING:
                    self._set(
                        s,
                        row,
                        FAILED,
                        now,
                        error="start: the host stopped while starting the program; check the "
                        "machine before dispatching again (it is never started twice)",
                    )
                else:
                    self._set(s, row, PENDING, now, error="host restarted during the transfer")
        self._recovered = True
        return len(rows)

    def run_once(self, limit: int = 10) -> list[int]:
        """Run every due dispatch (oldest first); returns the ids that were worked on."""
        if not self._recovered:
            self.recover()
        now = self._now()
        with transaction(self._sessions) as s:
            ids = list(
                s.scalars(
                    select(m.Dispatch.id)
                    .where(
                        m.Dispatch.state == PENDING,
                        or_(
                            m.Dispatch.next_attempt_at.is_(None), m.Dispatch.next_attempt_at <= now
                        ),
                    )
                    .order_by(m.Dispatch.id)
                    .limit(limit)
                )
            )
        for dispatch_id in ids:
            self.run(dispatch_id)
        return ids

    def run(self, dispatch_id: int) -> str:
        """One attempt at one dispatch; returns its new state."""
        now = self._now()
        with transaction(self._sessions) as s:
            # Everything the attempt needs in one query, Core rather than ORM (twenty
            # transfers at once made the ORM's per-row work most of the host's CPU time),
            # read before the claim so the write lock is held only for the writes.
            found = s.execute(_ATTEMPT, dict(dispatch_id=dispatch_id)).one()
            # Claim it: only one worker moves a pending dispatch to transferring.
            claimed = s.execute(_CLAIM, dict(dispatch_id=dispatch_id, now=now)).one_or_none()
            if claimed is None:
                return s.scalar(select(_D.c.state).where(_D.c.id == dispatch_id))
            snap = dict(
                id=dispatch_id,
                machine=found.machine,
                revision_id=found.revision_id,
                state=TRANSFERRING,
                attempts=claimed.attempts,
                bytes_sent=claimed.bytes_sent,
                verified=claimed.verified,
                error=claimed.error,
            )
            _event(s, snap, now)
            job = dict(
                mode=found.mode,
                start=found.start,
                attempts=claimed.attempts,
                machine=found.machine,
                address=found.dnc_address or "",
                profile=dict(found.dnc_profile or {}),
                sha=found.posted_sha256 or found.sha256,
                number=found.number,
            )
        if found.kind in SOURCE_KINDS and found.posted_sha256 is None:
            # a dispatch the scheduler made for an APT/CL revision: posted now, for this
            # machine, with the derived revision stored before anything is sent
            try:
                job["sha"] = self._post(dispatch_id, found.revision_id, found.machine)
            except DncError as exc:  # the post refused: no attempt will do better
                failure = TransferError("post", exc.message)
                return self._fail(dispatch_id, job["attempts"], failure)
            except Exception as exc:  # the database, a concurrent post: the next attempt may pass
                failure = TransferError("read", f"posting revision {found.revision_id}: {exc}")
                return self._fail(dispatch_id, job["attempts"], failure)
        try:
            # read after the claim committed: a failure here must still end in a recorded
            # failure or retry, never leave the dispatch in `transferring`
            text = self._text(job["sha"])
        except Exception as exc:
            failure = TransferError("read", f"revision text {job['sha'][:12]}: {exc}")
            return self._fail(dispatch_id, job["attempts"], failure)
        if (unsendable := _outside_tape_code(text)) is not None:
            # stored before uploads were held to the ISO character set: the 7-bit tape
            # cannot carry it, on this attempt or any other
            return self._fail(dispatch_id, job["attempts"], unsendable)
        if found.kind == GCODE and (refusal := self._not_for_machine(found, text)) is not None:
            # a dispatch the scheduler made to a machine without an axis the program names
            # (a mill3 given a mill4's A words): refused before anything is sent
            return self._fail(dispatch_id, job["attempts"], refusal)
        try:
            # the programs it calls, as released now (the request checked them; one may
            # have been made obsolete since): a missing one fails before anything is sent
            with transaction(self._sessions) as s:
                deps = dependencies(s, found.revision_id)
        except MissingDependency as exc:
            failure = TransferError("dependency", exc.message)
            return self._fail(dispatch_id, job["attempts"], failure)
        except Exception as exc:
            failure = TransferError("read", f"dependencies of revision {found.revision_id}: {exc}")
            return self._fail(dispatch_id, job["attempts"], failure)
        try:
            host, port = _address(job["address"], dispatch_id)
            client = self._client(host, port, job["profile"])
            with client:
                brought = self._bring(client, deps, dispatch_id) if deps else 0
                if job["mode"] == "drip_feed":
                    result = client.drip_feed(iter_blocks([text]))
                    sent, verified = brought + result.bytes_sent, None
                else:
                    result = client.send_program(text, number=job["number"])
                    sent = result.bytes_sent
                    if not self._step(snap, VERIFYING, bytes_sent=sent):
                        return self._called_off(dispatch_id)
                    verified = self._verify(client, job, text, result.sha256)
            if job["start"]:
                if self._starter is None:
                    raise TransferError(
                        "start",
                        "start requested but this host has no cycle-start path to the machine",
                    )
                # Claimed under the database's write lock, conditional on the dispatch not
                # having been called off and its allocation still active: a part whose
                # allocation the scheduler interrupted is never started.
                before = self._part_counter(job["machine"]) if self._part_counter else None
                if not self._step(
                    snap, STARTING, bytes_sent=sent, verified=verified, start=True, baseline=before
                ):
                    return self._called_off(dispatch_id)
                try:
                    baseline = self._starter(job["machine"], job["number"])
                except Exception as exc:
                    # The NC (or PLC) said no: nothing ran, and the allocation must never be
                    # credited with a part the machine counts later (dnc.allocation).
                    kind = "start refused" if getattr(exc, "refused", False) else "start"
                    raise TransferError(kind, f"cycle start failed: {exc}") from exc
            else:
                baseline = None
            done = dict(bytes_sent=sent, verified=verified, error=None)
            if not self._step(snap, DONE, baseline=baseline, **done):
                return self._called_off(dispatch_id)
            return DONE
        except TransferError as exc:
            return self._fail(dispatch_id, job["attempts"], exc)
        except Exception as exc:  # a bug costs one attempt, recorded, never a dispatch stuck
            log.exception("dispatch %d: attempt failed", dispatch_id)
            failure = TransferError("internal", f"{type(exc).__name__}: {exc}")
            return self._fail(dispatch_id, job["attempts"], failure)

    # ------------------------------------------------------------------------------ helpers

    def _bring(self, client: DncClient, deps: list[Dependency], dispatch_id: int) -> int:
        """Load the programs the dispatched one calls, deepest first; one the machine holds
        already with the same content (DIR's sha256) is not sent again. Returns the bytes
        sent on the connection so far."""
        held = {number: sha for number, _, sha in client.directory()}
        sent: list[int] = []
        bytes_sent = 0
        kept: list[int] = []
        for dep in deps:
            text = self._text(dep.sha256)
            if (unsendable := _outside_tape_code(text)) is not None:
                raise TransferError("encode", f"subprogram O{dep.number:04d}: {unsendable.message}")
            expected = self._expected_sha(dep.sha256, text)
            if held.get(dep.number) == expected:
                kept.append(dep.number)
                continue
            result = client.send_program(text, number=dep.number)
            if result.sha256 != expected:
                raise TransferError(
                    "verify",
                    f"subprogram O{dep.number:04d}: sent {expected[:12]}, machine stored "
                    f"{result.sha256[:12]}",
                )
            sent.append(dep.number)
            bytes_sent = result.bytes_sent  # counted from the connection's start
        with transaction(self._sessions) as s:
            record(s, now=self._now(), actor="transfer-worker", action="dispatch.subprograms",
                   entity="dispatch", entity_id=dispatch_id, sent=sent, already_there=kept,
                   revisions=[d.revision_id for d in deps])  # fmt: skip
        return bytes_sent

    def _not_for_machine(self, found, text: str) -> TransferError | None:
        """The machine check of a G-code revision (dnc.checker.machine_check) as a
        failure of kind `check`; None when it passes or the host lacks the machine's
        configuration."""
        config = self.machine_configs(found.machine, found.machine_kind)
        if config is None:
            return None
        kind = found.program_kind
        errors = machine_check(text, kind, config, programs=LibraryPrograms(self._sessions, kind))
        if not errors:
            return None
        e = errors[0]
        return TransferError(
            "check",
            f"line {e['line']}, column {e['col']}: {e['message']} "
            f"({found.machine} has axes {' '.join(config.axes)})",
        )

    def _post(self, dispatch_id: int, revision_id: int, machine: str) -> str:
        """Post the dispatch's source for its machine and record the derived revision on
        the dispatch (one transaction); the sha256 of the posted text."""
        with transaction(self._sessions) as s:
            rev, _, posted = posted_for(s, revision_id, machine, self.machine_configs)
            derived = store_derived(s, rev, posted, actor="transfer-worker", now=self._now())
            s.execute(update(_D).where(_D.c.id == dispatch_id).values(derived_id=derived.id))
            return derived.sha256

    def _verify(self, client: DncClient, job: dict, text: str, stored_sha: str) -> bool:
        expected = self._expected_sha(job["sha"], text)
        punched = client.punch_sha256(job["number"], expected=expected)
        if stored_sha != expected or punched != expected:
            raise TransferError(
                "verify",
                f"verification failed: sent {expected[:12]}, machine stored {stored_sha[:12]}, "
                f"read back {punched[:12]}",
            )
        return True

    def _expected_sha(self, content_sha: str, text: str) -> str:
        return self._stored_sha.get(content_sha, lambda: sha256_text(canonical_text(text)))

    def _text(self, sha: str) -> str:
        """The revision's text, read once for all the dispatches of it."""

        def read() -> str:
            with transaction(self._sessions) as s:
                return read_text(s, sha)

        return self._texts.get(sha, read)

    def _fail(self, dispatch_id: int, attempts: int, exc: TransferError) -> str:
        now = self._now()
        retry = exc.retryable and attempts < self.retry.max_attempts
        with transaction(self._sessions) as s:
            row = s.get(m.Dispatch, dispatch_id, with_for_update=True)
            if row.state not in _WORKER_STATES:
                return row.state  # called off by the scheduler meanwhile: it stays so
            row.bytes_sent = max(row.bytes_sent, exc.sent)
            error = f"{exc.kind}: {exc.message}"
            if retry:
                row.next_attempt_at = now + self.retry.delay(attempts)
                error += f" (attempt {attempts} of {self.retry.max_attempts}; retry at {row.next_attempt_at.isoformat()})"
                self._set(s, row, PENDING, now, error=error)
            else:
                self._set(s, row, FAILED, now, error=error)
            return row.state

    def _step(
        self,
        snap: dict,
        state: str,
        *,
        start: bool = False,
        baseline: int | None = None,
        **values,
    ) -> bool:
        """Move a claimed dispatch on: one UPDATE and its event, from the claim's snapshot
        (only this worker writes a dispatch it has claimed, so the snapshot is the row).

        False if the scheduler has called the dispatch off meanwhile (or, for the start,
        its allocation is no longer active): nothing is written then."""
        now = self._now()
        with transaction(self._sessions) as s:
            moved = s.execute(
                _START if start else _STEP,
                dict(
                    dispatch_id=snap["id"],
                    state=state,
                    updated_at=now,
                    bytes_sent=values.get("bytes_sent", snap["bytes_sent"]),
                    verified=values.get("verified", snap["verified"]),
                    error=values.get("error", snap["error"]),
                ),
            ).first()
            if moved is None:
                return False
            if isinstance(baseline, int):
                s.execute(_BASELINE, dict(b_dispatch=snap["id"], b_parts=baseline))
            snap.update(values, state=state)
            _event(s, snap, now)
            return True

    def _called_off(self, dispatch_id: int) -> str:
        with transaction(self._sessions) as s:
            state = s.scalar(select(_D.c.state).where(_D.c.id == dispatch_id))
        log.info("dispatch %s called off by the scheduler: not started", dispatch_id)
        return state

    def _set(self, s: Session, row: m.Dispatch, state: str, now: datetime, **values) -> None:
        row.state, row.updated_at = state, now
        for key, value in values.items():
            setattr(row, key, value)
        info = dispatch_info(row)
        _event(s, {k: getattr(info, k) for k in _EVENT_FIELDS}, now)


# Core statements on the tables, compiled once: an ORM-enabled UPDATE goes through the ORM's
# bulk-update machinery, several times the CPU of the statement itself.
_D = m.Dispatch.__table__
_DERIVED = m.DerivedRevision.__table__
_ATTEMPT = (
    select(
        _D.c.machine,
        _D.c.revision_id,
        _D.c.mode,
        _D.c.start,
        m.Machine.__table__.c.dnc_address,
        m.Machine.__table__.c.dnc_profile,
        m.Revision.__table__.c.sha256,
        m.Revision.__table__.c.kind,
        m.Program.__table__.c.number,
        m.Program.__table__.c.machine_kind.label("program_kind"),
        m.Machine.__table__.c.kind.label("machine_kind"),
        _DERIVED.c.sha256.label("posted_sha256"),
    )
    .select_from(_D)
    .join(m.Revision.__table__, m.Revision.__table__.c.id == _D.c.revision_id)
    .join(m.Program.__table__, m.Program.__table__.c.id == m.Revision.__table__.c.program_id)
    .outerjoin(m.Machine.__table__, m.Machine.__table__.c.name == _D.c.machine)
    .outerjoin(_DERIVED, _DERIVED.c.id == _D.c.derived_id)
    .where(_D.c.id == bindparam("dispatch_id"))
)
_CLAIM = (
    update(_D)
    .where(_D.c.id == bindparam("dispatch_id"), _D.c.state == PENDING)
    .values(state=TRANSFERRING, attempts=_D.c.attempts + 1, updated_at=bindparam("now"))
    .returning(_D.c.attempts, _D.c.bytes_sent, _D.c.verified, _D.c.error)
)
# The states only the worker moves a claimed dispatch through; the scheduler may call a
# dispatch off (failed) before its start, so every step is conditional on still being in one.
_WORKER_STATES = (TRANSFERRING, VERIFYING, STARTING)
_STEP_VALUES = dict(
    state=bindparam("state"),
    updated_at=bindparam("updated_at"),
    bytes_sent=bindparam("bytes_sent"),
    verified=bindparam("verified"),
    error=bindparam("error"),
)
_STEP = (
    update(_D)
    .where(_D.c.id == bindparam("dispatch_id"), _D.c.state.in_(_WORKER_STATES))
    .values(**_STEP_VALUES)
    .returning(_D.c.id)
)
_A = m.Allocation.__table__
_START = (
    update(_D)
    .where(
        _D.c.id == bindparam("dispatch_id"),
        _D.c.state.in_((TRANSFERRING, VERIFYING)),
        ~exists().where(_A.c.dispatch_id == _D.c.id, _A.c.status.not_in(("dispatched", "running"))),
    )
    .values(**_STEP_VALUES)
    .returning(_D.c.id)
)
_BASELINE = (
    update(_A)
    .where(
        _A.c.dispatch_id == bindparam("b_dispatch"),
        _A.c.status.in_(("dispatched", "running")),
    )
    .values(parts_at_start=bindparam("b_parts"))
)
TEXT_CACHE_CHARS = 64 * 1024 * 1024
_EVENT_FIELDS = (
    "id",
    "machine",
    "revision_id",
    "state",
    "attempts",
    "bytes_sent",
    "verified",
    "error",
)


class _Memo:
    """Values computed once per key and kept, least recently used first out, up to `limit`
    in total `weight`. Threads asking for a key being computed wait for that result: twenty
    dispatches of a new revision start at once, and each working it out for itself cost a
    first round twenty times the work."""

    def __init__(self, limit: int, weight: Callable[[object], int] = lambda _: 1) -> None:
        self._limit, self._weight = limit, weight
        self._values: OrderedDict[str, object] = OrderedDict()
        self._total = 0
        self._lock = threading.Lock()
        self._computing: dict[str, threading.Lock] = {}

    def get(self, key: str, compute: Callable[[], object]):
        with self._lock:
            if key in self._values:
                self._values.move_to_end(key)
                return self._values[key]
            gate = self._computing.setdefault(key, threading.Lock())
        with gate:
            with self._lock:
                if key in self._values:
                    return self._values[key]
            try:
                value = compute()
                weight = self._weight(value)  # before storing: a value it rejects is not kept
            except BaseException:
                with self._lock:
                    self._computing.pop(key, None)
                raise
            with self._lock:
                # stored and the gate dropped under one lock: a thread arriving now finds
                # either the value or the gate, never neither (which would compute again)
                self._values[key] = value
                self._total += weight
                self._computing.pop(key, None)
                while self._total > self._limit and len(self._values) > 1:
                    self._total -= self._weight(self._values.popitem(last=False)[1])
            return value


def _event(s: Session, snap: dict, now: datetime) -> None:
    record(
        s,
        now=now,
        actor="transfer-worker",
        action=f"dispatch.{snap['state']}",
        entity="dispatch",
        entity_id=snap["id"],
        machine=snap["machine"],
        revision_id=snap["revision_id"],
        attempts=snap["attempts"],
        bytes_sent=snap["bytes_sent"],
        verified=snap["verified"],
        error=snap["error"],
    )


def _address(address: str, dispatch_id: int) -> tuple[str, int]:
    host, _, port = address.rpartition(":")
    if not host or not port.isdigit():
        raise TransferError(
            "connect", f"machine has no DNC address (got {address!r}) for dispatch {dispatch_id}"
        )
    return host, int(port)


def _outside_tape_code(text: str) -> TransferError | None:
    """A failure naming the first character the ISO 7-bit tape cannot carry, or None."""
    if text.isascii():
        return None
    at = next(i for i, ch in enumerate(text) if ord(ch) > 0x7F)
    before = text[:at]
    line, column = before.count("\n") + 1, at - (before.rfind("\n") + 1) + 1
    return TransferError(
        "encode",
        f"character {text[at]!r} (U+{ord(text[at]):04X}) at line {line}, column {column} is "
        "outside the ISO 7-bit tape code; the revision cannot be sent (upload a corrected one)",
    )
