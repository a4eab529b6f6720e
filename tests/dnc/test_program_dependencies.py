"""Programs across files in the DNC library: calls recorded at upload and resolved by the NC
check, subprogram files checked in subprogram mode, a dispatch that brings its subprograms
along over a real DNC port (and the program then runs on the simulated machine), and a
dispatch refused before anything is sent when a subprogram has no released revision.

SQLite and, when it answers, PostgreSQL (tests/dnc/conftest.py)."""

from __future__ import annotations

import pytest
from sqlalchemy import func, select

from dnc import models as m
from dnc.checker import nc_checker
from dnc.db import transaction
from dnc.dependencies import MissingDependency
from dnc.dispatch import Dispatches
from dnc.jobs import Jobs
from dnc.library import Library
from dnc.transfer import canonical_text
from dnc.transfer_worker import TransferWorker
from tests.cnc.dnc_helpers import Machine as DncMachine

# a Haas-style pair (payne-o1001 / o1002 in the corpus): the subprogram has no F of its own
MAIN = """%
O1001 (GAUGE)
G21 G90 G17
G0 X-10. Y-10. Z-10.
G01 Z-12. F600.
M98 P1002 L2 (twice)
G0 Z-10.
M30
%
"""
SUB = """%
O1002 (ONE PASS)
G91 G01 X-5.
G90
M99
%
"""
# O1003 calls O1004 by G65 with an argument: two levels
OUTER = "%\nO1003\nG21 G90 G0 X-10. Y-10. Z-10.\nG1 F600 X-11.\nM98 P1004\nM30\n%\n"
MIDDLE = "%\nO1004\nG65 P9005 A2.\nM99\n%\n"
MACRO = "%\nO9005\nG91 G1 Y-#1\nG90\nM99\n%\n"


@pytest.fixture
def lib(sessions):
    return Library(sessions, checker=nc_checker)


def upload(lib, number, text, release=True):
    _, rev = lib.create_program(number=number, name=f"O{number}", text=text)
    if release:
        rev = lib.release(rev.id, approver="ann", comment="ok")
    return rev


def dispatch_count(sessions) -> int:
    with transaction(sessions) as s:
        return s.scalar(select(func.count()).select_from(m.Dispatch))


# --- upload ------------------------------------------------------------------------------------


def test_a_subprogram_file_is_checked_in_subprogram_mode(lib):
    rev = upload(lib, 1002, SUB, release=False)
    assert (rev.check_ok, rev.check_errors) == (True, [])
    # the same moves ending in M30 are a main program without a feed
    rev = upload(lib, 1012, SUB.replace("O1002", "O1012").replace("M99", "M30"), release=False)
    assert [e["message"] for e in rev.check_errors] == ["feed move without F"]


def test_upload_records_the_calls_and_the_check_goes_through_the_called_program(lib):
    sub = upload(lib, 1002, SUB)
    main = upload(lib, 1001, MAIN)
    assert main.check_ok
    (call,) = lib.calls(main.id)
    assert call == dict(code="M98", number=1002, line=6, col=5, program_id=sub.program_id,
                        released_revision_id=sub.id)  # fmt: skip
    (caller,) = lib.called_by(sub.program_id)
    assert (caller["number"], caller["revision_id"], caller["line"]) == (1001, main.id, 6)
    assert lib.called_by(main.program_id) == []
    # an error in the called program fails the caller's check and says where it is
    bad = upload(lib, 1022, "%\nO1022\nG91 G01 X-5.\nG2 X1\nM99\n%\n", release=False)
    assert not bad.check_ok
    rev = upload(lib, 1021, MAIN.replace("O1001", "O1021").replace("P1002", "P1022"), False)
    assert not rev.check_ok
    assert any(e["message"].endswith("(in O1022)") for e in rev.check_errors), rev.check_errors


def test_a_program_may_be_uploaded_before_the_programs_it_calls(lib):
    main = upload(lib, 1001, MAIN)
    assert main.check_ok  # the call is recorded unresolved; the check goes on past it
    assert lib.calls(main.id) == [dict(code="M98", number=1002, line=6, col=5, program_id=None,
                                       released_revision_id=None)]  # fmt: skip
    sub = upload(lib, 1002, SUB, release=False)
    (call,) = lib.calls(main.id)
    assert (call["program_id"], call["released_revision_id"]) == (sub.program_id, None)


