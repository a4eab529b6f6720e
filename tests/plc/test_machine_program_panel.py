"""The remote operator panel's program select and home all (zero return) rungs, in lockstep.

The host holds a strobe at 1 until it reads the answer; the PLC passes the request to the NC
on the strobe's rising edge, holds it until the NC answers (done / refused with a code) and
raises alarm 1050 / 1051 when the NC stays silent for 1 s. Here the NC is played by the test
through the NcPort, so every answer lands on an exact scan."""

from __future__ import annotations

import pytest

from plc.signals import (
    MODE_AUTO,
    MODE_REF,
    REFUSE_ABORTED,
    REFUSE_BAD_NUMBER,
    REFUSE_ESTOP,
    REFUSE_NO_ANSWER,
    REFUSE_NOT_ENABLED,
    REFUSE_NOT_IN_MEMORY,
    REFUSE_NOT_REF_MODE,
    REFUSE_PROGRAM_ACTIVE,
    dword_value,
    dword_words,
)
from tests.plc.test_machine_program import PERIOD, Plc


@pytest.fixture
def plc() -> Plc:
    p = Plc()
    p.ready()
    return p


def select(plc: Plc, number: int | tuple[int, int]) -> None:
    """Write the O number (or raw (low, high) words) and raise the strobe."""
    low, high = dword_words(number) if isinstance(number, int) else number
    plc.rt.write_once("RemProgNumber", low)
    plc.rt.write_once("RemProgNumberHigh", high)
    plc.rt.write_once("RemProgSelect", True)


def selected_number(plc: Plc) -> int:
    return dword_value(plc.nc.get("ProgSelectNumber"), plc.nc.get("ProgSelectNumberHigh"))


def home(plc: Plc) -> None:
    plc.rt.write_once("RemHomeAll", True)


def select_answer(plc: Plc) -> tuple[bool, bool, int]:
    return (plc.read("ProgSelected"), plc.read("ProgSelectRefused"), plc.read("ProgRefuseCode"))


def home_answer(plc: Plc) -> tuple[bool, bool, int]:
    return (plc.read("HomeAccepted"), plc.read("HomeRefused"), plc.read("HomeRefuseCode"))


# --- program select ------------------------------------------------------------------------


def test_program_select_is_passed_to_the_nc_and_its_answer_held_while_the_strobe_is(plc):
    select(plc, 1234)
    plc.scan()
    # the request goes to the NC with the number; no answer yet
    assert plc.nc.get("ProgSelectReq") and selected_number(plc) == 1234
    assert select_answer(plc) == (False, False, 0)
    assert plc.read("RemProgSelect"), "the strobe is the host's: the PLC leaves it"
    plc.nc.set("ProgSelectDone", True)
    plc.nc.set("ActiveProgram", 1234)
    plc.scan()
    assert select_answer(plc) == (True, False, 0)
    assert not plc.nc.get("ProgSelectReq"), "the request drops with the NC's answer"
    plc.nc.set("ProgSelectDone", False)  # the NC drops its answer with the request
    plc.run(5 * PERIOD)
    assert select_answer(plc) == (True, False, 0), "held while the strobe is 1"
    assert not plc.nc.get("ProgSelectReq"), "one request per rising edge of the strobe"
    plc.rt.write_once("RemProgSelect", False)
    plc.scan()
    assert select_answer(plc) == (False, False, 0)
    assert plc.rt.alarms == {}


@pytest.mark.parametrize(
    ("in_cycle", "number", "nc_code", "code", "passed_to_nc"),
    [
        (True, 100, None, REFUSE_PROGRAM_ACTIVE, False),  # the PLC's own interlock
        (False, 0, None, REFUSE_BAD_NUMBER, False),  # O0
        (False, (0, 1526), None, REFUSE_BAD_NUMBER, False),  # high word above O99999999's
        (False, (5, -1), None, REFUSE_BAD_NUMBER, False),  # high word 0xFFFF
        (False, 7, REFUSE_NOT_IN_MEMORY, REFUSE_NOT_IN_MEMORY, True),  # the NC's answer
        (False, 7, REFUSE_PROGRAM_ACTIVE, REFUSE_PROGRAM_ACTIVE, True),
        (False, 10000, REFUSE_NOT_IN_MEMORY, REFUSE_NOT_IN_MEMORY, True),  # 5 digits
        (False, 80000001, REFUSE_NOT_IN_MEMORY, REFUSE_NOT_IN_MEMORY, True),  # 8 digits
        # high word 1525 passes the PLC's coarse test; the NC refuses the exact range
        (False, 100_000_000, REFUSE_BAD_NUMBER, REFUSE_BAD_NUMBER, True),
    ],
)
def test_program_select_refusals(plc, in_cycle, number, nc_code, code, passed_to_nc):
    plc.nc.set("NcInCycle", in_cycle)
    select(plc, number)
    plc.scan()
    assert plc.nc.get("ProgSelectReq") is passed_to_nc
    if passed_to_nc:
        assert selected_number(plc) == number, "both words reach the NC"
        plc.nc.set("ProgSelectFail", True)
        plc.nc.set("ProgSelectFailCode", nc_code)
        plc.scan()
    assert select_answer(plc) == (False, True, code)
    assert not plc.nc.get("ProgSelectReq")
    assert plc.rt.alarms == {}, "a refusal is an answer, not an alarm"


