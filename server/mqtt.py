"""The cell's MQTT face: live machine state as retained topics, the outbox's events, and the
cell's birth and death, for a factory of cells sharing one broker (docs/mqtt.md).

    <prefix>/<cell>/status                 retained: ONLINE at connect, OFFLINE (last will)
    <prefix>/<cell>/<machine>/<item>       retained, QoS 0: the item's last value (`_items`)
    <prefix>/<cell>/events/<entity>/<verb> the outbox's events, QoS 1, not retained

The state comes from the monitoring model (SHDR -> MTConnect agent), as the REST API and
the scheduler see it: a machine whose stream is lost turns UNAVAILABLE here too. paho's
network thread reconnects with exponential backoff; at every connect the face publishes
its birth and every retained value again (a restarted broker may have lost them), and the
outbox publisher sends the events the broker has not acknowledged.
"""

from __future__ import annotations

import json
import logging
import os
import threading
import time
import uuid
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from datetime import UTC, datetime

from server.host import CONDITIONS, MonitoringModel

log = logging.getLogger(__name__)

# A machine item is a last value, republished whole at every connect. At QoS 1, a copy the
# broker had not acknowledged when the connection dropped is sent again by paho after the
# connect's newer values and, retained, overwrites them with the stale one (seen: a program
# O0001 back on the broker after O0005). At QoS 0 nothing is sent again; the republish at
# connect is what makes the last value arrive.
ITEM_QOS = 0

RECONNECT_MIN_S, RECONNECT_MAX_S = 1, 30
# topic levels under the cell that are not machines
RESERVED = frozenset({"status", "events"})


@dataclass(frozen=True, slots=True)
class MqttSettings:
    host: str
    port: int
    prefix: str = "fmscell"
    cell_id: str = "cell"
    period_s: float = 0.1
    position_period_s: float = 1.0
    keepalive_s: int = 10


def parse_broker(text: str, where: str = "broker") -> tuple[str, int]:
    """`HOST:PORT` (PORT alone means 127.0.0.1) -> (host, port), or a ValueError saying why."""
    host, sep, port = text.strip().rpartition(":")
    if not sep:
        host, port = "", text.strip()
    if not port.isdigit() or not 0 < int(port) < 65536:
        raise ValueError(f"{where}: {text!r} is not HOST:PORT (port 1..65535)")
    return host or "127.0.0.1", int(port)


def mqtt_settings(host_config, environ: Mapping[str, str] = os.environ) -> MqttSettings | None:
    """The face's settings: the cell file's `host.mqtt`, with FMSCELL_MQTT=HOST:PORT naming
    the broker (and turning the face on with the defaults when the file has no section)."""
    section = host_config.mqtt
    target = environ.get("FMSCELL_MQTT", "").strip()
    if section is None and not target:
        return None
    host, port = parse_broker(
        target or section.broker, "FMSCELL_MQTT" if target else "host.mqtt.broker"
    )
    if section is None:
        return MqttSettings(host, port)
    return MqttSettings(
        host,
        port,
        prefix=section.prefix,
        cell_id=section.cell_id,
        period_s=section.period_s,
        position_period_s=section.position_period_s,
        keepalive_s=section.keepalive_s,
    )


def utc_now() -> str:
    return datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%S.%fZ")


def _items(axes: str) -> dict[str, tuple[tuple[str, ...], Callable[[dict], object]]]:
    """Each published item: the agent's data items it is made of (for its timestamp and
    sequence) and its value from the monitoring model's status."""
    conditions = (*CONDITIONS, *(f"{ax}servo" for ax in axes))
    return {
        "availability": (("avail",), lambda s: s["availability"]),
        "emergency_stop": (("estop",), lambda s: s["emergency_stop"]),
        "execution": (("exec",), lambda s: s["execution"]),
        "mode": (("mode",), lambda s: s["mode"]),
        "program": (("program",), lambda s: s["program"]),
        "line": (("line",), lambda s: s["line"]),
        "part_count": (("part_count",), lambda s: s["counters"]["part_count"]),
        "alarms": (conditions, lambda s: s["alarms"]),
        "state": (("avail", "exec", "mode", "estop", *conditions), MonitoringModel._state),
        "position": (tuple(f"{ax}act" for ax in axes), lambda s: s["actual"]),
    }


