"""Agent fed by a real SHDR adapter over a real socket: ingest, heartbeats, disconnects."""

from __future__ import annotations

import asyncio
import time

import pytest

from cnc.faces.loop_thread import LoopThread
from cnc.faces.shdr import ShdrAdapter
from cnc.status import Alarm, AxisStatus, MachineStatus
from mtconnect import AdapterConnection, Agent, build_device
from tests.server.test_mtconnect_support import parse, values

HB_MS = 100
AXES = ("X", "Y", "Z")
TS = "2026-11-21T06:00:00.000000Z"


def wait_for(predicate, timeout: float = 5.0, step: float = 0.005) -> float:
    """Poll until predicate() is true; returns the time it took. Bounded, never a bare sleep."""
    start = time.monotonic()
    while time.monotonic() - start < timeout:
        if predicate():
            return time.monotonic() - start
        time.sleep(step)
    raise AssertionError("condition not reached within the bound")


@pytest.fixture
def machine_loop():
    loop = LoopThread("machine").start()
    yield loop
    loop.stop()


@pytest.fixture
def agent_loop():
    loop = LoopThread("agent").start()
    yield loop
    loop.stop()


@pytest.fixture
def agent():
    return Agent([build_device("mill1", AXES)])


def start_connection(loop: LoopThread, agent: Agent, port: int, **kw) -> AdapterConnection:
    conn = AdapterConnection(agent, "mill1", "127.0.0.1", port, reconnect_interval_s=0.05, **kw)

    async def go():
        conn.start()

    loop.run(go)
    return conn


def test_agent_ingests_from_a_real_adapter(machine_loop, agent_loop, agent):
    adapter = ShdrAdapter(AXES, heartbeat_ms=HB_MS)
    machine_loop.run(adapter.start)
    adapter.publish(MachineStatus(axes={a: AxisStatus() for a in AXES}), TS)
    conn = start_connection(agent_loop, agent, adapter.bound_port)
    try:
        wait_for(lambda: agent.value("mill1", "avail") == "AVAILABLE")
        wait_for(lambda: conn.heartbeat_ms == HB_MS)
        status = MachineStatus(
            execution="ACTIVE",
            program="O1000",
            line=17,
            path_feed_rate=1200.0,
            axes={"X": AxisStatus(-10.0, -10.002), "Y": AxisStatus(-5.0, -5.0), "Z": AxisStatus()},
            spindle_speed=3000.0,
            spindle_load=42.0,
            part_count=3,
            alarms=(Alarm(7003, "door open | feed hold", "PLC", "WARNING"),),
        )
        adapter.publish(status, "2026-11-21T06:00:01.000000Z")
        # One publish is several SHDR lines (values, then conditions): wait for the last.
        wait_for(lambda: agent.value("mill1", "part_count") == "3")
        wait_for(lambda: agent.value("mill1", "plc_cond") == "WARNING")
        _, text = agent.request("current", "mill1", {})
        v = values(parse("Streams", text))
        assert v["mill1_exec"] == ["ACTIVE"]
        assert v["mill1_program"] == ["O1000"]
        assert v["mill1_line"] == ["17"]
        assert v["mill1_path_feedrate"] == ["20.000"]
        assert v["mill1_Xact"] == ["-10.0000"] and v["mill1_Xcmd"] == ["-10.0020"]
        assert v["mill1_Cspeed"] == ["3000.0"] and v["mill1_Cload"] == ["42.0"]
        assert v["mill1_plc_cond"] == ["WARNING"]
        cond = agent.latest("mill1", "plc_cond")[0]
        assert (cond.native_code, cond.value) == ("7003", "door open | feed hold")
        assert cond.timestamp == "2026-11-21T06:00:01.000000Z"
        # the alarm resets: the condition goes back to NORMAL
        adapter.publish(
            MachineStatus(**{**_fields(status), "alarms": ()}), "2026-11-21T06:00:02.000000Z"
        )
        wait_for(lambda: agent.value("mill1", "plc_cond") == "NORMAL")
    finally:
        agent_loop.run(conn.stop)
        machine_loop.run(adapter.stop)


