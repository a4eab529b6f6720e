"""The MTConnect router over HTTP (FastAPI TestClient), including a live adapter."""

from __future__ import annotations

import asyncio
import time

import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient

from cnc.faces.loop_thread import LoopThread
from cnc.faces.shdr import ShdrAdapter
from cnc.status import AxisStatus, MachineStatus
from mtconnect import AdapterConnection
from tests.server.test_mtconnect_e2e import wait_for
from tests.server.test_mtconnect_support import error_code, header, parse, small_agent, values
from web_api.mtconnect import mtconnect_router, stream_parts


@pytest.fixture
def agent():
    return small_agent()


@pytest.fixture
def client(agent):
    app = FastAPI()
    app.include_router(mtconnect_router(agent), prefix="/mtconnect")
    with TestClient(app) as c:
        yield c


@pytest.mark.parametrize(
    ("url", "kind"),
    [
        ("/mtconnect/probe", "Devices"),
        ("/mtconnect/m1/probe", "Devices"),
        ("/mtconnect/current", "Streams"),
        ("/mtconnect/m2/current?path=//Linear", "Streams"),
        ("/mtconnect/sample", "Streams"),
        ("/mtconnect/m1/sample?from=1&count=5", "Streams"),
        ("/mtconnect/sample?to=10&from=2&heartbeat=500", "Streams"),
    ],
)
def test_documents(client, url, kind):
    r = client.get(url)
    assert r.status_code == 200, r.text
    assert r.headers["content-type"].startswith("application/xml")
    parse(kind, r.text)


def test_sample_paging_by_next_sequence(client, agent):
    for i in range(30):
        agent.ingest_line("m1", f"2026-11-21T06:00:00Z|line|{i}")
    got, nxt = [], 1
    while True:
        r = client.get(f"/mtconnect/m1/sample?from={nxt}&count=7&path=//DataItem[@name='line']")
        root = parse("Streams", r.text)
        v = values(root).get("m1_line", [])
        if not v:
            break
        got += v
        nxt = int(header(root)["nextSequence"])
    assert got == ["UNAVAILABLE"] + [str(i) for i in range(30)]


@pytest.mark.parametrize(
    ("url", "status", "code"),
    [
        ("/mtconnect/sample?from=0", 400, "OUT_OF_RANGE"),
        ("/mtconnect/sample?count=0", 400, "OUT_OF_RANGE"),
        ("/mtconnect/current?at=999999", 400, "OUT_OF_RANGE"),
        ("/mtconnect/sample?count=many", 400, "INVALID_REQUEST"),
        ("/mtconnect/nope/current", 404, "NO_DEVICE"),
        ("/mtconnect/current?path=//Bogus", 400, "INVALID_PATH"),
        ("/mtconnect/current?path=//Foo[", 400, "INVALID_PATH"),
        ("/mtconnect/m1/sample?path=//Foo[@name=", 400, "INVALID_PATH"),
        ("/mtconnect/m1/assets/x", 404, "INVALID_URI"),
        ("/mtconnect/sample?interval=-5", 400, "OUT_OF_RANGE"),
        ("/mtconnect/sample?interval=10&heartbeat=0", 400, "OUT_OF_RANGE"),
        ("/mtconnect/current?interval=0", 400, "OUT_OF_RANGE"),
        ("/mtconnect/nope/sample?interval=10", 404, "NO_DEVICE"),
        ("/mtconnect/sample?interval=10&path=//Bogus", 400, "INVALID_PATH"),
    ],
)
def test_error_documents(client, url, status, code):
    r = client.get(url)
    assert r.status_code == status
    assert r.headers["content-type"].startswith("application/xml")
    assert error_code(r.text)[0] == code


def test_openapi_lists_the_routes(client):
    paths = client.get("/openapi.json").json()["paths"]
    for p in ("probe", "current", "sample"):
        assert f"/mtconnect/{p}" in paths and f"/mtconnect/{{device}}/{p}" in paths


def test_http_shows_a_live_machine():
    agent = small_agent()
    machine, agent_loop = LoopThread("m").start(), LoopThread("a").start()
    adapter = ShdrAdapter(("X", "Y", "Z"), heartbeat_ms=200)
    machine.run(adapter.start)
    conn = AdapterConnection(
        agent, "m1", "127.0.0.1", adapter.bound_port, reconnect_interval_s=0.05
    )

    async def go():
        conn.start()

    agent_loop.run(go)
    app = FastAPI()
    app.include_router(mtconnect_router(agent))
    try:
        adapter.publish(
            MachineStatus(execution="ACTIVE", axes={"X": AxisStatus(-1.0, -1.0)}),
            "2026-11-21T06:00:00.000000Z",
        )
        with TestClient(app) as c:
            wait_for(lambda: ">ACTIVE<" in c.get("/m1/current?path=//DataItem[@name='exec']").text)
            v = values(parse("Streams", c.get("/m1/current").text))
            assert v["m1_exec"] == ["ACTIVE"] and v["m1_Xact"] == ["-1.0000"]
            assert v["m1_avail"] == ["AVAILABLE"] and "m2_exec" not in v
    finally:
        agent_loop.run(conn.stop)
        machine.run(adapter.stop)
        agent_loop.stop()
        machine.stop()


