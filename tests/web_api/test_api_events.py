# ruff: noqa: F811 - pytest fixtures are imported by name from test_api_common
"""The event stream: SSE resumed with Last-Event-ID, keep-alive comments, the WebSocket."""

from __future__ import annotations

import json

import pytest
from starlette.websockets import WebSocketDisconnect

from dnc.outbox import events_after
from tests.web_api.test_api_common import (  # noqa: F401 - fixtures
    GOOD,
    KEYS,
    SQLITE_ONLY,
    api,
    assert_problem,
    engine,
    make_api,
    pg_url,
    sessions,
    sqlite_template,
)

pytestmark = pytest.mark.timeout(60)


def read_sse(lines, *, events: int = 0, until_comment: str | None = None):
    """Parse SSE lines until `events` events (or the comment) arrived: (events, comments)."""
    got, comments, current = [], [], {}
    for line in lines:
        if line.startswith(":"):
            comments.append(line[1:].strip())
            if until_comment and comments[-1] == until_comment:
                break
        elif line == "":
            if "data" in current:
                got.append(current)
                if events and len(got) >= events:
                    break
            current = {}
        else:
            field, _, value = line.partition(":")
            current[field] = value.lstrip(" ")
    return got, comments


def upload_three(api) -> int:
    """Three uploads (each writes revision.create and program.create) after the machine
    registrations; returns the id of the last event before them."""
    base = events_after(api.sessions, 0)[-1].id
    for n in (1, 2, 3):
        api.upload(n)
    return base


def test_sse_sends_the_outbox_in_order_and_resumes_after_last_event_id(api):
    base = upload_three(api)
    headers = api.h("viewer", **{"Last-Event-ID": str(base)})
    with api.client.stream("GET", "/api/events", headers=headers) as r:
        assert r.status_code == 200
        assert r.headers["content-type"].startswith("text/event-stream")
        first, comments = read_sse(r.iter_lines(), events=4)
    assert comments[0] == "fmscell events"
    ids = [int(e["id"]) for e in first]
    assert ids == sorted(ids) and len(set(ids)) == 4
    payloads = [json.loads(e["data"]) for e in first]
    assert [p["event_id"] for p in payloads] == ids
    assert [p["action"] for p in payloads[:2]] == ["revision.create", "program.create"]
    headers = api.h("viewer", **{"Last-Event-ID": str(ids[-1])})
    with api.client.stream("GET", "/api/events", headers=headers) as r:
        rest, _ = read_sse(r.iter_lines(), events=2)
    rest_ids = [int(e["id"]) for e in rest]
    assert rest_ids[0] > ids[-1] and rest_ids == sorted(rest_ids)
    assert json.loads(rest[-1]["data"])["action"] == "program.create"
    assert json.loads(rest[-1]["data"])["number"] == 3


def test_after_parameter_and_last_event_id_precedence(api):
    base = upload_three(api)
    headers = api.h("viewer", **{"Last-Event-ID": str(base + 3)})
    with api.client.stream("GET", f"/api/events?after={base}", headers=headers) as r:
        got, _ = read_sse(r.iter_lines(), events=1)
    assert int(got[0]["id"]) == base + 4
    with api.client.stream("GET", "/api/events?after=1", headers=api.h("viewer")) as r:
        got, _ = read_sse(r.iter_lines(), events=1)
    assert int(got[0]["id"]) == 2


def test_live_events_then_keep_alive_when_quiet(sessions):
    a = make_api(sessions, events_keepalive_s=0)
    with a.client, a.client.stream("GET", "/api/events", headers=a.h("viewer")) as r:
        lines = r.iter_lines()
        _, comments = read_sse(lines, until_comment="keep-alive")
        assert comments[-1] == "keep-alive"
        # A change made by a service while the stream is open arrives on it.
        a.library.create_program(number=7, name="live", text=GOOD)
        got, _ = read_sse(lines, events=2)
    assert [json.loads(e["data"])["action"] for e in got] == ["revision.create", "program.create"]


@SQLITE_ONLY
@pytest.mark.parametrize("value", ["abc", "-1", "1.5"])
def test_bad_last_event_id_is_a_400_problem(api, value):
    r = api.client.get("/api/events", headers=api.h("viewer", **{"Last-Event-ID": value}))
    assert value in assert_problem(r, 400, "invalid-last-event-id")["detail"]


def test_websocket_sends_the_same_events_and_resumes_with_after(api):
    base = upload_three(api)
    url = f"/api/events/ws?api_key={KEYS['viewer']}&after={base}"
    with api.client.websocket_connect(url) as ws:
        all_events = [ws.receive_json() for _ in range(6)]
    assert [e["event_id"] for e in all_events] == sorted(e["event_id"] for e in all_events)
    url = f"/api/events/ws?api_key={KEYS['viewer']}&after={all_events[3]['event_id']}"
    with api.client.websocket_connect(url) as ws:
        assert ws.receive_json() == all_events[4]
    with api.client.websocket_connect(
        f"/api/events/ws?after={all_events[4]['event_id']}", headers={"X-API-Key": KEYS["viewer"]}
    ) as ws:
        assert ws.receive_json() == all_events[5]


@SQLITE_ONLY
def test_websocket_refuses_a_missing_key_with_a_problem_and_1008(api):
    with api.client.websocket_connect("/api/events/ws") as ws:
        problem = ws.receive_json()
        assert problem["type"].endswith("/unauthenticated") and problem["status"] == 401
        with pytest.raises(WebSocketDisconnect) as exc:
            ws.receive_json()
    assert exc.value.code == 1008
