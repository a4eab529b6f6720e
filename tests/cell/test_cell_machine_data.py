"""GET/PUT /api/machines/{name}/tools and /offsets over real HTTP, through the cell and the
machine's DNC port: read, write (audited), refused in cycle (409), bad values (422 with
the JSON pointer), and the next program uses what was written."""

from __future__ import annotations

import pytest

from tests.cell.conftest import idem, poll, sse_until, upload_released

pytestmark = pytest.mark.timeout(120)

STOPS = "%\nO1001 (STOP)\nG21 G90 G0 X0 Y0 Z50\nM0\nM30\n%\n"
TOOL7 = "%\nO1002 (T7)\nG21 G90 G54 G0 X0 Y0\nG43 H7 Z10\nM30\n%\n"


def status(api, name):
    return api("viewer").get(f"/api/machines/{name}").json()["status"]


def test_tools_and_offsets_read_written_and_used(make_cell):
    cell, api = make_cell()
    r = api("viewer").get("/api/machines/mill1/tools")
    assert r.status_code == 200, r.text
    assert r.json()["tools"]["1"]["radius"] == 5.0  # the shipped setup
    r = api("viewer").get("/api/machines/mill1/offsets")
    assert r.json()["work_offsets"]["G54"] == [-300.0, -200.0, -300.0]
    # a viewer may read, not write
    assert api("viewer").put("/api/machines/mill1/tools", json={"tools": {}}).status_code == 403
    op = api("operator")
    r = op.put("/api/machines/mill1/tools", json={"tools": {"7": {"length": -40.0}}})
    assert r.status_code == 200, r.text
    assert r.json()["tools"] == {"7": pytest.approx(r.json()["tools"]["7"])}
    r = op.put("/api/machines/mill1/offsets", json={"work_offsets": {"G54": [-250, -150, -200]}})
    assert r.status_code == 200, r.text
    assert r.json()["work_offsets"]["G54"] == [-250.0, -150.0, -200.0]
    assert r.json()["work_offsets"]["G55"] == [-450.0, -200.0, -300.0]  # not named: kept
    # the next program on the machine runs with them: G54 + G43 H7
    rev = upload_released(api, TOOL7, 1002)
    r = op.post(
        "/api/dispatches",
        json={"revision_id": rev, "machine": "mill1", "mode": "memory", "start": True},
        headers=idem(),
    )
    assert r.status_code == 202, r.text
    s = poll(lambda: (s := status(api, "mill1"))["counters"]["part_count"] == 1 and s, 40, "O1002")
    assert s["commanded"] == pytest.approx({"X": -250.0, "Y": -150.0, "Z": -230.0}, abs=1e-3)
    events = sse_until(api, lambda e: e.get("action") == "machine.offsets_written", 10)
    written = [e["action"] for e in events if e.get("action", "").endswith("_written")]
    assert written == ["machine.tools_written", "machine.offsets_written"]
    audit = [
        (a["action"], a["actor"])
        for a in cell.library.audit(entity="machine")
        if a["action"].endswith("_written")
    ]
    assert audit == [
        ("machine.tools_written", "operator"),
        ("machine.offsets_written", "operator"),
    ]


@pytest.mark.parametrize(
    "path,body,pointer",
    [
        ("tools", {"tools": {"1000": {"length": 1.0}}}, "#/tools/1000"),
        ("tools", {"tools": {"3": {"radius": "big"}}}, "#/tools/3/radius"),
        ("tools", {"tool": {}}, "#"),
        ("offsets", {"work_offsets": {"G60": [0, 0, 0]}}, "#/work_offsets/G60"),
        ("offsets", {"work_offsets": {"G54": [0, 0, 1e9]}}, "#/work_offsets/G54/2"),
    ],
)
def test_bad_bodies_are_422_with_the_json_pointer(make_cell, path, body, pointer):
    _, api = make_cell()
    before = api("viewer").get(f"/api/machines/mill1/{path}").json()
    r = api("operator").put(f"/api/machines/mill1/{path}", json=body)
    assert r.status_code == 422, r.text
    assert r.headers["content-type"].startswith("application/problem+json")
    assert r.json()["errors"][0]["pointer"] == pointer
    assert api("viewer").get(f"/api/machines/mill1/{path}").json() == before


def test_writes_are_refused_in_cycle_with_409(make_cell):
    cell, api = make_cell()
    op = api("operator")
    rev = upload_released(api, STOPS, 1001)
    r = op.post(
        "/api/dispatches",
        json={"revision_id": rev, "machine": "mill2", "mode": "memory", "start": True},
        headers=idem(),
    )
    assert r.status_code == 202, r.text
    poll(lambda: status(api, "mill2")["execution"] == "PROGRAM_STOPPED", 40, "stopped at M0")
    r = op.put("/api/machines/mill2/offsets", json={"work_offsets": {"G54": [0, 0, 0]}})
    assert r.status_code == 409, r.text
    assert r.headers["content-type"].startswith("application/problem+json")
    assert "PROGRAM_STOPPED" in r.json()["detail"]
    assert api("viewer").get("/api/machines/mill2/offsets").json()["work_offsets"]["G54"] == [
        -300.0,
        -200.0,
        -300.0,
    ]
    sse_until(api, lambda e: e.get("action") == "machine.offsets_refused", 10)
    refused = [a for a in cell.library.audit(entity="machine") if "refused" in a["action"]]
    assert [(a["action"], a["actor"]) for a in refused] == [("machine.offsets_refused", "operator")]
    assert api("viewer").get("/api/machines/nope/tools").status_code == 404
