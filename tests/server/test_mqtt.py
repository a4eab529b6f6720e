"""The cell's MQTT face against the real Mosquitto broker: retained values, birth and last
will, replay of the outbox after a broker restart, and the factory view of two cells."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import uuid
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cnc.config import ConfigError
from server.config import load_cell_config
from server.mqtt import CellFace, MqttSettings, mqtt_settings, parse_broker
from tests.server.mqtt_support import (
    SHARED_BROKER,
    PrivateBroker,
    Subscriber,
    broker_answers,
    clear_retained,
    live_state,
)

HOST, PORT = SHARED_BROKER
needs_broker = pytest.mark.skipif(
    not broker_answers(), reason="no MQTT broker answers on 127.0.0.1:1883 (.ci/run starts one)"
)
ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def prefix():
    """A topic prefix of this test's own (other runs may share the broker); its retained
    topics are removed afterwards."""
    p = f"test-{uuid.uuid4().hex[:12]}"
    yield p
    if broker_answers():
        clear_retained(HOST, PORT, p)


def _settings(prefix: str, cell: str = "cell1", port: int = PORT) -> MqttSettings:
    return MqttSettings(HOST, port, prefix=prefix, cell_id=cell, period_s=0.05)


# ---------------------------------------------------------------------- configuration
def test_the_cell_file_turns_the_face_on_and_fmscell_mqtt_names_the_broker():
    machines = {"m1": {"base": "mill3"}}
    off = load_cell_config({"machines": machines})
    assert mqtt_settings(off.host, {}) is None
    on = load_cell_config(
        {"machines": machines, "host": {"mqtt": {"broker": "broker.local:1884", "cell_id": "c7"}}}
    )
    s = mqtt_settings(on.host, {})
    assert (s.host, s.port, s.prefix, s.cell_id) == ("broker.local", 1884, "fmscell", "c7")
    s = mqtt_settings(on.host, {"FMSCELL_MQTT": "127.0.0.1:1999"})
    assert (s.host, s.port, s.cell_id) == ("127.0.0.1", 1999, "c7")
    s = mqtt_settings(off.host, {"FMSCELL_MQTT": "10.0.0.9:1883"})
    assert (s.host, s.port, s.prefix, s.cell_id) == ("10.0.0.9", 1883, "fmscell", "cell")


@pytest.mark.parametrize(
    ("mqtt", "where"),
    [
        ({"broker": "localhost"}, "host.mqtt.broker"),
        ({"broker": "localhost:70000"}, "host.mqtt.broker"),
        ({"broker": "h:1", "prefix": "plant/#"}, "host.mqtt.prefix"),
        ({"broker": "h:1", "cell_id": "a/b"}, "host.mqtt.cell_id"),
        ({"broker": "h:1", "period_s": 0}, "host.mqtt.period_s"),
        ({"brokr": "h:1"}, "host.mqtt"),
    ],
)
def test_a_bad_mqtt_section_is_refused_with_its_key(mqtt, where):
    with pytest.raises(ConfigError) as err:
        load_cell_config({"machines": {"m1": {"base": "mill3"}}, "host": {"mqtt": mqtt}})
    assert where in str(err.value)


def test_a_bad_broker_address_says_where():
    with pytest.raises(ValueError, match="FMSCELL_MQTT: 'h:x' is not HOST:PORT"):
        parse_broker("h:x", "FMSCELL_MQTT")
    assert parse_broker("1884") == ("127.0.0.1", 1884)


def test_a_machine_named_like_a_cell_topic_is_refused():
    with pytest.raises(ValueError, match="machine 'status'"):
        CellFace(_settings("p"), live_state(("status",)))


# ---------------------------------------------------------------------- on the broker
@needs_broker
def test_machine_items_are_retained_with_mtconnect_timestamps(prefix):
    monitor = live_state(("mill1", "lathe1"))
    face = CellFace(_settings(prefix), monitor).start()
    try:
        assert face.connected.wait(10)
        monitor.agent.observe("mill1", "exec", "ACTIVE")
        monitor.agent.observe("mill1", "program", "O1234")
        root = f"{prefix}/cell1/mill1"
        early = Subscriber(HOST, PORT, [f"{root}/state"])
        try:
            early.wait_for(lambda ms: ms and ms[-1][1]["value"] == "busy", what="mill1 busy")
        finally:
            early.close()
        # a subscriber that comes later gets every last value from the broker (retained)
        late = Subscriber(HOST, PORT, [f"{prefix}/#"])
        try:
            late.wait_for(
                lambda ms: (
                    (late.last(f"{root}/program") or {}).get("value") == "O1234"
                    and late.last(f"{prefix}/cell1/lathe1/position")
                ),
                what="mill1's program and lathe1's position",
            )
            status = late.last(f"{prefix}/cell1/status")
            assert status["status"] == "ONLINE" and status["machines"] == ["mill1", "lathe1"]
            ex = late.last(f"{root}/execution")
            assert ex["value"] == "ACTIVE" and ex["dataItemId"] == "mill1_exec"
            assert ex["timestamp"].endswith("Z") and ex["sequence"] > 0
            assert late.last(f"{prefix}/cell1/lathe1/mode")["value"] == "AUTOMATIC"
            assert late.last(f"{root}/state")["value"] == "busy"
            assert all(r for t, _, r in late.messages if t.startswith(root))
            assert {"X", "Y", "Z"} <= set(late.last(f"{root}/position")["value"])

            # a change is published once, live; a machine whose stream is lost is UNAVAILABLE
            before = len(late.messages)
            monitor.agent.observe("mill1", "line", "42")
            late.wait_for(lambda ms: late.last(f"{root}/line")["value"] == 42, what="line 42")
            monitor.agent.disconnected("mill1")
            late.wait_for(
                lambda ms: (
                    late.last(f"{root}/availability")["value"] == "UNAVAILABLE"
                    and late.last(f"{root}/state")["value"] == "offline"
                ),
                what="UNAVAILABLE",
            )
            lines = [b["value"] for t, b, _ in late.messages[before:] if t == f"{root}/line"]
            assert lines[0] == 42 and lines.count(42) == 1
        finally:
            late.close()
    finally:
        face.stop()


@needs_broker
def test_alarms_are_one_retained_list_per_machine(prefix):
    monitor = live_state(("mill1",))
    face = CellFace(_settings(prefix), monitor).start()
    sub = Subscriber(HOST, PORT, [f"{prefix}/cell1/mill1/alarms"])
    try:
        assert face.connected.wait(10)
        monitor.agent.ingest_line(
            "mill1", "2026-01-01T00:00:00Z|plc_cond|FAULT|2001||HIGH|Door open"
        )
        topic = f"{prefix}/cell1/mill1/alarms"
        sub.wait_for(lambda ms: (sub.last(topic) or {}).get("value"), what="an alarm")
        (alarm,) = sub.last(topic)["value"]
        assert (alarm["code"], alarm["level"], alarm["text"]) == ("2001", "FAULT", "Door open")
        monitor.agent.ingest_line("mill1", "2026-01-01T00:00:01Z|plc_cond|NORMAL||||")
        sub.wait_for(lambda ms: sub.last(topic)["value"] == [], what="the alarm cleared")
    finally:
        sub.close()
        face.stop()


PUBLISHER = textwrap.dedent(
    """
    import sys, time
    sys.path.insert(0, {root!r})
    from server.mqtt import CellFace, MqttSettings
    from tests.server.mqtt_support import live_state
    face = CellFace(MqttSettings("127.0.0.1", {port}, prefix={prefix!r}, cell_id="doomed",
                                 keepalive_s=5), live_state(("mill1",))).start()
    face.connected.wait(10)
    print("online", flush=True)
    time.sleep(120)
    """
)


@needs_broker
def test_a_killed_cell_is_declared_offline_by_its_last_will(prefix):
    status = f"{prefix}/doomed/status"
    sub = Subscriber(HOST, PORT, [status])
    proc = subprocess.Popen(
        [sys.executable, "-c", PUBLISHER.format(root=str(ROOT), port=PORT, prefix=prefix)],
        stdout=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    try:
        assert proc.stdout.readline().strip() == "online"
        sub.wait_for(lambda ms: any(b and b["status"] == "ONLINE" for _, b, _ in ms), what="birth")
        proc.kill()  # SIGKILL: no DISCONNECT, the broker sees the socket close
        proc.wait(10)
        sub.wait_for(
            lambda ms: ms[-1][1] and ms[-1][1]["status"] == "OFFLINE", 20, what="the last will"
        )
        assert sub.messages[-1][1]["reason"] == "connection lost"
    finally:
        if proc.poll() is None:
            proc.kill()
        sub.close()
    # and it stays: a newcomer reads OFFLINE (retained)
    late = Subscriber(HOST, PORT, [status])
    try:
        late.wait_for(lambda ms: ms and ms[-1][1]["status"] == "OFFLINE", what="retained death")
        assert late.messages[-1][2]
    finally:
        late.close()


@needs_broker
def test_a_stopped_cell_says_offline_itself(prefix):
    face = CellFace(_settings(prefix), live_state(("mill1",))).start()
    assert face.connected.wait(10)
    face.stop()
    sub = Subscriber(HOST, PORT, [f"{prefix}/cell1/status"])
    try:
        sub.wait_for(lambda ms: ms and ms[-1][1]["status"] == "OFFLINE", what="OFFLINE")
        assert sub.messages[-1][1]["reason"] == "stopped"
    finally:
        sub.close()


@pytest.mark.skipif(not PrivateBroker.available(), reason="mosquitto is not installed")
def test_events_survive_a_broker_restart_at_least_once_and_machine_items_come_back(tmp_path):
    """The outbox's events across a broker restart: none lost, in order, delivered at least
    once (docs/mqtt.md); a copy the broker passes on twice is the same event, byte for
    byte, so a consumer drops it by event_id. The machines' retained items are back after
    the restart, with the value they took while the broker was away."""
    from dnc.db import make_engine, migrate, session_factory
    from dnc.library import Library
    from dnc.outbox import OutboxPublisher

    broker = PrivateBroker(tmp_path)
    broker.start()
    engine = make_engine(f"sqlite:///{tmp_path / 'cell.db'}")
    migrate(engine)
    sessions = session_factory(engine)
    library = Library(sessions)
    prog = "%\nO{n}\nG0 X0\nM30\n%\n"
    monitor = live_state(("mill1",))
    face = CellFace(
        MqttSettings("127.0.0.1", broker.port, prefix="plant", cell_id="c1", period_s=0.05),
        monitor,
    ).start()
    # a consumer with a persistent session: the broker keeps its QoS 1 messages across
    # the restart and its own disconnection
    sub = Subscriber(
        "127.0.0.1", broker.port, ["plant/c1/events/#"], client_id="consumer", clean=False
    )
    publisher = OutboxPublisher(sessions, face.publish_event)

    def outbox_ids():
        from sqlalchemy import select

        from dnc import models as m

        with sessions() as s:
            rows = s.execute(select(m.OutboxEvent.id, m.OutboxEvent.published_at)).all()
        return [r[0] for r in rows], [r[0] for r in rows if r[1] is None]

    def received():
        return [b["event_id"] for _, b, _ in sub.messages]

    try:
        assert face.connected.wait(10) and sub.subscribed.wait(10)
        monitor.agent.observe("mill1", "exec", "ACTIVE")
        monitor.agent.observe("mill1", "program", "O0001")
        for n in (1, 2, 3):
            library.create_program(number=n, name=f"p{n}", text=prog.format(n=n))
        assert publisher.publish_pending() == 6
        sub.wait_for(lambda ms: len(ms) == 6, what="6 events")

        broker.stop()
        face.connected.clear()  # paho notices the loss on its own thread; do not race it
        for n in (4, 5):
            library.create_program(number=n, name=f"p{n}", text=prog.format(n=n))
        monitor.agent.observe("mill1", "program", "O0005")  # while the broker is away
        assert publisher.publish_pending() == 0  # refused while the broker is away
        assert len(outbox_ids()[1]) == 4

        sub.subscribed.clear()
        broker.start()
        assert face.connected.wait(30), broker.log()  # reconnect with backoff
        assert sub.subscribed.wait(30)  # the consumer is back before the replay
        deadline = 30.0
        import time

        end = time.monotonic() + deadline
        while outbox_ids()[1] and time.monotonic() < end:
            publisher.publish_pending()
            time.sleep(0.1)
        all_ids, unpublished = outbox_ids()
        assert unpublished == []
        sub.wait_for(lambda ms: len(ms) >= len(all_ids), 30, what="the replayed events")
        # at least once (docs/mqtt.md): an event the broker took just before it stopped, whose
        # PUBACK was lost with it, is sent again (seen once at load 30). A copy is the same
        # event: same topic, same payload, so the consumer's de-duplication by event_id
        # loses nothing. In order of first receipt, none lost:
        first: dict[int, tuple] = {}
        for topic, body, _ in sub.messages:
            copy = first.setdefault(body["event_id"], (topic, body))
            assert (topic, body) == copy, f"event {body['event_id']} differs in its copies"
        assert list(first) == all_ids
        assert sorted(set(received())) == all_ids
        assert face.connects == 2
        assert [t for t, _, _ in sub.messages][:2] == [
            "plant/c1/events/revision/create",
            "plant/c1/events/program/create",
        ]
        # the machine's retained items are back: a newcomer after the restart reads them,
        # the program as it became while the broker was away (the birth republishes them)
        late = Subscriber("127.0.0.1", broker.port, ["plant/c1/#"])
        try:
            late.wait_for(
                lambda ms: (late.last("plant/c1/mill1/program") or {}).get("value") == "O0005",
                30,
                what="mill1's retained program after the restart",
            )
            assert late.last("plant/c1/mill1/execution")["value"] == "ACTIVE"
            assert late.last("plant/c1/status")["status"] == "ONLINE"
            retained = {t for t, _, r in late.messages if r}
            assert {"plant/c1/mill1/program", "plant/c1/mill1/execution"} <= retained
        finally:
            late.close()
    finally:
        sub.close()
        face.stop()
        broker.stop()
        engine.dispose()


@needs_broker
def test_the_factory_view_lists_two_cells_sharing_a_broker(prefix):
    from server.cli import app
    from server.factory import FactoryView

    a = CellFace(_settings(prefix, "cell1"), live_state(("mill1", "lathe1"))).start()
    b_state = live_state(("mill7",))
    b = CellFace(_settings(prefix, "cell2"), b_state).start()
    try:
        assert a.connected.wait(10) and b.connected.wait(10)
        b_state.agent.observe("mill7", "exec", "ACTIVE")
        seen = Subscriber(HOST, PORT, [f"{prefix}/cell2/mill7/execution"])
        try:
            seen.wait_for(lambda ms: ms and ms[-1][1]["value"] == "ACTIVE", what="mill7 ACTIVE")
        finally:
            seen.close()
        # what a newcomer hears: the retained values, straight after subscribing
        cells = FactoryView(HOST, PORT, prefix).collect(1.0)
        assert cells["cell1"]["status"] == cells["cell2"]["status"] == "ONLINE"
        assert set(cells["cell1"]["machines"]) == {"mill1", "lathe1"}
        assert cells["cell2"]["machines"]["mill7"]["execution"] == "ACTIVE"
        assert cells["cell1"]["machines"]["mill1"]["state"] == "idle"

        got = CliRunner().invoke(
            app,
            ["factory", "--mqtt", f"{HOST}:{PORT}", "--prefix", prefix, "--seconds", "1", "--json"],
        )
        assert got.exit_code == 0, got.output
        doc = json.loads(got.output)
        assert set(doc["cells"]) == {"cell1", "cell2"}
        text = (
            CliRunner()
            .invoke(
                app, ["factory", "--mqtt", f"{HOST}:{PORT}", "--prefix", prefix, "--seconds", "1"]
            )
            .output
        )
        assert "cell2" in text and "mill7" in text and "ACTIVE" in text
    finally:
        a.stop()
        b.stop()
    # the stopped cells' machines read UNAVAILABLE from their last retained values
    cells = FactoryView(HOST, PORT, prefix).collect(1.0)
    assert cells["cell1"]["status"] == "OFFLINE"
    assert cells["cell1"]["machines"]["mill1"]["availability"] == "UNAVAILABLE"


def test_the_factory_view_says_when_no_broker_answers():
    from server.cli import app
    from tests.server.mqtt_support import free_port

    got = CliRunner().invoke(app, ["factory", "--mqtt", f"127.0.0.1:{free_port()}"])
    assert got.exit_code == 2 and "fmscell factory: MQTT broker 127.0.0.1:" in got.output
    got = CliRunner().invoke(app, ["factory", "--mqtt", "nowhere"])
    assert got.exit_code == 2 and "--mqtt: 'nowhere' is not HOST:PORT" in got.output


def test_the_factory_view_reports_messages_it_cannot_read():
    from server.factory import FactoryView

    view = FactoryView("127.0.0.1", 1, "plant")
    view.hear("plant/c1/status", b'{"status":"ONLINE","machines":["m1"]}')
    view.hear("plant/c1/m1/execution", b"ACTIVE")  # not JSON
    view.hear("plant/c1/m1/mode", b'["AUTOMATIC"]')  # not an object
    view.hear("plant/c1/m1/line", b"")  # a cleared retained topic: nothing
    view.hear("plant/c1/events/job", b'{"value": 1}')  # not a machine
    assert view.snapshot() == {
        "c1": {"status": "ONLINE", "since": None, "machines": {"m1": {}}},
    }
    assert view.errors == [
        "plant/c1/m1/execution: payload is not JSON",
        "plant/c1/m1/mode: payload is not a JSON object",
    ]


@pytest.mark.skipif(not PrivateBroker.available(), reason="mosquitto is not installed")
def test_a_cell_started_before_its_broker_connects_when_the_broker_comes(tmp_path):
    broker = PrivateBroker(tmp_path)  # its port chosen, nothing listening yet
    monitor = live_state(("mill1",))
    face = CellFace(_settings("plant", port=broker.port), monitor).start()  # does not raise
    try:
        assert not face.connected.wait(0.3)
        monitor.agent.observe("mill1", "exec", "ACTIVE")  # kept for the birth
        broker.start()
        assert face.connected.wait(30), broker.log()  # retried with backoff
        sub = Subscriber(HOST, broker.port, ["plant/cell1/#"])
        try:
            sub.wait_for(
                lambda ms: (
                    (sub.last("plant/cell1/mill1/execution") or {}).get("value") == "ACTIVE"
                    and (sub.last("plant/cell1/status") or {}).get("status") == "ONLINE"
                ),
                what="the birth and the state kept while the broker was away",
            )
        finally:
            sub.close()
    finally:
        face.stop()
        broker.stop()
