# ruff: noqa: F811 - pytest fixtures are imported by name from test_api_common
"""The machine registry with optional live status, and health."""

from __future__ import annotations

from dnc.db import make_engine, session_factory
from dnc.dispatch import Dispatches
from dnc.jobs import Jobs
from dnc.library import Library
from tests.web_api.test_api_common import (  # noqa: F401 - fixtures
    SQLITE_ONLY,
    api,
    assert_problem,
    engine,
    make_api,
    pg_url,
    sessions,
    settings,
    sqlite_template,
)
from web_api.app import create_app


def test_registry_without_live_status(api):
    machines = api.get("/api/machines").json()
    assert [m["name"] for m in machines] == ["lathe-1", "mill-1", "mill-2"]
    assert machines[1]["kind"] == "mill" and machines[1]["memory_bytes"] == 64 * 1024
    assert all(m["status"] is None for m in machines)
    assert api.get("/api/machines/mill-2").json()["name"] == "mill-2"
    r = api.get("/api/machines/mill-9")
    assert "unknown machine 'mill-9'" in assert_problem(r, 404, "not-found")["detail"]


@SQLITE_ONLY
def test_live_status_from_the_cell_is_joined_by_name(sessions):
    calls = []

    def provider():
        calls.append(1)
        return {"mill-1": {"execution": "ACTIVE", "line": 12}}

    a = make_api(sessions, machines_provider=provider)
    with a.client:
        machines = {m["name"]: m for m in a.get("/api/machines").json()}
        assert machines["mill-1"]["status"] == {"execution": "ACTIVE", "line": 12}
        assert machines["mill-2"]["status"] is None
        assert a.get("/api/machines/mill-1").json()["status"]["line"] == 12
    assert len(calls) == 2


@SQLITE_ONLY
def test_each_machines_opcua_endpoint_beside_its_other_faces(sessions):
    a = make_api(sessions, opcua_addresses=lambda: {"mill-1": "opc.tcp://127.0.0.1:4841"})
    with a.client:
        machines = {m["name"]: m for m in a.get("/api/machines").json()}
        assert machines["mill-1"]["opcua_address"] == "opc.tcp://127.0.0.1:4841"
        assert machines["mill-2"]["opcua_address"] is None  # its OPC UA face is off
        one = a.get("/api/machines/mill-1").json()
        assert one["opcua_address"] == "opc.tcp://127.0.0.1:4841"


def test_health_ok(api):
    r = api.client.get("/api/health")
    assert r.json() == {
        "status": "ok",
        "database": "ok",
        "insecure_open": False,
        "faults_enabled": False,
    }


def test_database_down_is_a_503_problem_everywhere(tmp_path):
    eng = make_engine(f"sqlite:///{tmp_path / 'missing' / 'dir' / 'x.db'}")
    s = session_factory(eng)
    app = create_app(
        settings(), library=Library(s), dispatches=Dispatches(s), jobs=Jobs(s), sessions=s
    )
    from fastapi.testclient import TestClient

    with TestClient(app) as c:
        body = assert_problem(c.get("/api/health"), 503, "database-unavailable")
        assert "database unavailable" in body["detail"]
        assert_problem(
            c.get("/api/programs", headers={"X-API-Key": "viewer-key-0123456789abcdef"}),
            503,
            "database-unavailable",
        )
    eng.dispose()