def test_a_silent_nc_is_alarm_1050_and_a_refusal_after_exactly_one_second(plc):
    select(plc, 55)
    t0 = plc.now
    t = plc.until(lambda: plc.read("ProgSelectRefused"), 2000)
    assert t - t0 == 1000
    assert select_answer(plc) == (False, True, REFUSE_NO_ANSWER)
    assert not plc.nc.get("ProgSelectReq")
    assert 1050 in plc.rt.alarms and plc.nc.get("PlcAlarm")
    assert plc.nc.get("PlcAlarmNumber") == 1050
    # cleared by reset (the cause, a silent handshake, is gone)
    plc.rt.write_once("RemProgSelect", False)
    plc.rt.write_once("RemReset", True)
    plc.scan()
    plc.scan()
    assert plc.rt.alarms == {} and not plc.nc.get("PlcAlarm")


def test_a_reset_aborts_a_pending_program_select_with_an_answer(plc):
    select(plc, 55)
    plc.scan()
    assert plc.nc.get("ProgSelectReq")
    plc.rt.write_once("RemReset", True)
    plc.scan()
    assert select_answer(plc) == (False, True, REFUSE_ABORTED)
    assert not plc.nc.get("ProgSelectReq")


def test_a_new_select_after_the_strobe_dropped_clears_the_old_answer(plc):
    plc.nc.set("NcInCycle", True)
    select(plc, 100)
    plc.scan()
    assert select_answer(plc) == (False, True, REFUSE_PROGRAM_ACTIVE)
    plc.rt.write_once("RemProgSelect", False)
    plc.scan()
    plc.nc.set("NcInCycle", False)
    select(plc, 100)
    plc.scan()
    assert select_answer(plc) == (False, False, 0) and plc.nc.get("ProgSelectReq")


# --- home all (zero return) ------------------------------------------------------------------


def test_home_all_in_ref_mode_is_passed_to_the_nc(plc):
    plc.nc.set("NcMode", MODE_REF)
    home(plc)
    plc.scan()
    assert plc.nc.get("HomeAllReq") and home_answer(plc) == (False, False, 0)
    plc.nc.set("HomeAck", True)
    plc.nc.set("HomingActive", True)
    plc.scan()
    assert home_answer(plc) == (True, False, 0) and not plc.nc.get("HomeAllReq")
    plc.nc.set("HomeAck", False)
    plc.run(3 * PERIOD)
    assert not plc.nc.get("HomeAllReq"), "one request per rising edge of the strobe"
    plc.rt.write_once("RemHomeAll", False)
    plc.scan()
    assert home_answer(plc) == (False, False, 0)


@pytest.mark.parametrize(
    ("mode", "estop", "nc_code", "code", "passed_to_nc"),
    [
        (MODE_AUTO, False, None, REFUSE_NOT_REF_MODE, False),  # effective in REF only
        (MODE_REF, True, None, REFUSE_ESTOP, False),
        (MODE_AUTO, True, None, REFUSE_ESTOP, False),
        (MODE_REF, False, REFUSE_NOT_ENABLED, REFUSE_NOT_ENABLED, True),  # the NC's answer
    ],
)
def test_home_all_refusals(plc, mode, estop, nc_code, code, passed_to_nc):
    plc.nc.set("NcMode", mode)
    if estop:
        plc.io.press_estop()
        plc.scan()
        assert plc.nc.get("EStopActive")
    home(plc)
    plc.scan()
    assert plc.nc.get("HomeAllReq") is passed_to_nc
    if passed_to_nc:
        plc.nc.set("HomeFail", True)
        plc.nc.set("HomeFailCode", nc_code)
        plc.scan()
    assert home_answer(plc) == (False, True, code)
    assert not plc.nc.get("HomeAllReq")


def test_a_silent_nc_is_alarm_1051_after_exactly_one_second(plc):
    plc.nc.set("NcMode", MODE_REF)
    home(plc)
    t0 = plc.now
    t = plc.until(lambda: plc.read("HomeRefused"), 2000)
    assert t - t0 == 1000
    assert home_answer(plc) == (False, True, REFUSE_NO_ANSWER)
    assert 1051 in plc.rt.alarms and plc.nc.get("PlcAlarmNumber") == 1051


def test_an_estop_aborts_a_pending_home_all(plc):
    plc.nc.set("NcMode", MODE_REF)
    home(plc)
    plc.scan()
    assert plc.nc.get("HomeAllReq")
    plc.io.press_estop()
    plc.scan()
    assert home_answer(plc) == (False, True, REFUSE_ABORTED)
    assert not plc.nc.get("HomeAllReq")


# --- the same handshakes through the real Modbus face and RemotePanel ------------------------


