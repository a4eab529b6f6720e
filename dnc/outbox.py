"""Publishing the outbox: at-least-once delivery of the events written with each change.

Events are read in id order and marked published only after the sink accepted them, so a
crash between the two publishes an event twice, never zero times. Consumers deduplicate by
the event id carried in every payload.
"""

from __future__ import annotations

import json
import threading
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime

from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from dnc import models as m
from dnc.db import transaction


@dataclass(frozen=True, slots=True)
class Event:
    id: int
    at: datetime
    topic: str
    payload: dict

    def to_json(self) -> str:
        return json.dumps(
            {"event_id": self.id, "at": self.at.isoformat(), "topic": self.topic, **self.payload},
            separators=(",", ":"),
        )


def events_after(sessions: sessionmaker[Session], after_id: int, limit: int = 500) -> list[Event]:
    """The event log in order, for the SSE stream (resumable by Last-Event-ID)."""
    with transaction(sessions) as s:
        rows = s.scalars(
            select(m.OutboxEvent)
            .where(m.OutboxEvent.id > after_id)
            .order_by(m.OutboxEvent.id)
            .limit(limit)
        )
        return [Event(r.id, r.at, r.topic, r.payload) for r in rows]


class OutboxPublisher:
    def __init__(
        self,
        sessions: sessionmaker[Session],
        sink: Callable[[Event], None],
        *,
        now: Callable[[], datetime] | None = None,
    ) -> None:
        self._sessions = sessions
        self._sink = sink
        self._now = now or (lambda: datetime.now(UTC))

    def publish_pending(self, batch: int = 100) -> int:
        """Publish up to `batch` unpublished events; returns how many were delivered.

        A sink failure stops the batch: the failed event and everything after it stay
        unpublished and are retried on the next call, in order.
        """
        delivered = 0
        with transaction(self._sessions) as s:
            stmt = (
                select(m.OutboxEvent)
                .where(m.OutboxEvent.published_at.is_(None))
                .order_by(m.OutboxEvent.id)
                .limit(batch)
                .with_for_update(skip_locked=True)
            )
            for row in s.scalars(stmt):
                try:
                    self._sink(Event(row.id, row.at, row.topic, row.payload))
                except Exception:
                    break
                row.published_at = self._now()
                delivered += 1
        return delivered


class AckedPublish:
    """QoS 1 publication of outbox events on a paho client, each waited for until PUBACK.

    An event is never handed to paho while the connection is down (paho would queue it and
    send it after the reconnect while the outbox sends it again), and an event whose PUBACK
    did not come in time stays with paho, which resends it after a reconnect: the next
    attempt waits for that message instead of publishing a second one. So each event id is
    published once per connection until the broker acknowledges it; a broker that dies
    between receiving an event and acknowledging it may still pass it on twice (QoS 1),
    which is why payloads carry the event id.
    """

    def __init__(self, client, timeout_s: float = 5.0) -> None:
        self._client = client
        self._timeout = timeout_s
        self._pending: dict[int, object] = {}  # event id -> paho MQTTMessageInfo

    def __call__(self, event: Event, topic: str) -> None:
        import paho.mqtt.client as mqtt

        info = self._pending.get(event.id)
        if info is None:
            if not self._client.is_connected():
                raise ConnectionError(f"MQTT broker not connected; event {event.id} kept")
            info = self._client.publish(topic, event.to_json(), qos=1)
            if info.rc == mqtt.MQTT_ERR_NO_CONN:
                # the connection dropped since the check: paho has queued the message and
                # sends it after the reconnect, but its MQTTMessageInfo would report the
                # failure for ever; wait for the PUBACK of that queued copy instead
                info.rc = mqtt.MQTT_ERR_SUCCESS
            elif info.rc != mqtt.MQTT_ERR_SUCCESS:
                raise ConnectionError(f"MQTT publish of event {event.id}: rc {info.rc}")
            self._pending[event.id] = info
        info.wait_for_publish(self._timeout)  # type: ignore[attr-defined]
        if not info.is_published():  # type: ignore[attr-defined]
            raise TimeoutError(f"MQTT broker did not acknowledge event {event.id}")
        del self._pending[event.id]


class MqttSink:
    """Publishes each event with QoS 1 to `[prefix/]topic` and waits for the broker's PUBACK.

    A prefix lets several cells share one broker (`plant/cell7/fmscell/job/...`). The cell's
    own MQTT face (server/mqtt.py) publishes events under its topic tree instead.
    """

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = 1883,
        *,
        prefix: str = "",
        timeout_s: float = 5.0,
        client_id: str = "",
    ) -> None:
        import paho.mqtt.client as mqtt

        self._client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=client_id)
        self._prefix = prefix.rstrip("/")
        self._publish = AckedPublish(self._client, timeout_s)
        up = threading.Event()
        self._client.on_connect = lambda *_: up.set()
        self._client.connect(host, port, keepalive=30)
        self._client.loop_start()
        up.wait(timeout_s)  # events before the CONNACK would only be refused and retried

    def __call__(self, event: Event) -> None:
        topic = f"{self._prefix}/{event.topic}" if self._prefix else event.topic
        self._publish(event, topic)

    def close(self) -> None:
        self._client.loop_stop()
        self._client.disconnect()
