"""The controller's homing sequence and its answers to the PLC's program select and zero
return requests (the remote operator panel's path), in lockstep with IdealAxes and a fake
or the real machine-tool PLC."""

from __future__ import annotations

import pytest

from cnc.controller import ControllerSettings
from plc.signals import (
    MODE_AUTO,
    MODE_REF,
    REFUSE_BAD_NUMBER,
    REFUSE_HOMING,
    REFUSE_NOT_ENABLED,
    REFUSE_NOT_IN_MEMORY,
    REFUSE_NOT_REF_MODE,
    REFUSE_PROGRAM_ACTIVE,
    dword_value,
    dword_words,
)
from tests.cnc.test_controller import SQUARE, Rig


def home_commands(rig: Rig, limit_s: float = 10.0) -> list[tuple[tuple[str, ...], dict]]:
    """Step until every axis is referenced; each home command sent to the axis layer with
    the axes referenced at that moment."""
    sent = []
    end = rig.k + int(limit_s / rig.dt)
    while not (all(rig.ctl.referenced.values()) and not rig.outputs.plc["HomingActive"]):
        assert rig.k < end, f"homing not done: {rig.ctl.events[-5:]}"
        rig.step()
        if rig.outputs.axis_command == "home":
            sent.append((rig.outputs.home_axes, dict(rig.ctl.referenced)))
    return sent


@pytest.mark.parametrize(
    ("machine", "settings", "groups"),
    [
        ("mill3", None, [("Z",), ("X", "Y")]),
        ("lathe2", None, [("X",), ("Z",)]),
        ("mill3", ControllerSettings(home_sequence=(("X", "Y", "Z"),)), [("X", "Y", "Z")]),
        (
            "mill3",
            ControllerSettings(home_sequence=(("Z",), ("Y",), ("X",))),
            [("Z",), ("Y",), ("X",)],
        ),
        ("mill3", ControllerSettings(home_order=("Y", "Z", "X")), [("Y",), ("Z",), ("X",)]),
    ],
)
def test_homing_runs_group_after_group(machine, settings, groups):
    rig = Rig(machine, settings=settings)
    rig.step(10)
    rig.cmd("mode", mode="REF")
    rig.cmd("home")
    sent = home_commands(rig)
    assert [axes for axes, _ in sent] == groups
    # a group starts only once every earlier group is referenced, and no later axis is
    for i, (_, referenced) in enumerate(sent):
        earlier = {a for g in groups[:i] for a in g}
        assert {a for a, ok in referenced.items() if ok} == earlier, (i, referenced)
    assert rig.outputs.plc["AllReferenced"]
    want = sum(1 << "XYZ".index(a) for a in rig.ctl.axes)
    assert rig.outputs.plc["ReferencedAxes"] == want
    assert any(t.startswith("homed ") for _, t in rig.ctl.events)


def test_homing_some_axes_keeps_the_sequence_order():
    rig = Rig()
    rig.step(10)
    rig.cmd("mode", mode="REF")
    rig.cmd("home", axes=("Y", "Z"))
    rig.step()
    sent = [rig.outputs.home_axes] + [axes for axes, _ in home_commands_until_idle(rig)]
    assert sent == [("Z",), ("Y",)]
    assert rig.ctl.referenced == {"X": False, "Y": True, "Z": True}
    assert rig.outputs.plc["ReferencedAxes"] == 0b110
    assert not rig.outputs.plc["AllReferenced"]


def home_commands_until_idle(rig: Rig, limit_s: float = 10.0) -> list:
    sent = []
    end = rig.k + int(limit_s / rig.dt)
    while rig.outputs.plc["HomingActive"]:
        assert rig.k < end
        rig.step()
        if rig.outputs.axis_command == "home":
            sent.append((rig.outputs.home_axes, dict(rig.ctl.referenced)))
    return sent