def test_dependencies_are_transitive_deepest_first_and_each_once(lib):
    macro, middle = upload(lib, 9005, MACRO), upload(lib, 1004, MIDDLE)
    outer = upload(lib, 1003, OUTER)
    assert outer.check_ok and middle.check_ok and macro.check_ok, outer.check_errors
    deps = lib.dependencies(outer.id)
    assert [(d.number, d.revision_id) for d in deps] == [(9005, macro.id), (1004, middle.id)]
    # two calls of one program, and a program calling back (recursion), bring it once
    twice = upload(lib, 1005, "%\nO1005\nG1 F600 X-1.\nM98 P1004\nM98 P1004\nM98 P1006\nM30\n%\n")
    back = upload(lib, 1006, "%\nO1006\nM98 P1004\nM99\n%\n")
    assert [d.number for d in lib.dependencies(twice.id)] == [9005, 1004, 1006]
    assert [d.number for d in lib.dependencies(back.id)] == [9005, 1004]


@pytest.mark.parametrize("state", ["absent", "draft", "obsolete"])
def test_a_missing_dependency_names_the_o_number_and_the_calling_line(lib, state):
    if state != "absent":
        rev = upload(lib, 9005, MACRO, release=state == "obsolete")
        if state == "obsolete":
            lib.obsolete(rev.id, approver="ann", comment="scrapped")
    upload(lib, 1004, MIDDLE)
    outer = upload(lib, 1003, OUTER)
    with pytest.raises(MissingDependency) as ei:
        lib.dependencies(outer.id)
    err = ei.value
    assert err.detail["missing"] == 9005 and err.detail["caller"] == 1004
    assert (err.detail["line"], err.detail["code"]) == (3, "G65")  # line 1 is the %
    assert "O1004 (revision" in err.message and "line 3: G65 P9005 calls O9005" in err.message
    why = "has no released revision" if state != "absent" else "the library has no O9005"
    assert why in err.message


# --- dispatch ----------------------------------------------------------------------------------


def test_a_dispatch_or_a_job_with_a_missing_subprogram_is_refused_and_nothing_is_recorded(
    lib, sessions
):
    dnc = DncMachine(capacity=64 * 1024)
    try:
        lib.register_machine("mill1", "mill", dnc_address=f"127.0.0.1:{dnc.port.bound_port}")
        main = upload(lib, 1001, MAIN)
        with pytest.raises(MissingDependency, match=r"line 6: M98 P1002 calls O1002"):
            Dispatches(sessions).request(key="k1", revision_id=main.id, machine="mill1")
        with pytest.raises(MissingDependency):
            Jobs(sessions).create(revision_id=main.id, quantity=2)
        assert dispatch_count(sessions) == 0
        TransferWorker(sessions).run_once()
        assert dnc.memory.directory() == []  # nothing sent
    finally:
        dnc.close()


def test_a_subprogram_obsoleted_after_the_request_fails_the_transfer_before_sending(lib, sessions):
    dnc = DncMachine(capacity=64 * 1024)
    try:
        lib.register_machine("mill1", "mill", dnc_address=f"127.0.0.1:{dnc.port.bound_port}")
        sub, main = upload(lib, 1002, SUB), upload(lib, 1001, MAIN)
        info, _ = Dispatches(sessions).request(key="k1", revision_id=main.id, machine="mill1")
        lib.obsolete(sub.id, approver="ann", comment="wrong depth")
        assert TransferWorker(sessions).run(info.id) == "failed"
        d = Dispatches(sessions).get(info.id)
        assert d.error.startswith("dependency: O1001") and "O1002" in d.error
        assert (d.attempts, d.bytes_sent) == (1, 0)
        assert dnc.memory.directory() == []
    finally:
        dnc.close()


@pytest.fixture
def mill():
    from cnc.config import load_machine_config
    from cnc.machine import Machine

    ports = {"dnc": 0, "modbus": 0, "shdr": 0, "simulation": None}
    cfg = load_machine_config({"base": "mill3", "ports": ports, "machine_data": None})
    machine = Machine(cfg, "mill1", ideal=True)
    machine.start_faces()
    machine.step(50)
    machine.command("mode", mode="REF")
    machine.command("home")
    assert machine.run_until(lambda mm: all(mm.controller.referenced.values()), 5.0)
    machine.command("mode", mode="AUTO")
    yield machine
    machine.close()


