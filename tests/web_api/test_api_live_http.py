# ruff: noqa: F811 - pytest fixtures are imported by name from test_api_common
"""The API on a real uvicorn server on 127.0.0.1: uploads over a socket, and an SSE client
that drops the connection and resumes with Last-Event-ID, as a browser's EventSource does."""

from __future__ import annotations

import json
import logging
import socket
import threading
import time
from datetime import UTC, datetime

import httpx
import pytest
import uvicorn

from dnc.db import transaction
from dnc.events import record
from tests.web_api.test_api_common import (  # noqa: F401 - fixtures
    GOOD,
    KEYS,
    SQLITE_ONLY,
    engine,
    make_api,
    pg_url,
    sessions,
    sqlite_template,
)

pytestmark = [SQLITE_ONLY, pytest.mark.timeout(60)]


@pytest.fixture
def live(sessions):
    api = make_api(sessions, events_keepalive_s=0)
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind(("127.0.0.1", 0))
    sock.listen(64)  # clients may connect before uvicorn accepts: no start-up wait needed
    config = uvicorn.Config(
        api.client.app, log_level="warning", lifespan="off", timeout_graceful_shutdown=5
    )
    server = uvicorn.Server(config)
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
    thread.start()
    base = f"http://127.0.0.1:{sock.getsockname()[1]}"
    with httpx.Client(base_url=base, headers={"X-API-Key": KEYS["admin"]}, timeout=20) as c:
        yield api, c
    server.should_exit = True
    thread.join(timeout=20)
    sock.close()
    assert not thread.is_alive(), "uvicorn did not shut down"


def sse_events(lines, count):
    got, current = [], {}
    for line in lines:
        if line == "":
            if "data" in current:
                got.append(current)
                if len(got) == count:
                    return got
            current = {}
        elif not line.startswith(":"):
            field, _, value = line.partition(":")
            current[field] = value.lstrip(" ")
    raise AssertionError(f"stream ended after {len(got)} of {count} events")


def test_event_stream_survives_a_dropped_connection(live):
    api, c = live
    assert c.post("/api/programs", json={"number": 1, "name": "a", "text": GOOD}).status_code == 201
    with c.stream("GET", "/api/events") as r:
        assert r.status_code == 200
        lines = r.iter_lines()
        seen = sse_events(lines, 4)  # 3 machine registrations, then the upload's first event
        # The connection drops here (the client closes it mid-stream).
    last = seen[-1]["id"]
    r = c.post("/api/programs", json={"number": 2, "name": "b", "text": GOOD})
    assert r.status_code == 201
    with c.stream("GET", "/api/events", headers={"Last-Event-ID": last}) as r:
        resumed = sse_events(r.iter_lines(), 3)
    ids = [int(e["id"]) for e in resumed]
    assert ids == [int(last) + 1, int(last) + 2, int(last) + 3]
    actions = [json.loads(e["data"])["action"] for e in resumed]
    assert actions == ["program.create", "revision.create", "program.create"]


def test_problem_over_the_wire(live):
    _, c = live
    r = c.post("/api/programs", content=b"{", headers={"content-type": "application/json"})
    assert r.status_code == 400
    assert r.headers["content-type"] == "application/problem+json"
    assert r.json()["type"] == "https://fmscell.dev/problems/malformed-json"


class Records(logging.Handler):
    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)


def test_clients_dropping_mid_stream_are_released_without_an_error_logged(live):
    """Dropping while a backlog is being written used to log BrokenResourceError (FastAPI's
    per-connection SSE tasks); the subscription must also be given back to the hub."""
    api, c = live
    with transaction(api.sessions) as s:
        for n in range(1500):
            record(
                s,
                now=datetime.now(UTC),
                actor="t",
                action="machine.status",
                entity="machine",
                entity_id=None,
                machine=f"m{n % 50}",
                pad="x" * 200,
            )
    errors = Records()
    logging.getLogger("uvicorn.error").addHandler(errors)
    try:
        for _ in range(3):
            with c.stream("GET", "/api/events?after=0") as r:
                sse_events(r.iter_lines(), 10)  # then drop with most of the backlog unsent
        hub = api.client.app.state.event_hub
        deadline = time.monotonic() + 20
        while hub.subscribers and time.monotonic() < deadline:
            time.sleep(0.02)
        assert hub.subscribers == 0, "a dropped client's subscription was not released"
        assert c.get("/api/health").status_code == 200
    finally:
        logging.getLogger("uvicorn.error").removeHandler(errors)
    assert [r.getMessage() for r in errors.records] == []


@pytest.mark.parametrize("fanout", ["hub", "poll"])
def test_closing_the_hub_ends_open_streams_so_the_server_can_stop(sessions, fanout):
    """uvicorn waits for open responses before the lifespan's shutdown: a watching
    dashboard kept the server from stopping until the hub learnt to end its streams."""
    api = make_api(sessions, events_fanout=fanout)
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.bind(("127.0.0.1", 0))
    sock.listen(64)
    server = uvicorn.Server(uvicorn.Config(api.client.app, log_level="warning"))
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
    thread.start()
    base = f"http://127.0.0.1:{sock.getsockname()[1]}"
    try:
        with httpx.Client(base_url=base, headers={"X-API-Key": KEYS["viewer"]}, timeout=20) as c:
            with c.stream("GET", "/api/events") as r:
                lines = r.iter_lines()
                assert next(lines) == ": fmscell events"
                api.client.app.state.event_hub.close(wait=False)  # as on SIGTERM
                list(lines)  # returns: the server ended the stream
            after = c.get("/api/events")
            assert after.status_code == 503
            assert after.json()["type"].endswith("/shutting-down")
        server.should_exit = True
        thread.join(timeout=20)
        assert not thread.is_alive(), "uvicorn still waits for a stream"
    finally:
        server.should_exit = True
        thread.join(timeout=20)
        sock.close()