@pytest.mark.parametrize(
    "sequence",
    [
        (("Z",), ("X",)),
        (("Z",), ("X", "Y"), ("Y",)),
        (("Z", "Q"), ("X", "Y")),
        (("Z",), (), ("X", "Y")),
    ],
)
def test_a_bad_homing_sequence_is_refused_naming_it(sequence):
    with pytest.raises(ValueError, match="home_sequence .* must name each axis of X, Y, Z"):
        Rig(settings=ControllerSettings(home_sequence=sequence))


def test_an_estop_mid_sequence_drops_the_rest_of_it():
    rig = Rig()
    rig.step(10)
    rig.cmd("mode", mode="REF")
    rig.cmd("home")
    rig.until(lambda: rig.ctl.referenced["Z"], 5)
    rig.plc.out["EStopActive"] = True
    rig.plc_in = rig.plc.outputs()
    rig.step(50)
    assert not any(rig.ctl.referenced.values())
    assert not rig.outputs.plc["HomingActive"]


# --- the PLC's requests, answered by the NC (fake PLC: the test sets the PLC outputs) ---------


def request(rig: Rig, **signals) -> None:
    rig.plc.out.update(signals)
    rig.plc_in = rig.plc.outputs()
    rig.step()


def test_program_select_request_answers_done_and_drops_with_the_request():
    rig = Rig(programs={1000: SQUARE})
    rig.step(10)
    request(rig, ProgSelectReq=True, ProgSelectNumber=1000)
    out = rig.outputs.plc
    assert out["ProgSelectDone"] and not out["ProgSelectFail"] and out["ActiveProgram"] == 1000
    assert rig.ctl.selected == 1000 and rig.outputs.status.program == "O1000"
    rig.step(5)
    assert rig.outputs.plc["ProgSelectDone"], "held while the request is"
    request(rig, ProgSelectReq=False)
    assert not rig.outputs.plc["ProgSelectDone"]
    assert rig.outputs.plc["ActiveProgram"] == 1000


@pytest.mark.parametrize("number", [65535, 65536, 80000001, 99999999])
def test_eight_digit_o_numbers_are_selected_through_the_plc_words_and_by_command(number):
    """The O number crosses the PLC as 32 bits in two words, low word first (plc.signals)."""
    text = SQUARE.replace("O1000", f"O{number}")
    rig = Rig(programs={number: text, 1000: SQUARE})
    rig.step(10)
    low, high = dword_words(number)
    request(rig, ProgSelectReq=True, ProgSelectNumber=low, ProgSelectNumberHigh=high)
    out = rig.outputs.plc
    assert out["ProgSelectDone"] and not out["ProgSelectFail"], rig.ctl.events[-3:]
    assert dword_value(out["ActiveProgram"], out["ActiveProgramHigh"]) == number
    assert rig.ctl.selected == number and rig.outputs.status.program == f"O{number:04d}"
    request(rig, ProgSelectReq=False)
    rig.cmd("select_program", number=1000)
    rig.cmd("select_program", number=number)
    assert rig.ctl.selected == number


@pytest.mark.parametrize(
    ("number", "running", "code"),
    [
        (7, False, REFUSE_NOT_IN_MEMORY),
        (0, False, REFUSE_BAD_NUMBER),
        (100_000_000, False, REFUSE_BAD_NUMBER),
        (1000, True, REFUSE_PROGRAM_ACTIVE),
    ],
)
def test_program_select_refusals_have_their_code(number, running, code):
    rig = Rig(programs={1000: SQUARE, 1001: SQUARE.replace("O1000", "O1001")})
    rig.home()
    rig.cmd("select_program", number=1001)
    if running:
        rig.cmd("cycle_start")
        rig.step()
        assert rig.ctl.execution == "ACTIVE"
    low, high = dword_words(number)
    request(rig, ProgSelectReq=True, ProgSelectNumber=low, ProgSelectNumberHigh=high)
    out = rig.outputs.plc
    assert out["ProgSelectFail"] and not out["ProgSelectDone"]
    assert out["ProgSelectFailCode"] == code
    assert rig.ctl.selected == 1001, "a refused select leaves the selection"
    request(rig, ProgSelectReq=False)
    assert not rig.outputs.plc["ProgSelectFail"] and rig.outputs.plc["ProgSelectFailCode"] == 0