def test_dispatch_brings_the_subprograms_and_the_program_runs_on_the_machine(lib, sessions, mill):
    lib.register_machine("mill1", "mill", dnc_address=f"127.0.0.1:{mill.faces.ports()['dnc']}")
    sub, main = upload(lib, 1002, SUB), upload(lib, 1001, MAIN)
    worker = TransferWorker(sessions)
    info, _ = Dispatches(sessions).request(key="k1", revision_id=main.id, machine="mill1")
    assert worker.run(info.id) == "done"
    assert mill.memory.get(1002) == canonical_text(SUB)
    assert mill.memory.get(1001) == canonical_text(MAIN)
    (brought,) = lib.audit(entity="dispatch", entity_id=info.id)[2:3]
    assert brought["action"] == "dispatch.subprograms"
    assert brought["detail"]["sent"] == [1002] and brought["detail"]["revisions"] == [sub.id]

    mill.command("select_program", number=1001)
    mill.command("cycle_start")
    mill.step(5)
    assert mill.run_until(lambda mm: mm.status.execution != "ACTIVE", 30.0)
    assert mill.status.execution == "PROGRAM_COMPLETED", mill.alarms
    assert mill.axes.feedback().actual == pytest.approx({"X": -20.0, "Y": -10.0, "Z": -10.0})

    # again: the machine holds the same O1002, which is not sent twice
    info2, _ = Dispatches(sessions).request(key="k2", revision_id=main.id, machine="mill1")
    assert worker.run(info2.id) == "done"
    (brought,) = [a for a in lib.audit(entity="dispatch", entity_id=info2.id)
                  if a["action"] == "dispatch.subprograms"]  # fmt: skip
    assert (brought["detail"]["sent"], brought["detail"]["already_there"]) == ([], [1002])


def test_drip_feed_brings_the_subprograms_into_memory_first(lib, sessions):
    dnc = DncMachine(capacity=64 * 1024)
    try:
        lib.register_machine("mill1", "mill", dnc_address=f"127.0.0.1:{dnc.port.bound_port}")
        upload(lib, 9005, MACRO), upload(lib, 1004, MIDDLE)
        outer = upload(lib, 1003, OUTER)
        info, _ = Dispatches(sessions).request(
            key="k1", revision_id=outer.id, machine="mill1", mode="drip_feed"
        )
        assert TransferWorker(sessions).run(info.id) == "done"
        assert [e.number for e in dnc.memory.directory()] == [1004, 9005]
        assert dnc.drip_buffers and Dispatches(sessions).get(info.id).bytes_sent > len(OUTER)
    finally:
        dnc.close()


# --- REST ----------------------------------------------------------------------------------------


def test_rest_shows_calls_and_callers_and_refuses_a_dispatch_as_problem_json(sessions):
    from tests.web_api.test_api_common import BASE, PROBLEM, make_api

    api = make_api(sessions)
    with api.client:
        main = api.upload(1001, MAIN)
        pid, rid = main["program"]["id"], main["revision"]["id"]
        api.post(f"/api/revisions/{rid}/release", role="programmer", json={"comment": "ok"})
        r = api.post("/api/dispatches", role="operator", json=dict(revision_id=rid,
                     machine="mill-1"), headers={"Idempotency-Key": "k1"})  # fmt: skip
        assert r.status_code == 409 and r.headers["content-type"].startswith(PROBLEM)
        body = r.json()
        assert body["type"] == BASE + "missing-dependency"
        assert (body["missing"], body["caller"], body["line"]) == (1002, 1001, 6)
        assert "line 6: M98 P1002 calls O1002" in body["detail"]
        assert dispatch_count(sessions) == 0

        sub = api.upload(1002, SUB)
        detail = api.get(f"/api/programs/{pid}").json()
        assert detail["calls"] == [dict(code="M98", number=1002, line=6, col=5,
                                        program_id=sub["program"]["id"],
                                        released_revision_id=None)]  # fmt: skip
        assert detail["called_by"] == []
        callers = api.get(f"/api/programs/{sub['program']['id']}").json()["called_by"]
        assert [(c["number"], c["line"], c["code"]) for c in callers] == [(1001, 6, "M98")]
        assert api.get(f"/api/revisions/{rid}/calls").json() == detail["calls"]


def test_a_packed_m98_is_resolved_as_the_interpreter_does(lib):
    """`M98 P51000` without L: five times O1000, unless an O51000 exists."""
    sub = upload(lib, 1000, "%\nO1000\nG91 G0 X-1.\nG90\nM99\n%\n")
    main = upload(lib, 1, "%\nO1\nG21 G90 G0 X-10. Y-10. Z-10.\nM98 P51000\nM30\n%\n")
    assert main.check_ok, main.check_errors
    (call,) = lib.calls(main.id)
    assert (call["number"], call["program_id"]) == (1000, sub.program_id)
    assert [c["number"] for c in lib.called_by(sub.program_id)] == [1]
    assert [d.number for d in lib.dependencies(main.id)] == [1000]
    long = upload(lib, 51000, "%\nO51000\nG91 G0 Y-1.\nG90\nM99\n%\n")
    assert lib.called_by(sub.program_id) == []
    assert [c["number"] for c in lib.called_by(long.program_id)] == [1]
    assert [d.number for d in lib.dependencies(main.id)] == [51000]