class CellFace:
    """Publishes one cell's machines and events to a broker; see the module docstring.

    `monitor` is the cell's MonitoringModel (its `agent` gives timestamps and sequences);
    `publish_event` is the outbox publisher's sink."""

    def __init__(self, settings: MqttSettings, monitor: MonitoringModel) -> None:
        import paho.mqtt.client as mqtt

        # deferred: SQLAlchemy; `fmscell --help` loads this module (server.factory)
        from dnc.outbox import AckedPublish

        clash = RESERVED & set(monitor.links)
        if clash:
            raise ValueError(
                f"host.mqtt: machine {sorted(clash)[0]!r} would share its topic with the cell's own"
            )
        self.settings, self.monitor = settings, monitor
        self.root = f"{settings.prefix}/{settings.cell_id}"
        self.status_topic = f"{self.root}/status"
        self._items = {n: _items(link.axes) for n, link in monitor.links.items()}
        self._lock = threading.Lock()
        self._retained: dict[str, str] = {}  # topic -> last payload, republished at connect
        self._values: dict[str, object] = {}  # topic -> last value (changes are published)
        self._position_at: dict[str, float] = {}
        self.connected = threading.Event()
        self.published = 0  # state messages handed to the broker (bench, tests)
        self.connects = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        client_id = f"fmscell-{settings.cell_id}-{uuid.uuid4().hex[:8]}"
        self.client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=client_id)
        self.client.will_set(self.status_topic, self._status("OFFLINE", "connection lost"), 1, True)
        self.client.reconnect_delay_set(RECONNECT_MIN_S, RECONNECT_MAX_S)
        self.client.on_connect = self._on_connect
        self.client.on_disconnect = lambda *_: self.connected.clear()
        self._acked = AckedPublish(self.client)

    # ------------------------------------------------------------------ lifetime
    def start(self) -> CellFace:
        """Connect in the background (a broker that is down now is retried with backoff)
        and start reading the live state."""
        self.client.connect_async(
            self.settings.host, self.settings.port, keepalive=self.settings.keepalive_s
        )
        self.client.loop_start()
        self._thread = threading.Thread(target=self._run, name="mqtt-face", daemon=True)
        self._thread.start()
        return self

    def stop(self, timeout_s: float = 2.0) -> None:
        """Say OFFLINE (a clean disconnect sends no last will) and disconnect."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout_s + self.settings.period_s)
        if self.client.is_connected():
            info = self.client.publish(
                self.status_topic, self._status("OFFLINE", "stopped"), 1, True
            )
            info.wait_for_publish(timeout_s)
        self.client.disconnect()
        self.client.loop_stop()

    def _on_connect(self, client, userdata, flags, reason, properties) -> None:
        if reason.is_failure:
            log.warning(
                "MQTT broker %s:%s refused the cell: %s",
                self.settings.host,
                self.settings.port,
                reason,
            )
            return
        self.connects += 1
        client.publish(self.status_topic, self._status("ONLINE", "connected"), 1, True)
        # under the lock, so that a value the reader publishes is never followed by an
        # older copy of it from here
        with self._lock:
            for topic, payload in self._retained.items():
                client.publish(topic, payload, ITEM_QOS, True)
            self.published += len(self._retained)
            self.connected.set()

    def _status(self, status: str, reason: str) -> str:
        return json.dumps(
            {
                "cell": self.settings.cell_id,
                "status": status,
                "reason": reason,
                "timestamp": utc_now(),
                "machines": list(self.monitor.links),
            },
            separators=(",", ":"),
        )

    # ------------------------------------------------------------------ live state
    def _run(self) -> None:
        while not self._stop.is_set():
            t0 = time.monotonic()
            try:
                self.publish_changes()
            except Exception:  # noqa: BLE001 - the face outlives one bad reading
                log.exception("MQTT face: reading the live state failed")
            self._stop.wait(max(0.0, self.settings.period_s - (time.monotonic() - t0)))

    def publish_changes(self, now: float | None = None) -> int:
        """Publish every item whose value changed since it was last published (positions at
        most every `position_period_s`); returns how many were published. While the broker
        is away only the retained copies are updated: the next connect sends them."""
        now = time.monotonic() if now is None else now
        sent = 0
        for name, items in self._items.items():
            status = self.monitor.status(name)
            for item, (keys, value_of) in items.items():
                topic = f"{self.root}/{name}/{item}"
                value = value_of(status)
                if self._values.get(topic, object()) == value:
                    continue
                if item == "position":
                    if now - self._position_at.get(name, -1e9) < self.settings.position_period_s:
                        continue
                    self._position_at[name] = now
                self._values[topic] = value
                payload = self._payload(name, item, keys, value)
                with self._lock:
                    self._retained[topic] = payload
                    if self.connected.is_set():
                        self.client.publish(topic, payload, ITEM_QOS, True)
                        self.published += 1
                        sent += 1
        return sent

    def _payload(self, machine: str, item: str, keys: tuple[str, ...], value: object) -> str:
        """MTConnect-style: the value with the newest timestamp and sequence of the data items
        it comes from (the agent's, wall-clock UTC in a running cell)."""
        agent = self.monitor.agent
        newest = None
        for key in keys:
            got = agent.latest(machine, key)
            for obs in got if isinstance(got, tuple) else (got,):
                if obs is not None and (newest is None or obs.sequence > newest.sequence):
                    newest = obs
        body = {
            "cell": self.settings.cell_id,
            "machine": machine,
            "item": item,
            "value": value,
            "timestamp": newest.timestamp if newest is not None else utc_now(),
            "sequence": newest.sequence if newest is not None else 0,
        }
        if len(keys) == 1:
            body["dataItemId"] = agent.device(machine).by_key[keys[0]].id
        return json.dumps(body, separators=(",", ":"))

    # ------------------------------------------------------------------ events
    def event_topic(self, topic: str) -> str:
        """An outbox topic (`fmscell/job/create`) under this cell: `<root>/events/job/create`."""
        return f"{self.root}/events/{topic.removeprefix('fmscell/')}"

    def publish_event(self, event) -> None:
        """The outbox publisher's sink: QoS 1, returns once the broker acknowledged it."""
        self._acked(event, self.event_topic(event.topic))
