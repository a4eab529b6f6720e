"""Audit entry plus outbox event, always written together in the caller's transaction."""

from __future__ import annotations

import json
from datetime import datetime

from sqlalchemy import insert
from sqlalchemy.orm import Session

from dnc import models as m


def record(
    s: Session,
    *,
    now: datetime,
    actor: str,
    action: str,
    entity: str,
    entity_id: int | None,
    topic: str | None = None,
    **detail: object,
) -> None:
    """Append who did what to the audit log and queue the matching event for publication.

    The topic defaults to `fmscell/<entity>/<verb>` (the verb is the action's last part).
    """
    # Both rows by Core inserts on the tables (compiled once, reused): every change writes
    # them, and the ORM's unit of work, even an ORM-enabled insert, cost more CPU than the
    # rest of a small state change.
    audit, outbox = _rows(now, actor, action, entity, entity_id, detail, topic)
    s.execute(_AUDIT, audit)
    s.execute(_OUTBOX, outbox)
    # A Core insert is no ORM flush: tell the session's listeners (the event hub wakes its
    # readers at commit) that this transaction wrote events.
    s.info[OUTBOX_WRITTEN] = True


def record_many(
    s: Session,
    *,
    now: datetime,
    actor: str,
    entries: list[tuple[str, str, int | None, dict]],
) -> None:
    """`record` for many changes of one transaction: (action, entity, entity_id, detail)
    each, written in that order by one insert per table (a scheduler tick records dozens)."""
    rows = [_rows(now, actor, *entry) for entry in entries]
    if rows:
        s.execute(_AUDIT, [audit for audit, _ in rows])
        s.execute(_OUTBOX, [outbox for _, outbox in rows])
        s.info[OUTBOX_WRITTEN] = True


def _rows(
    now: datetime,
    actor: str,
    action: str,
    entity: str,
    entity_id: int | None,
    detail: dict,
    topic: str | None = None,
) -> tuple[dict, dict]:
    """The audit row and the outbox row of one change."""
    detail = json.loads(json.dumps(detail, default=str))  # JSON columns take plain data only
    audit = dict(
        at=now, actor=actor, action=action, entity=entity, entity_id=entity_id, detail=detail
    )
    outbox = dict(
        at=now,
        topic=topic or f"fmscell/{entity}/{action.rsplit('.', 1)[-1]}",
        payload={"action": action, "entity": entity, "id": entity_id, **detail},
    )
    return audit, outbox


OUTBOX_WRITTEN = "fmscell_outbox_written"
"""Session.info key set when a transaction wrote outbox rows (read by web_api.event_hub)."""
_AUDIT = insert(m.AuditEntry.__table__)
_OUTBOX = insert(m.OutboxEvent.__table__)
