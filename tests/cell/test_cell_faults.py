"""Fault injection over HTTP: a drive fault in one mill stops its part, the part is rerouted
to the other mill, and the alarm shows in the API, the event stream and MTConnect."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import pytest

from tests.cell.conftest import KEYS, poll, sse_until, upload_released

pytestmark = pytest.mark.timeout(120)

# M0 stops every part halfway (execution PROGRAM_STOPPED) until cycle start: the fault
# lands mid-part however fast the clock runs.
STOPPING_PROGRAM = """%
O1002 (E2E PART WITH A PROGRAM STOP)
N10 G21 G90 G17
N20 G0 X-40 Y-30 Z-10
N30 G1 Z-50 F6000
N40 G1 X-120 Y-80
N45 M0
N50 G1 X-40 Y-30
N60 G0 Z-20
N70 M30
%
"""


def status(api, name):
    return api("viewer").get(f"/api/machines/{name}").json()["status"]


def test_fault_in_one_mill_reroutes_its_part_and_the_alarm_is_visible_everywhere(make_cell):
    _, api = make_cell(faults=True)
    types = api("viewer").get("/api/fault-types").json()
    assert {"overcurrent", "encoder_break", "air_pressure_loss"} <= {t["type"] for t in types}
    # every drive fault kind comes from drives.fault_registry, the newest row included
    noise = next(t for t in types if t["type"] == "encoder_noise")
    assert noise["target"] == "drive:<AXIS>" and noise["emcy"] == ["0x7305"]
    assert noise["recovery_class"] == "encoder" and noise["params"][0]["max"] == 2**20
    # a PLC field fault says how to come back too (plc.machine_io.RECOVERY)
    air = next(t for t in types if t["type"] == "air_pressure_loss")
    assert air["recovery_class"] == "air" and air["recovery"].startswith("restore the shop air")
    rev = upload_released(api, STOPPING_PROGRAM, number=1002)
    job = api("operator").post("/api/jobs", json={"revision_id": rev, "quantity": 2}).json()["id"]
    poll(lambda: status(api, "mill1")["execution"] == "PROGRAM_STOPPED", 60, "mill1 at M0")
    r = api("admin").post(
        "/api/machines/mill1/faults", json={"type": "overcurrent", "target": "drive:X"}
    )
    assert r.status_code == 201, r.text
    fault = r.json()
    assert fault["spec"] == "drive:X:overcurrent" and fault["state"] == "active"
    assert [f["id"] for f in api("viewer").get("/api/machines/mill1/faults").json()] == [
        fault["id"]
    ]

    alarmed = poll(lambda: (s := status(api, "mill1"))["alarms"] and s, 30, "mill1 alarm")
    assert any(a["level"] == "FAULT" for a in alarmed["alarms"]), alarmed["alarms"]

    def completed():
        # the operator at mill2 continues each part after its M0
        if status(api, "mill2")["execution"] == "PROGRAM_STOPPED":
            r = api("operator").post(
                "/api/machines/mill2/commands", json={"command": "cycle_start"}
            )
            assert r.status_code == 202, r.text
        j = api("viewer").get(f"/api/jobs/{job}").json()
        return j["status"] == "completed" and j

    done = poll(completed, 90, "job completed on mill2", interval_s=0.2)
    assert done["done"] == 2
    by_state = {}
    for a in done["allocations"]:
        by_state.setdefault(a["status"], []).append(a["machine"])
    # interrupted, then its part rerouted to mill2 (dnc/allocation.py)
    assert by_state.get("rerouted") == ["mill1"], done["allocations"]
    rerouted = next(a for a in done["allocations"] if a["status"] == "rerouted")
    assert rerouted["rerouted_to"] in {a["id"] for a in done["allocations"]}
    assert sorted(by_state["completed"]) == ["mill2", "mill2"], done["allocations"]
    assert any(
        d["action"] == "interrupt" and "mill1 raised an alarm" in d["reason"]
        for d in done["decisions"]
    )
    assert status(api, "mill2")["counters"]["part_count"] == 2
    assert status(api, "mill1")["counters"]["part_count"] == 0

    events = sse_until(
        api, lambda e: e.get("action") == "machine.alarm" and e.get("machine") == "mill1", 20
    )
    assert any(e.get("action") == "job.interrupt" for e in events) or sse_until(
        api, lambda e: e.get("action") == "job.interrupt", 10
    )

    injected = sse_until(api, lambda e: e.get("action") == "machine.fault_injected", 10)
    assert injected[-1]["spec"] == "drive:X:overcurrent" and injected[-1]["machine"] == "mill1"

    xml = api("viewer").get("/mtconnect/mill1/current").text
    root = ET.fromstring(xml)
    faults = [el for el in root.iter() if el.tag.endswith("Fault")]
    assert faults, xml[:2000]

    r = api("admin").delete(f"/api/machines/mill1/faults/{fault['id']}")
    assert r.status_code == 200, r.text
    assert r.json()["state"] == "cleared"
    assert api("admin").delete("/api/machines/mill1/faults/999").status_code == 404


def test_bad_fault_requests_are_problems(make_cell):
    _, api = make_cell(faults=True)
    r = api("admin").post("/api/machines/mill1/faults", json={"type": "nonsense", "target": "X"})
    assert r.status_code == 422 and r.headers["content-type"].startswith("application/problem")
    assert "nonsense" in r.json()["detail"]
    r = api("admin").post("/api/machines/nope/faults", json={"type": "encoder", "target": "X"})
    assert r.status_code == 404
    r = api("admin").post("/api/machines/mill1/faults", json={"type": "encoder", "target": "Q!"})
    assert r.status_code == 422
    # ideal axes have no CAN bus: the machine refuses, the API says so
    r = api("admin").post("/api/machines/mill1/faults", json={"type": "bus_off", "target": "bus:X"})
    assert r.status_code == 409, r.text
    assert "ideal axes" in r.json()["detail"]
    assert api("viewer").get("/api/machines/mill1/faults").json() == []


def test_fault_endpoints_are_absent_when_disabled_and_the_auth_matrix_holds(make_cell):
    _, api = make_cell(faults=False)
    paths = api("viewer").get("/openapi.json").json()["paths"]
    assert "/api/machines/{name}/commands" in paths
    assert not any("fault" in p for p in paths)
    for method, path in (
        ("get", "/api/fault-types"),
        ("get", "/api/machines/mill1/faults"),
        ("post", "/api/machines/mill1/faults"),
        ("delete", "/api/machines/mill1/faults/1"),
    ):
        r = api("admin").request(method.upper(), path, json={"type": "encoder", "target": "X"})
        assert r.status_code in (404, 405), (method, path, r.status_code)
        assert r.status_code == 404 or method != "get"
    # commands: operator and above; viewers 403; no key 401
    cmd = {"command": "feed_hold"}
    assert api("anonymous").post("/api/machines/mill1/commands", json=cmd).status_code == 401
    assert api("viewer").post("/api/machines/mill1/commands", json=cmd).status_code == 403
    for role in ("operator", "programmer", "admin"):
        r = api(role).post("/api/machines/mill1/commands", json=cmd)
        assert r.status_code == 202, (role, r.text)
    assert api("viewer").get("/api/machines/mill1").status_code == 200
    assert api("anonymous").get("/api/machines").status_code == 401
    r = api("operator").post("/api/machines/nope/commands", json=cmd)
    assert r.status_code == 404
    r = api("operator").post("/api/machines/mill1/commands", json={"command": "select_program"})
    assert r.status_code == 422
    # 8-digit O numbers: REST -> Modbus (registers 1028 + 1029) -> PLC -> NC, which answers
    sel = {"command": "select_program", "number": 80000001}
    r = api("operator").post("/api/machines/mill1/commands", json=sel)
    assert r.status_code == 409 and "O80000001 refused: program not in memory" in r.text, r.text
    r = api("operator").post("/api/machines/mill1/commands", json={**sel, "number": 100000000})
    assert r.status_code == 422 and "99999999" in r.text
    # E-stop has no face without the simulation face: a clear refusal, not a 5xx
    r = api("operator").post("/api/machines/mill1/commands", json={"command": "estop"})
    assert r.status_code == 409 and "simulation face" in r.json()["detail"]
    assert set(KEYS) == {"viewer", "operator", "programmer", "admin"}


def test_fault_auth_matrix(make_cell):
    _, api = make_cell(faults=True)
    paths = api("viewer").get("/openapi.json").json()["paths"]
    for path in (
        "/api/fault-types",
        "/api/machines/{name}/faults",
        "/api/machines/{name}/faults/{fault_id}",
        "/api/machines/{name}/commands",
    ):
        assert path in paths, sorted(paths)
    body = {"type": "air_pressure_loss", "target": "plc", "duration": 0.5}
    assert api("anonymous").post("/api/machines/lathe1/faults", json=body).status_code == 401
    for role in ("viewer", "operator", "programmer"):
        assert api(role).post("/api/machines/lathe1/faults", json=body).status_code == 403
        assert api(role).get("/api/machines/lathe1/faults").status_code == 200
        assert api(role).get("/api/fault-types").status_code == 200
    r = api("admin").post("/api/machines/lathe1/faults", json=body)
    assert r.status_code == 201, r.text
    fid = r.json()["id"]
    assert api("operator").delete(f"/api/machines/lathe1/faults/{fid}").status_code == 403
    # the duration ends it without a DELETE
    poll(
        lambda: api("viewer").get("/api/machines/lathe1/faults").json()[0]["state"] == "cleared",
        20,
        "fault cleared after its duration",
    )


def test_clear_reset_home_over_http_brings_a_machine_back_and_it_says_when_it_is_not_homed(
    make_cell,
):
    """docs/recovery.md over the REST API: a drive fault that loses the reference, cleared,
    one reset (no FAULT left, but `referenced` false: the tile says NOT REFERENCED, the cell
    does not dispatch to it), home, referenced again."""
    _, api = make_cell(faults=True)
    poll(lambda: status(api, "mill1")["referenced"] is True, 30, "mill1 referenced")
    r = api("admin").post(
        "/api/machines/mill1/faults", json={"type": "encoder_break", "target": "drive:X"}
    )
    assert r.status_code == 201, r.text
    fault = r.json()
    poll(
        lambda: any(a["level"] == "FAULT" for a in status(api, "mill1")["alarms"]),
        30,
        "mill1 drive alarm",
    )
    r = api("admin").delete(f"/api/machines/mill1/faults/{fault['id']}")
    assert r.status_code == 200, r.text
    r = api("operator").post("/api/machines/mill1/commands", json={"command": "reset"})
    assert r.status_code == 202, r.text

    def no_fault():
        s = status(api, "mill1")
        return not [a for a in s["alarms"] if a["level"] == "FAULT"] and s

    after = poll(no_fault, 30, "mill1 FAULT alarms cleared")
    assert after["referenced"] is False and "X" in after["unreferenced_axes"], after
    # what is left says what to do
    assert {(a["code"], a["level"]) for a in after["alarms"]} == {("3031", "WARNING")}
    assert "axis X not referenced: home the machine" in after["alarms"][0]["text"]
    r = api("operator").post("/api/machines/mill1/commands", json={"command": "home"})
    assert r.status_code == 202, r.text
    back = poll(lambda: (s := status(api, "mill1"))["referenced"] and s, 60, "mill1 homed")
    assert back["unreferenced_axes"] == [] and back["mode"] == "AUTOMATIC"
    assert back["alarms"] == []


@pytest.mark.parametrize(
    ("fault", "target"),
    [("power_cycle", "drive:Z"), ("drop", "bus:X"), ("encoder_break", "drive:Y")],
)
def test_recovery_over_http_on_canopen_drives(make_cell, fault, target):
    """The issue's recipe on the real drives (CiA 402 over the simulated CAN bus, clock
    fast): inject, clear, reset, home over REST, then the machine is referenced, without
    alarms and idle for the cell."""
    _, api = make_cell(faults=True, ideal_axes=False)
    poll(lambda: status(api, "mill1")["referenced"] is True, 60, "mill1 referenced")
    body = {"type": fault, "target": target}
    if fault == "drop":
        body["params"] = {"count": 0}
    r = api("admin").post("/api/machines/mill1/faults", json=body)
    assert r.status_code == 201, r.text
    fault_id = r.json()["id"]
    poll(lambda: status(api, "mill1")["alarms"], 30, "mill1 alarm")
    r = api("admin").delete(f"/api/machines/mill1/faults/{fault_id}")
    assert r.status_code == 200, r.text
    r = api("operator").post("/api/machines/mill1/commands", json={"command": "reset"})
    assert r.status_code == 202, r.text

    def no_fault():
        s = status(api, "mill1")
        return not [a for a in s["alarms"] if a["level"] == "FAULT"] and s

    poll(no_fault, 30, "mill1 FAULT alarms cleared")
    r = api("operator").post("/api/machines/mill1/commands", json={"command": "home"})
    assert r.status_code == 202, r.text
    back = poll(
        lambda: (s := status(api, "mill1"))["referenced"] and not s["alarms"] and s,
        60,
        "mill1 homed without alarms",
    )
    assert back["mode"] == "AUTOMATIC" and back["execution"] in ("READY", "PROGRAM_COMPLETED")