@pytest.mark.parametrize(
    ("mode", "enable", "already", "code"),
    [
        ("AUTO", True, False, REFUSE_NOT_REF_MODE),
        ("REF", False, False, REFUSE_NOT_ENABLED),
        ("REF", True, True, REFUSE_HOMING),
    ],
)
def test_zero_return_refusals_have_their_code(mode, enable, already, code):
    rig = Rig()
    rig.step(10)
    rig.cmd("mode", mode=mode)
    if already:
        rig.cmd("home")
        rig.step()
    if not enable:
        request(rig, AxisEnable=False)
        rig.until(lambda: not rig.ctl._enabled, 2)
    request(rig, HomeAllReq=True)
    out = rig.outputs.plc
    assert out["HomeFail"] and not out["HomeAck"] and out["HomeFailCode"] == code


def test_zero_return_request_homes_in_sequence_and_answers_taken():
    rig = Rig()
    rig.step(10)
    rig.cmd("mode", mode="REF")
    request(rig, HomeAllReq=True)
    assert rig.outputs.plc["HomeAck"] and rig.outputs.plc["HomingActive"]
    assert rig.outputs.home_axes == ("Z",)
    request(rig, HomeAllReq=False)
    assert not rig.outputs.plc["HomeAck"]
    sent = home_commands(rig)
    assert [axes for axes, _ in sent] == [("X", "Y")]
    assert rig.outputs.plc["AllReferenced"] and rig.outputs.plc["ReferencedAxes"] == 0b111


# --- through the real machine-tool PLC: the remote panel's markers to the NC and back ---------


def test_remote_panel_select_and_home_through_the_real_plc():
    rig = Rig(plc="real", programs={1000: SQUARE})
    rt = rig.plc.rt
    rig.step(50)
    # home all in AUTO: refused by the PLC, never reaches the NC
    rt.write_once("RemHomeAll", True)
    rig.step(10)
    assert rt.read("HomeRefused") and rt.read("HomeRefuseCode") == REFUSE_NOT_REF_MODE
    rt.write_once("RemHomeAll", False)
    rt.write_once("RemModeReq", MODE_REF)
    rig.until(lambda: rig.ctl.mode == "REF", 1)
    rig.step(10)
    rt.write_once("RemHomeAll", True)
    rig.until(lambda: rt.read("HomeAccepted"), 1)
    rt.write_once("RemHomeAll", False)
    rig.until(lambda: rt.read("AllReferenced") and not rt.read("HomingActive"), 10)
    assert rt.read("ReferencedAxes") == 0b111
    rt.write_once("RemModeReq", MODE_AUTO)
    rig.until(lambda: rig.ctl.mode == "AUTO", 1)
    # program select: not in memory, then in memory
    rt.write_once("RemProgNumber", 7)
    rt.write_once("RemProgSelect", True)
    rig.until(lambda: rt.read("ProgSelectRefused"), 1)
    assert rt.read("ProgRefuseCode") == REFUSE_NOT_IN_MEMORY
    rt.write_once("RemProgSelect", False)
    rig.until(lambda: not rt.read("ProgSelectRefused"), 1)
    rt.write_once("RemProgNumber", 1000)
    rt.write_once("RemProgSelect", True)
    rig.until(lambda: rt.read("ProgSelected"), 1)
    assert rt.read("ActiveProgram") == 1000 and rig.ctl.selected == 1000
    rt.write_once("RemProgSelect", False)
    rt.write_once("RemCycleStart", True)
    rig.until(lambda: rig.ctl.execution == "PROGRAM_COMPLETED", 60)
    assert rig.ctl.part_count == 1
    assert rt.alarms == {}