class PlayedNc:
    """The NC's side of the two handshakes, answered in the scan after the request."""

    def __init__(self, plc: Plc, memory: set[int]) -> None:
        self.plc, self.memory = plc, memory

    def scan(self) -> None:
        nc, plc = self.plc.nc, self.plc
        req = nc.get("ProgSelectReq")
        number = dword_value(nc.get("ProgSelectNumber"), nc.get("ProgSelectNumberHigh"))
        nc.set("ProgSelectDone", req and number in self.memory)
        nc.set("ProgSelectFail", req and number not in self.memory)
        nc.set(
            "ProgSelectFailCode", REFUSE_NOT_IN_MEMORY if req and number not in self.memory else 0
        )
        if req and number in self.memory:
            low, high = dword_words(number)
            nc.set("ActiveProgram", low)
            nc.set("ActiveProgramHigh", high)
        nc.set("HomeAck", nc.get("HomeAllReq"))
        if nc.get("HomeAllReq"):
            nc.set("AllReferenced", True)
            nc.set("ReferencedAxes", 0b111)
        plc.scan()


@pytest.fixture
def panel(plc):
    from pymodbus.client import ModbusTcpClient

    from plc.modbus import ModbusFace
    from plc.remote_panel import WRITABLE, RemotePanel

    face = ModbusFace(
        lambda: plc.rt.snapshot, plc.rt.writes, plc.rt.image.size, port=0, writable=WRITABLE
    )
    face.start_in_thread()
    client = ModbusTcpClient("127.0.0.1", port=face.bound_port, timeout=3)
    assert client.connect()
    nc = PlayedNc(plc, {1234, 65535, 80000001})
    # every poll of the panel's handshake is one PLC scan: lockstep through a real socket
    yield RemotePanel(client, sleep=lambda _s: nc.scan())
    client.close()
    face.stop_thread()


def test_remote_panel_program_select_over_modbus(plc, panel):
    from plc.remote_panel import PanelRefused

    panel.select_program(1234)
    assert plc.nc.get("ActiveProgram") == 1234
    assert panel.nc_state()["ActiveProgram"] == 1234
    with pytest.raises(PanelRefused, match=r"O0007 refused: program not in memory \(code 1\)"):
        panel.select_program(7)
    with pytest.raises(ValueError, match="O0 outside O1..O99999999"):
        panel.select_program(0)  # refused before anything is written
    # 8 digits: 32 bits in holding registers 1028 (low) and 1029 (high), read back the same way
    panel.select_program(80000001)
    assert panel.nc_state()["ActiveProgram"] == 80000001
    assert panel.client.read_holding_registers(1028, count=2).registers == [0xB401, 0x04C4]
    # a host that writes only register 1028 (and leaves 1029 at 0) selects up to O65535
    panel.client.write_register(1029, 0)
    panel.client.write_register(1028, 65535)
    raw_select = ("RemProgSelect", "ProgSelected", "ProgSelectRefused", "ProgRefuseCode")
    panel._handshake(*raw_select, "select by register 1028 alone", 5.0)
    assert panel.nc_state()["ActiveProgram"] == 65535
    # the PLC refuses a high word no O number has, with code 3
    panel.client.write_registers(1028, [0, 1526])
    with pytest.raises(PanelRefused, match="outside 1..99999999") as refused:
        panel._handshake(*raw_select, "select O1526*65536", 5.0)
    assert refused.value.code == REFUSE_BAD_NUMBER
    # the strobe is down after each handshake (the write lands in the next scan)
    plc.scan()
    assert not plc.read("RemProgSelect") and not plc.read("ProgSelectRefused")


def test_remote_panel_clears_a_strobe_left_up_by_an_earlier_host(plc, panel):
    plc.rt.write_once("RemProgNumber", 1234)
    plc.rt.write_once("RemProgSelect", True)
    plc.run(5 * PERIOD)
    plc.nc.set("ProgSelectDone", False)  # the old request was answered long ago
    assert plc.read("RemProgSelect")
    from plc.remote_panel import PanelRefused

    with pytest.raises(PanelRefused, match="not in memory"):
        panel.select_program(8)  # the old "selected" answer is not taken for this one


def test_remote_panel_home_all_over_modbus(plc, panel):
    from plc.remote_panel import PanelRefused

    with pytest.raises(PanelRefused, match=r"home all refused: mode is not REF \(code 5\)"):
        panel.home_all()
    plc.nc.set("NcMode", MODE_REF)
    panel.home_all()
    assert panel.referenced() == {
        "X": True,
        "Y": True,
        "Z": True,
        "A": False,
        "B": False,
        "C": False,
    }
    assert panel.nc_state()["AllReferenced"]


def test_answers_are_not_writable_by_the_host(plc, panel):
    from plc.remote_panel import ANSWER_COILS, ANSWER_REGISTERS, COMMAND_COILS

    client = panel.client
    assert client.write_coil(ANSWER_COILS["ProgSelected"], True).isError()
    assert client.write_register(ANSWER_REGISTERS["HomeRefuseCode"], 1).isError()
    assert not client.write_coil(COMMAND_COILS["RemHomeAll"], False).isError()
