"""Outbox publication: ordered, at-least-once, and through a real MQTT broker when one answers."""

from __future__ import annotations

import socket
import threading
import uuid

import pytest

from dnc.outbox import MqttSink, OutboxPublisher, events_after

PROG = "%\nO1\nG0 X0\nM30\n%\n"


def test_events_are_delivered_in_order_and_marked(library, sessions):
    library.create_program(number=1, name="a", text=PROG)
    got = []
    pub = OutboxPublisher(sessions, got.append)
    assert pub.publish_pending() == 2
    assert [e.topic for e in got] == ["fmscell/revision/create", "fmscell/program/create"]
    assert pub.publish_pending() == 0


def test_a_failing_sink_keeps_the_event_for_the_next_attempt(library, sessions):
    library.create_program(number=1, name="a", text=PROG)
    delivered, fail = [], {"on": True}

    def flaky(event):
        if fail["on"] and event.topic.endswith("program/create"):
            raise ConnectionError("broker down")
        delivered.append(event.id)

    pub = OutboxPublisher(sessions, flaky)
    assert pub.publish_pending() == 1
    fail["on"] = False
    assert pub.publish_pending() == 1
    assert delivered == sorted(delivered) and len(delivered) == 2


def test_event_log_is_readable_after_an_id(library, sessions):
    library.create_program(number=1, name="a", text=PROG)
    library.create_program(number=2, name="b", text=PROG.replace("O1", "O2"))
    first = events_after(sessions, 0)
    assert [e.id for e in events_after(sessions, first[1].id)] == [e.id for e in first[2:]]
    assert '"event_id":1' in first[0].to_json()


def _broker_up() -> bool:
    try:
        socket.create_connection(("127.0.0.1", 1883), timeout=1).close()
        return True
    except OSError:
        return False


@pytest.mark.skipif(not _broker_up(), reason="no MQTT broker on 127.0.0.1:1883")
def test_events_reach_an_mqtt_subscriber(library, sessions):
    import paho.mqtt.client as mqtt

    prefix = f"test-{uuid.uuid4().hex}"  # other test runs may share the broker
    received, ready, done = [], threading.Event(), threading.Event()
    sub = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2)
    sub.on_connect = lambda c, u, f, rc, p: c.subscribe(f"{prefix}/#", qos=1)
    sub.on_subscribe = lambda *a: ready.set()

    def on_message(c, u, msg):
        received.append(msg.topic)
        if len(received) >= 2:
            done.set()

    sub.on_message = on_message
    sub.connect("127.0.0.1", 1883)
    sub.loop_start()
    try:
        assert ready.wait(5)
        library.create_program(number=1, name="a", text=PROG)
        sink = MqttSink(prefix=prefix)
        try:
            assert OutboxPublisher(sessions, sink).publish_pending() == 2
        finally:
            sink.close()
        assert done.wait(5)
        assert received == [f"{prefix}/fmscell/revision/create", f"{prefix}/fmscell/program/create"]
    finally:
        sub.loop_stop()
        sub.disconnect()


class _FakeClient:
    """A paho client whose connection drops between the check and the publish."""

    def __init__(self) -> None:
        import paho.mqtt.client as mqtt

        self.published: list[str] = []
        self.info = mqtt.MQTTMessageInfo(1)
        self.info.rc = mqtt.MQTT_ERR_NO_CONN  # what paho answers: queued, not sent

    def is_connected(self) -> bool:
        return True

    def publish(self, topic, payload, qos):
        self.published.append(topic)
        return self.info


def test_an_event_queued_by_paho_is_waited_for_not_published_twice():
    from datetime import UTC, datetime

    from dnc.outbox import AckedPublish, Event

    client = _FakeClient()
    acked = AckedPublish(client, timeout_s=0.05)
    event = Event(7, datetime.now(UTC), "fmscell/job/create", {})
    with pytest.raises(TimeoutError, match="event 7"):
        acked(event, "t")
    client.info._set_as_published()  # paho's PUBACK of its queued copy, after the reconnect
    acked(event, "t")
    assert client.published == ["t"]
