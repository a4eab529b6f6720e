"""Cycle starts and program selects are audited whoever made them: a third-party Modbus
client on the remote panel, or the host itself (server/cycle_audit.py)."""

from __future__ import annotations

import pytest
from pymodbus.client import ModbusTcpClient
from sqlalchemy import select

from dnc import models as m
from plc.remote_panel import RemotePanel
from server.cycle_audit import NOT_THE_HOST, HostRequests, Seen, changes
from tests.cell.conftest import idem, poll, upload_released

pytestmark = pytest.mark.timeout(180)

R, A, H, C = "READY", "ACTIVE", "FEED_HOLD", "PROGRAM_COMPLETED"

# prev, cur -> the changes seen (kind, program, the detail that matters)
CASES = [
    (None, Seen(A, "O0001", 0), []),  # first look: nothing was done
    (Seen("UNAVAILABLE", "", None), Seen(A, "O0001", 0), []),  # reconnect
    (Seen(A, "O0001", 0), Seen("UNAVAILABLE", "", None), []),
    (Seen(R, "O0001", 0), Seen(R, "O0001", 0), []),
    (Seen(R, "O0001", 0), Seen(R, "O0002", 0), [("program_select", "O0002", "O0001")]),
    (Seen(R, "O0001", 0), Seen(R, "", 0), []),  # a reset that deselects is no select
    (Seen(R, "O0001", 0), Seen(A, "O0001", 0), [("cycle_start", "O0001", False)]),
    (Seen(C, "O0001", 1), Seen(A, "O0001", 1), [("cycle_start", "O0001", False)]),
    (Seen(H, "O0001", 0), Seen(A, "O0001", 0), [("cycle_start", "O0001", True)]),
    (Seen("OPTIONAL_STOP", "O1", 0), Seen(A, "O1", 0), [("cycle_start", "O1", True)]),
    (Seen(A, "O0001", 0), Seen(A, "O0001", 0), []),
    (Seen(A, "O0001", 0), Seen(C, "O0001", 1), []),  # ended: counted, no new start
    (Seen(A, "O0001", 0), Seen(H, "O0001", 0), []),
    # selected and started between two looks
    (
        Seen(R, "O0001", 0),
        Seen(A, "O0002", 0),
        [("program_select", "O0002", "O0001"), ("cycle_start", "O0002", False)],
    ),
    # a cycle shorter than one look: seen from the part counter only
    (Seen(C, "O0001", 3), Seen(C, "O0001", 4), [("cycle_start", "O0001", "part count")]),
    (Seen(R, "O0001", None), Seen(C, "O0001", 4), []),
]


@pytest.mark.parametrize(("prev", "cur", "want"), CASES)
def test_changes_between_two_looks(prev, cur, want):
    got = changes(prev, cur)
    assert [k for k, _ in got] == [w[0] for w in want]
    for (kind, detail), w in zip(got, want, strict=True):
        assert detail["program"] == w[1]
        if kind == "program_select":
            assert detail["previous"] == w[2]
        elif w[2] == "part count":
            assert detail["seen"] == "part count"
        else:
            assert detail["resumed"] is w[2] and detail["seen"] == "execution"


def test_host_requests_are_taken_once_and_forgotten_after_their_ttl():
    t = [0.0]
    req = HostRequests(ttl_s=30, clock=lambda: t[0])
    req.expect("mill1", "cycle_start", "transfer worker")
    req.expect("mill1", "cycle_start", "REST machine command")
    assert req.take("mill2", "cycle_start") is None
    assert req.take("mill1", "cycle_start") == "transfer worker"
    t[0] = 31
    assert req.take("mill1", "cycle_start") is None  # stale: a panel gets the credit


def test_host_requests_never_taken_are_forgotten_too():
    # every dispatch of a job expects the select of the program already selected: that
    # change never shows, so it is never taken; the requests held stay bounded by the ttl
    t = [0.0]
    req = HostRequests(ttl_s=30, clock=lambda: t[0])
    held = []
    for part in range(1000):
        t[0] = part * 20.0
        req.expect("mill1", "program_select O1101", "transfer worker")
        req.expect("mill1", "cycle_start", "transfer worker")
        assert req.take("mill1", "cycle_start") == "transfer worker"
        held.append(req.pending)
    assert max(held) <= 2 and held[-1] == 2


def audit(cell, action: str) -> list[tuple[str, dict]]:
    with cell.sessions() as s:
        rows = s.scalars(select(m.AuditEntry).where(m.AuditEntry.action == action)).all()
        return [(r.actor, dict(r.detail)) for r in rows]


def test_a_modbus_clients_select_and_cycle_start_are_audited_as_not_the_hosts(make_cell):
    cell, api = make_cell()
    rev = upload_released(api)
    # the host loads the program (no start): nothing selected or started yet
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
    assert audit(cell, "machine.cycle_start") == []
    # a third-party HMI on the Modbus face: program select, cycle start
    link = cell.links["mill2"]
    client = ModbusTcpClient(link.host, port=link.ports["modbus"], timeout=5)
    assert client.connect()
    try:
        panel = RemotePanel(client)
        panel.select_program(1001, timeout_s=20)
        panel.cycle_start()
    finally:
        client.close()
    starts = poll(lambda: audit(cell, "machine.cycle_start"), 30, "cycle start audited")
    actor, detail = starts[0]
    assert actor == "machine-panel"
    assert detail["machine"] == "mill2" and detail["program"] == "O1001"
    assert detail["requested_by"] == NOT_THE_HOST
    selects = audit(cell, "machine.program_selected")
    assert selects and selects[0][0] == "machine-panel"
    assert selects[0][1]["program"] == "O1001"
    poll(
        lambda: (
            api("viewer").get("/api/machines/mill2").json()["status"]["counters"]["part_count"] == 1
        ),
        30,
        "the HMI's part made",
    )
    # the host's own dispatch with start: audited too, as the host's
    r = api("operator").post(
        "/api/dispatches",
        json={"revision_id": rev, "machine": "mill1", "start": True},
        headers=idem(),
    )
    assert r.status_code == 202, r.text
    poll(
        lambda: [d for a, d in audit(cell, "machine.cycle_start") if d["machine"] == "mill1"],
        40,
        "the host's start audited",
    )
    host_starts = [(a, d) for a, d in audit(cell, "machine.cycle_start") if d["machine"] == "mill1"]
    assert host_starts == [
        (
            "host",
            {
                "machine": "mill1",
                "program": "O1001",
                "previous_execution": "READY",
                "resumed": False,
                "seen": "execution",
                "requested_by": "transfer worker",
            },
        )
    ]
    # the event stream carries them too (outbox in the same transaction)
    with cell.sessions() as s:
        topics = s.scalars(select(m.OutboxEvent.topic)).all()
    assert any(t.endswith("/cycle_start") for t in topics), topics
