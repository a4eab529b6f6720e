# ruff: noqa: F811 - pytest fixtures are imported by name from test_api_common
"""Dispatches over HTTP: 202 then 200 replays, one dispatch per key, refusals."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

from sqlalchemy import func, select

from dnc import models as m
from dnc.db import transaction
from tests.web_api.test_api_common import (  # noqa: F401 - fixtures
    SQLITE_ONLY,
    api,
    assert_problem,
    engine,
    pg_url,
    sessions,
    sqlite_template,
)


def dispatch_count(api) -> int:
    with transaction(api.sessions) as s:
        return s.scalar(select(func.count()).select_from(m.Dispatch))


def send(api, body, key="key-1", role="operator"):
    return api.post("/api/dispatches", role=role, json=body, headers={"Idempotency-Key": key})


def test_dispatch_is_accepted_then_replayed_with_the_same_body(api):
    rev = api.released()
    body = {"revision_id": rev, "machine": "mill-1", "mode": "drip_feed", "start": True}
    first = send(api, body)
    assert first.status_code == 202, first.text
    d = first.json()
    assert first.headers["location"] == f"/api/dispatches/{d['id']}"
    assert (d["state"], d["mode"], d["start"], d["requested_by"]) == (
        "pending",
        "drip_feed",
        True,
        "operator-user",
    )
    assert (d["bytes_sent"], d["verified"], d["idempotency_key"]) == (0, None, "key-1")
    for _ in range(5):
        again = send(api, body)
        assert again.status_code == 200 and again.json() == d
        assert again.headers["idempotent-replayed"] == "true"
    assert dispatch_count(api) == 1
    assert api.get(f"/api/dispatches/{d['id']}").json() == d


def test_same_key_with_another_body_is_422_and_changes_nothing(api):
    rev = api.released()
    d = send(api, {"revision_id": rev, "machine": "mill-1"}).json()
    r = send(api, {"revision_id": rev, "machine": "mill-2"})
    body = assert_problem(r, 422, "idempotency-key-reuse")
    assert "already used for a different request" in body["detail"]
    assert body["dispatch_id"] == d["id"]
    assert dispatch_count(api) == 1
    assert api.get(f"/api/dispatches/{d['id']}").json()["machine"] == "mill-1"


def test_refusals_say_why(api):
    draft = api.upload(5)["revision"]["id"]
    r = send(api, {"revision_id": draft, "machine": "mill-1"}, key="a")
    assert (
        "only a released revision can be dispatched" in assert_problem(r, 409, "workflow")["detail"]
    )
    rev = api.released()
    r = send(api, {"revision_id": rev, "machine": "mill-9"}, key="b")
    assert "unknown machine 'mill-9'" in assert_problem(r, 404, "not-found")["detail"]
    r = send(api, {"revision_id": 999999, "machine": "mill-1"}, key="c")
    assert "no revision with id 999999" in assert_problem(r, 404, "not-found")["detail"]
    assert dispatch_count(api) == 0


@SQLITE_ONLY
def test_request_shape_problems(api):
    rev = api.released()
    r = api.post("/api/dispatches", role="operator", json={"revision_id": rev, "machine": "m"})
    body = assert_problem(r, 422, "validation")
    assert body["errors"][0] == {
        "detail": "Field required",
        "parameter": "Idempotency-Key",
        "location": "header",
    }
    r = send(api, {"revision_id": rev, "machine": "mill-1", "mode": "tape"})
    assert assert_problem(r, 422, "validation")["errors"][0]["pointer"] == "#/mode"
    r = send(api, {"revision_id": "one", "machine": "mill-1", "start": "maybe"})
    pointers = [e["pointer"] for e in assert_problem(r, 422, "validation")["errors"]]
    assert pointers == ["#/revision_id", "#/start"]
    r = send(api, {"revision_id": rev, "machine": "mill-1"}, key="k" * 129)
    assert_problem(r, 422, "validation")
    assert dispatch_count(api) == 0


def test_list_newest_first_with_cursor_and_filters(api):
    rev = api.released()
    ids = [
        send(api, {"revision_id": rev, "machine": f"mill-{1 + n % 2}"}, key=f"k{n}").json()["id"]
        for n in range(5)
    ]
    seen, url = [], "/api/dispatches?limit=2"
    while url:
        r = api.get(url)
        seen += [d["id"] for d in r.json()["items"]]
        link = r.headers.get("link")
        url = link[1 : link.index(">")] if link else None
    assert seen == ids[::-1]
    mill2 = api.get("/api/dispatches?machine=mill-2").json()["items"]
    assert [d["id"] for d in mill2] == [ids[3], ids[1]]
    assert api.get("/api/dispatches?state=done").json()["items"] == []
    assert_problem(api.get("/api/dispatches?cursor=bm9wZQ"), 400, "invalid-cursor")


def test_unknown_dispatch(api):
    assert_problem(api.get("/api/dispatches/77"), 404, "not-found")


def test_concurrent_requests_with_one_key_make_one_dispatch(api):
    rev = api.released()
    body = {"revision_id": rev, "machine": "mill-2", "start": True}
    with ThreadPoolExecutor(max_workers=8) as pool:
        results = list(pool.map(lambda _: send(api, body, key="race"), range(16)))
    statuses = sorted(r.status_code for r in results)
    assert statuses == [200] * 15 + [202], statuses
    assert len({r.json()["id"] for r in results}) == 1
    assert dispatch_count(api) == 1


def test_a_dispatch_being_started_is_shown(api):
    """The transfer worker's `starting` state (cycle start in progress) is part of the schema."""
    rev = api.released()
    body = {"revision_id": rev, "machine": "mill-1", "mode": "memory", "start": True}
    did = send(api, body, key="starting-1").json()["id"]
    with transaction(api.sessions) as s:
        s.get(m.Dispatch, did).state = "starting"
    one = api.get(f"/api/dispatches/{did}", role="operator")
    assert one.status_code == 200 and one.json()["state"] == "starting"
    listed = api.get("/api/dispatches?state=starting", role="operator").json()["items"]
    assert [d["id"] for d in listed] == [did]
