"""The MTConnect router over HTTP (FastAPI TestClient), including a live adapter."""

from __future__ import annotations

import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient

from cnc.faces.loop_thread import LoopThread
from cnc.faces.shdr import ShdrAdapter
from cnc.status import AxisStatus, MachineStatus
from server.mtconnect import AdapterConnection
from tests.server.test_mtconnect_e2e import wait_for
from tests.server.test_mtconnect_support import error_code, header, parse, small_agent, values
from web_api.mtconnect import mtconnect_router


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
        ("/mtconnect/sample?count=many", 400, "QUERY_ERROR"),
        ("/mtconnect/nope/current", 404, "NO_DEVICE"),
        ("/mtconnect/current?path=//Bogus", 400, "INVALID_XPATH"),
        ("/mtconnect/m1/assets/x", 404, "INVALID_URI"),
        ("/mtconnect/sample?interval=10", 400, "UNSUPPORTED"),
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
