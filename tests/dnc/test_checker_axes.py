"""The upload check for a kind whose machines differ in their axes (mill: mill3's X Y Z,
mill4's rotary table A): uploads are checked with the kind's widest shipped machine, and a
dispatch to a machine without an axis the program names is refused with line and why."""

from __future__ import annotations

import pytest
from sqlalchemy import func, select

from cnc.config import builtin_machine
from dnc import models as m
from dnc.checker import kind_axes, machine_check, nc_checker
from dnc.db import transaction
from dnc.dispatch import Dispatches
from dnc.errors import NotForMachine
from dnc.library import Library

ROTARY = """%
O0040 (MILL4 ROTARY)
G21 G90 G54 G17
G00 X0 Y0 Z20 A0
G01 Z-2 F300
G01 X20 A90 F600
M30
%
"""
PLAIN = ROTARY.replace(" A0", "").replace(" A90", "").replace("O0040", "O0041")
# a macro call's argument A is no axis word: a mill3 runs it
MACRO_ARG = PLAIN.replace("O0041", "O0042").replace("M30", "G65 P9010 A1. B2.\nM30")
SUB = "%\nO9010\n#100=#1+#2\nM99\n%\n"
CONFIGS = {"mill1": builtin_machine("mill3"), "rot1": builtin_machine("mill4")}


def test_an_upload_for_mill_may_name_the_rotary_table_of_a_mill4():
    assert kind_axes("mill") == ("X", "Y", "Z", "A")
    assert kind_axes("lathe") == ("X", "Z") and kind_axes("mill5") == ("X", "Y", "Z", "B", "C")
    assert nc_checker(ROTARY, "mill") == []
    # an axis no shipped mill has is still refused at upload, with line and column
    [err] = nc_checker(ROTARY.replace("A90", "B90"), "mill")
    assert (err["line"], err["col"]) == (6, 9) and "axis B is not configured" in err["message"]


def test_the_machine_check_runs_the_nc_check_with_the_machines_own_axes():
    [a0, a90] = machine_check(ROTARY, "mill", CONFIGS["mill1"])
    assert (a0["line"], a0["col"]) == (4, 15) and "axis A is not configured" in a0["message"]
    assert (a90["line"], a90["col"]) == (6, 9)
    assert machine_check(ROTARY, "mill", CONFIGS["rot1"]) == []
    assert machine_check(PLAIN, "mill", CONFIGS["mill1"]) == []


@pytest.fixture
def lib(sessions):
    lib = Library(sessions, checker=nc_checker, machine_configs=lambda n, k: CONFIGS.get(n))
    for name in ("mill1", "rot1", "mill9"):  # mill9: the host has no configuration for it
        lib.register_machine(name, "mill")
    return lib


def _released(lib, text: str, number: int) -> int:
    _, rev = lib.create_program(number=number, name=f"p{number}", text=text)
    assert rev.check_ok, rev.check_errors
    return lib.release(rev.id, approver="ann", comment="ok").id


def _dispatches(sessions) -> int:
    with transaction(sessions) as s:
        return s.scalar(select(func.count()).select_from(m.Dispatch))


def test_a_dispatch_to_a_mill_without_the_a_axis_is_refused_with_line_and_reason(lib, sessions):
    rotary = _released(lib, ROTARY, 40)
    d = Dispatches(sessions, machine_configs=lib.machine_configs)
    with pytest.raises(NotForMachine) as err:
        d.request(key="k1", revision_id=rotary, machine="mill1")
    detail = err.value.detail
    assert (detail["line"], detail["column"], detail["machine"]) == (4, 15, "mill1")
    assert "axis A is not configured" in detail["reason"]
    assert "mill1 is a mill with axes X Y Z" in err.value.message
    assert _dispatches(sessions) == 0
    assert d.request(key="k2", revision_id=rotary, machine="rot1")[1] is True
    # without the machine's configuration the host cannot judge: the machine will
    assert d.request(key="k3", revision_id=rotary, machine="mill9")[1] is True
    for number, text in ((41, PLAIN), (9010, SUB), (42, MACRO_ARG)):
        rev = _released(lib, text, number)
        assert d.request(key=f"p{number}", revision_id=rev, machine="mill1")[1] is True
    assert _dispatches(sessions) == 5


def test_a_scheduler_made_dispatch_to_a_mill_without_the_a_axis_fails_before_sending(lib, sessions):
    from dnc.dispatch import DispatchRequest, create_dispatches
    from dnc.transfer_worker import TransferWorker

    rotary = _released(lib, ROTARY, 40)
    with transaction(sessions) as s:
        [(bad, _), (ok, _)] = create_dispatches(
            s,
            [DispatchRequest("j1", rotary, "mill1"), DispatchRequest("j2", rotary, "rot1")],
            requested_by="scheduler",
            now=lib._now(),
        )
    worker = TransferWorker(sessions, machine_configs=lib.machine_configs)
    assert worker.run(bad) == "failed"
    failed = Dispatches(sessions).get(bad)
    assert failed.bytes_sent == 0 and failed.attempts == 1
    assert failed.error.startswith("check: line 4, column 15: unknown address A")
    assert "mill1 has axes X Y Z" in failed.error
    # rot1 has an A: the attempt goes on to the line (no DNC address here: connect fails)
    worker.run(ok)
    assert Dispatches(sessions).get(ok).error.startswith("connect")