def test_adapter_stopped_makes_everything_unavailable_then_reconnect_restores(
    machine_loop, agent_loop, agent
):
    adapter = ShdrAdapter(AXES, heartbeat_ms=HB_MS)
    machine_loop.run(adapter.start)
    port = adapter.bound_port
    status = MachineStatus(execution="ACTIVE", axes={a: AxisStatus(1.0, 1.0) for a in AXES})
    adapter.publish(status, TS)
    conn = start_connection(agent_loop, agent, port)
    try:
        # the dump's last line is the last axis' condition: wait for all of it
        wait_for(lambda: agent.value("mill1", "Zservo") == "NORMAL")
        before = agent.buffer.next_sequence
        machine_loop.run(adapter.stop)
        wait_for(lambda: agent.value("mill1", "avail") == "UNAVAILABLE")
        wait_for(lambda: agent.value("mill1", "exec") == "UNAVAILABLE")
        assert agent.value("mill1", "Xservo") == "UNAVAILABLE"
        # exactly one UNAVAILABLE per item that was available
        after = agent.buffer.next_sequence
        items = [di for di in agent.devices[0].by_key.values() if "asset" not in di.name]
        assert after - before == len(items)
        # the machine comes back on the same port: values return, each once
        adapter2 = ShdrAdapter(AXES, heartbeat_ms=HB_MS, port=port)
        machine_loop.run(adapter2.start)
        adapter2.publish(status, "2026-11-21T06:00:05.000000Z")
        wait_for(lambda: agent.value("mill1", "exec") == "ACTIVE", timeout=10)
        wait_for(lambda: agent.value("mill1", "Zservo") == "NORMAL")
        _, text = agent.request(
            "sample", "mill1", {"from": str(after), "path": "//DataItem[@name='exec']"}
        )
        assert values(parse("Streams", text)) == {"mill1_exec": ["ACTIVE"]}
        assert conn.stats.connects == 2
        machine_loop.run(adapter2.stop)
    finally:
        agent_loop.run(conn.stop)


def test_silent_adapter_is_unavailable_within_two_heartbeats(machine_loop, agent_loop, agent):
    """An adapter that answers one PONG and then goes silent (hung machine, cable pulled
    without a FIN) must be dropped by the heartbeat supervision, not by TCP."""
    sent_pong = asyncio.Event()
    last_line_at: list[float] = []

    async def frozen(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        await reader.readline()  # the agent's first * PING
        writer.write(f"{TS}|avail|AVAILABLE|exec|ACTIVE\n* PONG {HB_MS}\n".encode())
        await writer.drain()
        last_line_at.append(time.monotonic())
        sent_pong.set()
        try:
            while await reader.readline():  # keep reading PINGs, never answer
                pass
        finally:
            writer.close()

    async def serve():
        return await asyncio.start_server(frozen, "127.0.0.1", 0)

    server = machine_loop.run(serve)
    port = server.sockets[0].getsockname()[1]
    conn = start_connection(agent_loop, agent, port, legacy_timeout_s=60.0)
    try:
        wait_for(lambda: agent.value("mill1", "exec") == "ACTIVE")
        wait_for(lambda: agent.value("mill1", "avail") == "UNAVAILABLE", timeout=5.0)
        elapsed = time.monotonic() - last_line_at[0]
        assert conn.stats.heartbeat_timeouts >= 1
        # two heartbeats, plus scheduling slack on a loaded 2-core machine
        assert elapsed < 2 * HB_MS / 1000 + 1.0, elapsed
        assert agent.value("mill1", "exec") == "UNAVAILABLE"
    finally:
        agent_loop.run(conn.stop)

        async def close():
            server.close()

        machine_loop.run(close)


def test_refused_connection_keeps_device_unavailable_and_retries(agent_loop, agent):
    import socket

    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    conn = start_connection(agent_loop, agent, port)
    try:
        wait_for(lambda: conn.stats.attempts >= 3)
        assert agent.value("mill1", "avail") == "UNAVAILABLE"
        assert conn.connected is False and conn.stats.connects == 0
    finally:
        agent_loop.run(conn.stop)


def test_unknown_device_refused_at_construction(agent):
    from mtconnect import RestError

    with pytest.raises(RestError):
        AdapterConnection(agent, "nope", "127.0.0.1", 1)


def _fields(s: MachineStatus) -> dict:
    return {name: getattr(s, name) for name in s.__dataclass_fields__}


def test_agent_connections_for_a_cell(machine_loop):
    """The cell server's shell: one agent, the default cell's machines, real adapters."""
    from mtconnect import AgentConnections
    from server.config import default_cell_config

    cell = default_cell_config()
    agent = Agent.from_cell(cell)
    adapters = {}
    for name, machine in cell.machines.items():
        adapters[name] = ShdrAdapter(list(machine.axes), heartbeat_ms=HB_MS)
        machine_loop.run(adapters[name].start)
        adapters[name].publish(MachineStatus(execution="ACTIVE", part_count=len(name)), TS)
    ports = {n: a.bound_port for n, a in adapters.items()}
    conns = AgentConnections.for_cell(agent, cell, ports=ports, reconnect_interval_s=0.05).start()
    try:
        for name in cell.machines:
            wait_for(lambda n=name: agent.value(n, "part_count") == str(len(n)))
            assert agent.value(name, "exec") == "ACTIVE"
        assert set(conns.connections) == set(cell.machines)
    finally:
        conns.stop()
        for a in adapters.values():
            machine_loop.run(a.stop)
    assert conns.connections == {}
