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
    detail = json.loads(json.dumps(detail, default=str))  # JSON columns take plain data only
    # The audit row by a Core insert (compiled once, reused): every change writes one, and
    # the ORM's unit of work cost more CPU than the rest of a small state change. The outbox
    # row stays an ORM object: the event hub learns of new events from the session's flush.
    s.execute(
        _AUDIT,
        dict(at=now, actor=actor, action=action, entity=entity, entity_id=entity_id, detail=detail),
    )
    s.add(
        m.OutboxEvent(
            at=now,
            topic=topic or f"fmscell/{entity}/{action.rsplit('.', 1)[-1]}",
            payload={"action": action, "entity": entity, "id": entity_id, **detail},
        )
    )


_AUDIT = insert(m.AuditEntry)
