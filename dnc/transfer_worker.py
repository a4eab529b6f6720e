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
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta

from sqlalchemy import or_, select, update
from sqlalchemy.orm import Session, sessionmaker

from dnc import models as m
from dnc.db import transaction
from dnc.dispatch import DONE, FAILED, PENDING, TRANSFERRING, VERIFYING, dispatch_info
from dnc.events import record
from dnc.transfer import DncClient, TransferError, canonical_text, iter_blocks, sha256_text

log = logging.getLogger(__name__)
STARTING = "starting"

ClientFactory = Callable[[str, int, dict], DncClient]
Starter = Callable[[str, int], None]
"""(machine name, program number) -> None: cycle start through the machine's remote panel."""


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
        chunk=int(profile.get("chunk", 1024)),
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
    ) -> None:
        self._sessions = sessions
        self._client = client_factory
        self._starter = starter
        self.retry = retry or RetryPolicy()
        self._now = now or (lambda: datetime.now(UTC))
        self._recovered = False

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
            # Claim it: only one worker moves a pending dispatch to transferring.
            claimed = s.execute(
                update(m.Dispatch)
                .where(m.Dispatch.id == dispatch_id, m.Dispatch.state == PENDING)
                .values(state=TRANSFERRING, attempts=m.Dispatch.attempts + 1, updated_at=now)
            ).rowcount
            if not claimed:
                return s.get(m.Dispatch, dispatch_id).state
            row = s.get(m.Dispatch, dispatch_id)
            self._event(s, row, now)
            mach = s.scalar(select(m.Machine).where(m.Machine.name == row.machine))
            rev = s.get(m.Revision, row.revision_id)
            job = dict(
                mode=row.mode,
                start=row.start,
                attempts=row.attempts,
                address=mach.dnc_address if mach else "",
                profile=dict(mach.dnc_profile or {}) if mach else {},
                sha=rev.sha256,
                number=s.get(m.Program, rev.program_id).number,
            )
        text = self._text(dispatch_id)
        try:
            host, port = _address(job["address"], dispatch_id)
            client = self._client(host, port, job["profile"])
            with client:
                if job["mode"] == "drip_feed":
                    result = client.drip_feed(iter_blocks([text]))
                    sent, verified = result.bytes_sent, None
                else:
                    result = client.send_program(text, number=job["number"])
                    sent = result.bytes_sent
                    self._step(dispatch_id, VERIFYING, bytes_sent=sent)
                    verified = self._verify(client, job["number"], text, result.sha256)
            if job["start"]:
                if self._starter is None:
                    raise TransferError(
                        "start",
                        "start requested but this host has no cycle-start path to the machine",
                    )
                self._step(dispatch_id, STARTING, bytes_sent=sent, verified=verified)
                try:
                    self._starter(self._machine_of(dispatch_id), job["number"])
                except Exception as exc:
                    raise TransferError("start", f"cycle start failed: {exc}") from exc
            self._step(dispatch_id, DONE, bytes_sent=sent, verified=verified, error=None)
            return DONE
        except TransferError as exc:
            return self._fail(dispatch_id, job["attempts"], exc)

    # ------------------------------------------------------------------------------ helpers

    def _verify(self, client: DncClient, number: int, text: str, stored_sha: str) -> bool:
        expected = sha256_text(canonical_text(text))
        punched = sha256_text(client.punch(number))
        if stored_sha != expected or punched != expected:
            raise TransferError(
                "verify",
                f"verification failed: sent {expected[:12]}, machine stored {stored_sha[:12]}, "
                f"read back {punched[:12]}",
            )
        return True

    def _text(self, dispatch_id: int) -> str:
        with transaction(self._sessions) as s:
            row = s.get(m.Dispatch, dispatch_id)
            rev = s.get(m.Revision, row.revision_id)
            return s.get(m.Content, rev.sha256).text

    def _machine_of(self, dispatch_id: int) -> str:
        with transaction(self._sessions) as s:
            return s.get(m.Dispatch, dispatch_id).machine

    def _fail(self, dispatch_id: int, attempts: int, exc: TransferError) -> str:
        now = self._now()
        retry = exc.retryable and attempts < self.retry.max_attempts
        with transaction(self._sessions) as s:
            row = s.get(m.Dispatch, dispatch_id)
            row.bytes_sent = max(row.bytes_sent, exc.sent)
            error = f"{exc.kind}: {exc.message}"
            if retry:
                row.next_attempt_at = now + self.retry.delay(attempts)
                error += f" (attempt {attempts} of {self.retry.max_attempts}; retry at {row.next_attempt_at.isoformat()})"
                self._set(s, row, PENDING, now, error=error)
            else:
                self._set(s, row, FAILED, now, error=error)
            return row.state

    def _step(self, dispatch_id: int, state: str, **values) -> None:
        now = self._now()
        with transaction(self._sessions) as s:
            self._set(s, s.get(m.Dispatch, dispatch_id), state, now, **values)

    def _set(self, s: Session, row: m.Dispatch, state: str, now: datetime, **values) -> None:
        row.state, row.updated_at = state, now
        for key, value in values.items():
            setattr(row, key, value)
        self._event(s, row, now)

    @staticmethod
    def _event(s: Session, row: m.Dispatch, now: datetime) -> None:
        info = dispatch_info(row)
        record(
            s,
            now=now,
            actor="transfer-worker",
            action=f"dispatch.{info.state}",
            entity="dispatch",
            entity_id=info.id,
            machine=info.machine,
            revision_id=info.revision_id,
            attempts=info.attempts,
            bytes_sent=info.bytes_sent,
            verified=info.verified,
            error=info.error,
        )


def _address(address: str, dispatch_id: int) -> tuple[str, int]:
    host, _, port = address.rpartition(":")
    if not host or not port.isdigit():
        raise TransferError(
            "connect", f"machine has no DNC address (got {address!r}) for dispatch {dispatch_id}"
        )
    return host, int(port)