# --- streaming (interval) ---------------------------------------------------------------------


class FakeTime:
    """Clock and sleep for the stream generator: sleeping advances the clock."""

    def __init__(self) -> None:
        self.t = 0.0
        self.hook = None

    def clock(self) -> float:
        return self.t

    async def sleep(self, seconds: float) -> None:
        self.t += seconds
        if self.hook:
            self.hook()


def _body(part_bytes: bytes) -> str:
    head, _, rest = part_bytes.partition(b"\r\n\r\n")
    assert head.startswith(b"--b\r\nContent-type: application/xml\r\nContent-length: ")
    length = int(head.rsplit(b" ", 1)[1])
    assert rest[length:] == b"\r\n"
    return rest[:length].decode()


def test_stream_sample_sends_new_data_and_heartbeats():
    agent = small_agent()
    plan = agent.stream_plan(
        "sample", "m1", {"interval": "10", "heartbeat": "100", "path": "//DataItem[@name='line']"}
    )
    ft = FakeTime()

    async def run():
        gen = stream_parts(agent, plan, "b", sleep=ft.sleep, clock=ft.clock)
        first = _body(await anext(gen))  # at once: nothing new yet
        assert values(parse("Streams", first)) == {}
        agent.ingest_line("m1", "2026-11-21T06:00:00Z|line|5")
        second = _body(await anext(gen))
        assert values(parse("Streams", second)) == {"m1_line": ["5"]}
        t_before = ft.t
        third = _body(await anext(gen))  # nothing new: an empty heartbeat part
        assert values(parse("Streams", third)) == {}
        assert ft.t - t_before >= 0.1
        ft.hook = lambda: agent.ingest_line("m1", f"2026-11-21T06:00:01Z|line|{int(ft.t * 1000)}")
        fourth = values(parse("Streams", _body(await anext(gen))))
        assert len(fourth["m1_line"]) == 1
        await gen.aclose()

    asyncio.run(run())


def test_stream_ends_with_out_of_range_when_the_buffer_overtakes_the_client():
    agent = small_agent(buffer_size=128)
    plan = agent.stream_plan("sample", None, {"interval": "10", "from": "1", "count": "5"})
    ft = FakeTime()

    async def run():
        gen = stream_parts(agent, plan, "b", sleep=ft.sleep, clock=ft.clock)
        _body(await anext(gen))
        for i in range(300):  # the client falls 300 observations behind a 128-slot buffer
            agent.ingest_line("m1", f"2026-11-21T06:00:00Z|line|{i}")
        last = _body(await anext(gen))
        assert error_code(last)[0] == "OUT_OF_RANGE"
        with pytest.raises(StopAsyncIteration):
            await anext(gen)

    asyncio.run(run())


def test_stream_current_repeats_every_interval():
    agent = small_agent()
    plan = agent.stream_plan("current", "m2", {"interval": "50"})
    ft = FakeTime()

    async def run():
        gen = stream_parts(agent, plan, "b", sleep=ft.sleep, clock=ft.clock)
        a = values(parse("Streams", _body(await anext(gen))))
        agent.ingest_line("m2", "2026-11-21T06:00:00Z|exec|ACTIVE")
        b = values(parse("Streams", _body(await anext(gen))))
        assert a["m2_exec"] == ["UNAVAILABLE"] and b["m2_exec"] == ["ACTIVE"]
        assert ft.t == pytest.approx(0.05)
        await gen.aclose()

    asyncio.run(run())


def test_streaming_over_real_http():
    """multipart/mixed parts as a real client sees them, from uvicorn on a loopback port."""
    import threading

    import httpx
    import uvicorn

    agent = small_agent()
    app = FastAPI()
    app.include_router(mtconnect_router(agent))
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=0, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    try:
        wait_for(lambda: server.started)
        port = server.servers[0].sockets[0].getsockname()[1]
        start = agent.buffer.next_sequence
        url = f"http://127.0.0.1:{port}/m1/sample?interval=20&heartbeat=200&from={start}"
        with httpx.stream("GET", url, timeout=5.0) as r:
            ctype = r.headers["content-type"]
            assert ctype.startswith("multipart/mixed;boundary=")
            boundary = ctype.split("=", 1)[1].encode()
            buf = b""
            agent.ingest_line("m1", "2026-11-21T06:00:00Z|exec|ACTIVE")
            deadline = time.monotonic() + 5.0
            for chunk in r.iter_bytes():
                buf += chunk
                if buf.count(b"--" + boundary) >= 2 and b"ACTIVE" in buf:
                    break
                assert time.monotonic() < deadline, buf[-500:]
        parts = [p for p in buf.split(b"--" + boundary) if p.strip()]
        bodies = [p.partition(b"\r\n\r\n")[2].rstrip(b"\r\n").decode() for p in parts]
        for body in bodies:
            if body.endswith("</MTConnectStreams>"):
                parse("Streams", body)
        assert any(">ACTIVE<" in b for b in bodies)
    finally:
        server.should_exit = True
        thread.join(5)
