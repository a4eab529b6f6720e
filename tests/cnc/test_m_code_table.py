"""The machine's M-code table from the NC's side: refused at the block when unknown, handed
to the real PLC program (with the table compiled in) and waited for, with its declared time."""

from __future__ import annotations

import pytest

from cnc.canon import AuxFunction
from cnc.config import builtin_machine
from cnc.errors import NcError
from cnc.interp import Interpreter
from plc.machine_io import machine_plc
from plc.runtime import RuntimeConfig
from tests.cnc.test_controller import RealPlc, Rig

MILL3 = builtin_machine("mill3")


def test_mill3_table_covers_the_haas_codes_of_the_corpus() -> None:
    # chip conveyor, through-spindle coolant, air gun, 4th-axis brake, user relays
    for code in (10, 11, 31, 33, 34, 35, 51, 61, 83, 84, 88, 89):
        assert code in MILL3.params.plc_m_codes
    assert 13 in MILL3.params.plc_m_codes  # the standard program's spindle + coolant


def test_interpreter_hands_table_codes_to_the_plc() -> None:
    cmds = list(Interpreter(MILL3.params).run("M31\nM88 M83\n"))
    assert [c.code for c in cmds if isinstance(c, AuxFunction)] == [31, 88, 83]


@pytest.mark.parametrize(
    ("text", "line", "col", "code"),
    [
        ("M31\nG0 X-10 M77\n", 2, 9, "M77"),
        ("M31 M262\n", 1, 5, "M262"),
        ("M32\n", 1, 1, "M32"),
    ],
)
def test_an_m_code_in_no_table_is_an_error_at_its_block(text, line, col, code) -> None:
    with pytest.raises(NcError, match=f"{code} is not an M code of this machine") as exc:
        list(Interpreter(MILL3.params).run(text))
    assert (exc.value.line, exc.value.col) == (line, col)


def test_a_machine_without_a_table_hands_any_m_code_on() -> None:
    lathe = builtin_machine("lathe2")
    assert lathe.params.plc_m_codes is None
    cmds = list(Interpreter(lathe.params).run("M77\n"))
    assert [c.code for c in cmds if isinstance(c, AuxFunction)] == [77]


class TablePlc(RealPlc):
    """The real program with mill3's M-code table compiled in; strobe/finish times kept."""

    def __init__(self) -> None:
        self.rt, self.io = machine_plc(RuntimeConfig(), m_functions=MILL3.plc.m_functions)
        self.rt.clock_ns = lambda: 0
        self.seen = []
        self._prev = {}
        self.edges: list[tuple[int, str, int]] = []  # (ms, "strobe"|"finish", M code)
        self._fin = False

    def scan(self, nc: dict, now_ms: int) -> None:
        if nc.get("MStrobe") and not self._prev.get("MStrobe"):
            self.edges.append((now_ms, "strobe", nc["MCode"]))
        super().scan(nc, now_ms)
        fin = bool(self.io.nc.outputs()["MFinish"])
        if fin and not self._fin:
            self.edges.append((now_ms, "finish", nc["MCode"]))
        self._fin = fin


PROGRAM = """%
O7000
G90 G0 X-50 Y-50 Z-20
M31
M88
G1 X-60 F1000
M89
M33
M30
%
"""


def test_table_functions_run_through_the_controller_and_the_real_plc() -> None:
    rig = Rig(plc="real", programs={7000: PROGRAM, 7001: "%\nO7001\nG0 X-10\nM77\nM30\n%\n"})
    rig.plc = TablePlc()
    rig.plc_in = rig.plc.outputs()
    rig.home()
    rig.run_program(7000, 60)
    assert rig.ex == "PROGRAM_COMPLETED", rig.ctl.alarms
    assert rig.ctl.alarms == ()
    assert [c for k, c in rig.plc.seen if k == "M"] == [31, 88, 89, 33, 30]
    times = {}
    for ms, kind, code in rig.plc.edges:
        times.setdefault(code, {})[kind] = ms
    # the NC waits for each finish: it comes the declared time after the strobe
    assert times[88]["finish"] - times[88]["strobe"] == 1500
    assert times[89]["finish"] - times[89]["strobe"] == 1000
    assert times[31]["finish"] - times[31]["strobe"] == 100
    assert rig.plc.rt.read("ChipConveyor") is False and rig.plc.rt.read("TscPump") is False
    # an M code in no table: a program alarm naming the block, nothing handed to the PLC
    before = len(rig.plc.seen)
    rig.run_program(7001, 30)
    assert rig.ex == "STOPPED"
    texts = [a.text for a in rig.ctl.alarms]
    assert any(":4:1: M77 is not an M code of this machine" in t for t in texts), texts
    assert [c for k, c in rig.plc.seen[before:] if k == "M"] == []
