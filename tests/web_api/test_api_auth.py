# ruff: noqa: F811 - pytest fixtures are imported by name from test_api_common
"""The auth matrix: each role against each class of endpoint, 401 and 403 as problems."""

from __future__ import annotations

import json

import pytest

from tests.web_api.test_api_common import (  # noqa: F401 - fixtures
    GOOD,
    KEYS,
    ROLES,
    SQLITE_ONLY,
    api,
    assert_problem,
    engine,
    make_api,
    pg_url,
    sessions,
    sqlite_template,
)

pytestmark = SQLITE_ONLY

# endpoint class -> (lowest role allowed, request maker given a released revision id)
CLASSES = {
    "read": ("viewer", lambda api, rev: ("GET", "/api/programs", {})),
    "read-events": ("viewer", lambda api, rev: ("GET", "/api/events?after=999999", {})),
    "upload": (
        "programmer",
        lambda api, rev: (
            "POST",
            "/api/programs",
            {"json": {"number": 4242, "name": "n", "text": GOOD}},
        ),
    ),
    "revise": (
        "programmer",
        lambda api, rev: ("POST", "/api/programs/1/revisions", {"json": {"text": GOOD + "\n"}}),
    ),
    "release": (
        "programmer",
        lambda api, rev: ("POST", f"/api/revisions/{rev}/release", {"json": {"comment": "c"}}),
    ),
    "dispatch": (
        "operator",
        lambda api, rev: (
            "POST",
            "/api/dispatches",
            {
                "json": {"revision_id": rev, "machine": "mill-1"},
                "headers": {"Idempotency-Key": "auth-matrix"},
            },
        ),
    ),
    "job": (
        "operator",
        lambda api, rev: ("POST", "/api/jobs", {"json": {"revision_id": rev, "quantity": 1}}),
    ),
}


def call(api, method, url, kw, headers):
    kw = dict(kw)
    headers = {**headers, **kw.pop("headers", {})}
    if url.startswith("/api/events"):
        with api.client.stream(method, url, headers=headers) as r:
            return r.status_code, r.headers, (r.read() if r.status_code >= 400 else b"")
    r = api.client.request(method, url, headers=headers, **kw)
    return r.status_code, r.headers, r.content


@pytest.fixture
def rev(api):
    api.released(1)
    # a fresh draft for the release class (admin uploads it)
    return api.upload(2)["revision"]["id"]


@pytest.mark.parametrize("cls", CLASSES)
@pytest.mark.parametrize("role", ROLES)
def test_role_against_endpoint_class(api, rev, role, cls):
    lowest, make = CLASSES[cls]
    if cls in ("dispatch", "job"):
        rev = 1  # the released one
    method, url, kw = make(api, rev)
    status, headers, content = call(api, method, url, kw, {"X-API-Key": KEYS[role]})
    if ROLES.index(role) >= ROLES.index(lowest):
        assert status < 400, (role, cls, status, content)
    else:
        assert status == 403, (role, cls, status)
        assert headers["content-type"].startswith("application/problem+json")
        body = json.loads(content)
        assert body["type"].endswith("/forbidden") and body["needed_role"] == lowest
        assert f"needs the {lowest} role" in body["detail"] and role in body["detail"]


@pytest.mark.parametrize("cls", CLASSES)
@pytest.mark.parametrize(
    "headers",
    [{}, {"X-API-Key": "no-such-key-000000"}, {"Authorization": "Bearer no-such-key-00000"}],
    ids=["none", "unknown-key", "unknown-bearer"],
)
def test_missing_or_unknown_key_is_401(api, rev, cls, headers):
    method, url, kw = CLASSES[cls][1](api, rev)
    status, hdrs, content = call(api, method, url, kw, headers)
    assert status == 401, (cls, status, content)
    assert hdrs["www-authenticate"] == 'Bearer realm="fmscell"'
    assert hdrs["content-type"].startswith("application/problem+json")


def test_bearer_token_and_whoami(api):
    r = api.client.get("/api/whoami", headers={"Authorization": f"Bearer {KEYS['operator']}"})
    assert r.json() == {"user": "operator-user", "role": "operator"}


def test_query_key_is_only_for_the_event_stream(api):
    r = api.client.get(f"/api/programs?api_key={KEYS['admin']}")
    assert_problem(r, 401, "unauthenticated")
    with api.client.stream("GET", f"/api/events?after=99999&api_key={KEYS['viewer']}") as r:
        assert r.status_code == 200


def test_health_and_docs_need_no_key(api):
    assert api.client.get("/api/health").status_code == 200
    assert api.client.get("/openapi.json").status_code == 200


def test_insecure_open_makes_everyone_an_anonymous_admin(sessions):
    a = make_api(sessions, insecure_open=True, api_keys=[])
    with a.client:
        assert a.client.get("/api/whoami").json() == {"user": "anonymous", "role": "admin"}
        r = a.client.post("/api/programs", json={"number": 1, "name": "n", "text": GOOD})
        assert r.status_code == 201 and r.json()["revision"]["author"] == "anonymous"
        assert a.client.get("/api/health").json()["insecure_open"] is True


def test_no_keys_configured_refuses_everyone(sessions):
    a = make_api(sessions, api_keys=[])
    with a.client:
        assert_problem(a.client.get("/api/programs"), 401, "unauthenticated")
