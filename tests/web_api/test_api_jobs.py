# ruff: noqa: F811 - pytest fixtures are imported by name from test_api_common
"""Jobs over HTTP: create, list with cursors, detail with allocations and decisions, cancel."""

from __future__ import annotations

from dnc.checker import nc_checker
from dnc.jobs import Scheduler
from dnc.scheduler import MachineView
from tests.web_api.test_api_common import (  # noqa: F401 - fixtures
    SQLITE_ONLY,
    api,
    assert_problem,
    engine,
    make_api,
    pg_url,
    sessions,
    sqlite_template,
)


def new_job(api, rev, **over):
    r = api.post("/api/jobs", role="operator", json={"revision_id": rev, "quantity": 4, **over})
    assert r.status_code == 201, r.text
    return r.json()


def test_job_created_then_allocated_by_the_scheduler(api):
    rev = api.released()
    job = new_job(api, rev, due_at="2026-11-21T16:00:00Z", priority=5, cycle_time_s=90)
    assert (job["status"], job["quantity"], job["done"], job["machine_kind"]) == (
        "queued",
        4,
        0,
        "mill",
    )
    assert job["due_at"].startswith("2026-11-21T16:00:00")
    idle = [MachineView("mill-1", "mill", "idle", 0), MachineView("mill-2", "mill", "idle", 0)]
    Scheduler(api.sessions, lambda: idle).tick()
    detail = api.get(f"/api/jobs/{job['id']}").json()
    assert detail["status"] == "running"
    assert sorted(a["machine"] for a in detail["allocations"]) == ["mill-1", "mill-2"]
    assert all(a["dispatch_id"] for a in detail["allocations"])
    assert [d["action"] for d in detail["decisions"]] == ["allocate", "allocate"]
    assert all(d["rule"] == "fifo" and d["reason"] for d in detail["decisions"])
    dispatch = api.get(f"/api/dispatches/{detail['allocations'][0]['dispatch_id']}").json()
    assert dispatch["requested_by"] == "scheduler"


def test_cancel_then_cancel_again(api):
    job = new_job(api, api.released())
    r = api.post(f"/api/jobs/{job['id']}/cancel", role="operator")
    assert r.status_code == 200 and r.json()["status"] == "cancelled"
    r = api.post(f"/api/jobs/{job['id']}/cancel", role="operator")
    assert "already cancelled" in assert_problem(r, 409, "workflow")["detail"]
    assert_problem(api.post("/api/jobs/999/cancel", role="operator"), 404, "not-found")
    assert_problem(api.get("/api/jobs/999"), 404, "not-found")


def test_list_with_cursor_and_status(api):
    rev = api.released()
    ids = [new_job(api, rev)["id"] for _ in range(5)]
    api.post(f"/api/jobs/{ids[2]}/cancel", role="operator")
    seen, url = [], "/api/jobs?limit=2"
    while url:
        r = api.get(url)
        seen += [j["id"] for j in r.json()["items"]]
        link = r.headers.get("link")
        url = link[1 : link.index(">")] if link else None
    assert seen == ids
    cancelled = api.get("/api/jobs?status=cancelled").json()["items"]
    assert [j["id"] for j in cancelled] == [ids[2]]


def test_job_refusals(api):
    draft = api.upload(9)["revision"]["id"]
    r = api.post("/api/jobs", role="operator", json={"revision_id": draft, "quantity": 1})
    assert "jobs need a released revision" in assert_problem(r, 409, "workflow")["detail"]
    r = api.post("/api/jobs", role="operator", json={"revision_id": 5555, "quantity": 1})
    assert_problem(r, 404, "not-found")
    assert api.get("/api/jobs").json()["items"] == []


@SQLITE_ONLY
def test_job_request_shape_problems(api):
    rev = api.released()
    cases = [
        ({"revision_id": rev, "quantity": 0}, "#/quantity"),
        ({"revision_id": rev, "quantity": 1, "due_at": "2026-11-21T16:00:00"}, "#/due_at"),
        ({"revision_id": rev, "quantity": 1, "cycle_time_s": -1}, "#/cycle_time_s"),
        ({"revision_id": rev, "quantity": 1, "priority": 10**12}, "#/priority"),
        ({"quantity": 1}, "#/revision_id"),
    ]
    for body, pointer in cases:
        r = api.post("/api/jobs", role="operator", json=body)
        assert assert_problem(r, 422, "validation")["errors"][0]["pointer"] == pointer, body
    assert api.get("/api/jobs").json()["items"] == []


ROTARY = "%\nO1040 (TURN A)\nG0 X0 Y0 Z20 A0\nG1 X20 A90 F600\nM30\n%\n"


def test_a_job_whose_program_no_machine_can_run_is_refused_and_one_that_can_waits_for_it(
    sessions,
):
    api = make_api(sessions, checker=nc_checker)
    with api.client:
        for name in ("mill-1", "mill-2"):  # the cell's mills are mill3s: X Y Z
            api.library.register_machine(name, "mill", axes=("X", "Y", "Z"))
        rev = api.released(1040, ROTARY)
        assert api.get(f"/api/revisions/{rev}").json()["axes"] == ["X", "Y", "Z", "A"]
        assert api.get("/api/machines/mill-1").json()["axes"] == ["X", "Y", "Z"]
        r = api.post("/api/jobs", role="operator", json={"revision_id": rev, "quantity": 2})
        body = assert_problem(r, 422, "no-machine-can-run")
        assert body["pointer"] == "#/revision_id"
        assert body["needs"] == {"kinds": ["mill"], "axes": ["X", "Y", "Z", "A"]}
        assert body["machines"]["mill-1"] == "mill-1 has axes X Y Z; the program needs A"
        assert body["machines"]["lathe-1"].startswith("lathe-1 is a lathe;")
        assert api.get("/api/jobs").json()["items"] == []
        # a mill4 joins the cell: the job is queued, and only the mill4 gets its parts
        api.library.register_machine("mill-4", "mill", axes=("X", "Y", "Z", "A"))
        job = new_job(api, rev, quantity=2)
        assert job["needs"] == {"kinds": ["mill"], "axes": ["X", "Y", "Z", "A"]}
        views = [
            MachineView("mill-1", "mill", "idle", 0, axes=("X", "Y", "Z")),
            MachineView("mill-4", "mill", "idle", 0, axes=("X", "Y", "Z", "A")),
        ]
        Scheduler(api.sessions, lambda: views).tick()
        detail = api.get(f"/api/jobs/{job['id']}").json()
        assert [a["machine"] for a in detail["allocations"]] == ["mill-4"]
