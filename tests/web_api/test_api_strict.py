# ruff: noqa: F811 - pytest fixtures are imported by name from test_api_common
"""Strict request types and complete 405 answers (issue 14, item 12).

`"number": true` had been stored as program 1 and `"revision_id": "1"` accepted; a 405
listed only `POST` on paths that also take `GET`.
"""

from __future__ import annotations

import pytest
from sqlalchemy import func, select

from dnc import models as m
from dnc.db import transaction
from tests.web_api.test_api_common import (  # noqa: F401 - fixtures
    GOOD,
    SQLITE_ONLY,
    api,
    assert_problem,
    engine,
    pg_url,
    sessions,
    sqlite_template,
)


def count(api, model) -> int:
    with transaction(api.sessions) as s:
        return s.scalar(select(func.count()).select_from(model))


@SQLITE_ONLY
@pytest.mark.parametrize(
    ("change", "pointer", "says"),
    [
        ({"number": True}, "#/number", "valid integer"),
        ({"number": False}, "#/number", "valid integer"),
        ({"number": "1001"}, "#/number", "valid integer"),
        ({"number": 1001.0}, "#/number", "valid integer"),
        ({"name": 5}, "#/name", "valid string"),
        ({"text": ["G0 X1"]}, "#/text", "valid string"),
        ({"tags": "a,b"}, "#/tags", "valid array"),
        ({"description": None}, "#/description", "valid string"),
    ],
)
def test_program_upload_takes_no_coerced_values(api, change, pointer, says):
    body = {"number": 1001, "name": "x", "text": GOOD, **change}
    r = api.post("/api/programs", role="programmer", json=body)
    problem = assert_problem(r, 422, "validation")
    assert problem["errors"][0]["pointer"] == pointer
    assert says in problem["errors"][0]["detail"]
    assert count(api, m.Program) == 0


@SQLITE_ONLY
def test_revision_upload_takes_no_coerced_text(api):
    prog = api.upload()["program"]["id"]
    r = api.post(f"/api/programs/{prog}/revisions", role="programmer", json={"text": 1})
    assert assert_problem(r, 422, "validation")["errors"][0]["pointer"] == "#/text"


@SQLITE_ONLY
def test_form_upload_still_reads_its_text_fields(api):
    """A multipart form carries text only: its number field "1002" is the number 1002."""
    r = api.post(
        "/api/programs",
        role="programmer",
        data={"number": "1002", "name": "form"},
        files={"file": ("p.nc", GOOD.encode())},
    )
    assert r.status_code == 201, r.text
    assert r.json()["program"]["number"] == 1002


@SQLITE_ONLY
@pytest.mark.parametrize(
    ("change", "pointer"),
    [
        ({"revision_id": "REV"}, "#/revision_id"),  # filled in below
        ({"revision_id": True}, "#/revision_id"),
        ({"start": 1}, "#/start"),
        ({"start": "true"}, "#/start"),
        ({"machine": 1}, "#/machine"),
    ],
)
def test_dispatch_takes_no_coerced_values(api, change, pointer):
    rev = api.released()
    change = {k: (str(rev) if v == "REV" else v) for k, v in change.items()}
    body = {"revision_id": rev, "machine": "mill-1", **change}
    r = api.post("/api/dispatches", role="operator", json=body, headers={"Idempotency-Key": "k1"})
    assert assert_problem(r, 422, "validation")["errors"][0]["pointer"] == pointer
    assert count(api, m.Dispatch) == 0


@SQLITE_ONLY
@pytest.mark.parametrize(
    ("change", "pointer"),
    [
        ({"revision_id": "REV"}, "#/revision_id"),
        ({"quantity": "4"}, "#/quantity"),
        ({"quantity": True}, "#/quantity"),
        ({"priority": 1.5}, "#/priority"),
        ({"cycle_time_s": True}, "#/cycle_time_s"),
        ({"cycle_time_s": "60"}, "#/cycle_time_s"),
        ({"due_at": 1700000000}, "#/due_at"),
        ({"due_at": "2026-12-01T08:00:00"}, "#/due_at"),  # no offset: which time zone?
    ],
)
def test_job_takes_no_coerced_values(api, change, pointer):
    rev = api.released()
    change = {k: (str(rev) if v == "REV" else v) for k, v in change.items()}
    body = {"revision_id": rev, "quantity": 4, **change}
    r = api.post("/api/jobs", role="operator", json=body)
    assert assert_problem(r, 422, "validation")["errors"][0]["pointer"] == pointer
    assert count(api, m.Job) == 0


@SQLITE_ONLY
def test_job_still_takes_an_integer_cycle_time_and_a_datetime_string(api):
    rev = api.released()
    body = {"revision_id": rev, "quantity": 2, "cycle_time_s": 45, "due_at": "2026-12-01T08:00:00Z"}
    r = api.post("/api/jobs", role="operator", json=body)
    assert r.status_code == 201, r.text
    assert r.json()["cycle_time_s"] == 45.0


@SQLITE_ONLY
@pytest.mark.parametrize(
    ("method", "url", "allowed"),
    [
        ("PUT", "/api/programs", "GET, POST"),
        ("DELETE", "/api/programs", "GET, POST"),
        ("PATCH", "/api/jobs", "GET, POST"),
        ("PUT", "/api/dispatches", "GET, POST"),
        ("POST", "/api/health", "GET"),
    ],
)
def test_405_allow_lists_every_method_of_the_path(api, method, url, allowed):
    r = api.client.request(method, url, headers=api.h("admin"))
    body = assert_problem(r, 405, "method-not-allowed")
    assert r.headers["allow"] == allowed
    assert body["detail"].endswith(f"allowed: {allowed}")
