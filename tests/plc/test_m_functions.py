"""The M-code table (plc.m_functions) compiled into the real machine-tool PLC program.

Lockstep: the Runtime scans every 10 ms of virtual time; a table function finishes its
declared time after the strobe (never before the program's 50 ms check delay), switches
its bit, and a code in no table is still alarm 1021, never finished.
"""

from __future__ import annotations

import pytest

from plc.ladder import parse_program
from plc.ladder.ast import format_elements
from plc.m_functions import MFunction, MTableError, section_text, table_from, with_m_functions
from plc.machine_io import PROGRAM_PATH, machine_plc
from tests.plc.test_machine_program import Plc

TABLE = (
    MFunction(31, 100, "chip conveyor forward", sets="ChipConveyor"),
    MFunction(33, 100, "chip conveyor stop", clears="ChipConveyor"),
    MFunction(88, 1500, "through-spindle coolant on", sets="TscPump"),
    MFunction(40, 0, "no time of its own"),
)


class TablePlc(Plc):
    def __init__(self, table) -> None:
        super().__init__()
        self.rt, self.io = machine_plc(m_functions=table)
        self.rt.clock_ns = lambda: 0
        self.nc = self.io.nc


@pytest.fixture
def plc() -> TablePlc:
    p = TablePlc(TABLE)
    p.ready()
    return p


@pytest.mark.parametrize(("code", "ms"), [(31, 100), (88, 1500), (40, 50)])
def test_a_table_function_finishes_after_its_declared_time(plc, code, ms):
    # ms 0: the finish waits for the program's own 50 ms check delay (MSettle)
    assert plc.function("M", code) == ms
    assert plc.rt.alarms == {}


def test_table_functions_switch_their_bits(plc):
    assert plc.read("ChipConveyor") is False
    plc.function("M", 31)
    assert plc.read("ChipConveyor") is True
    plc.function("M", 33)
    assert plc.read("ChipConveyor") is False
    plc.function("M", 88)
    assert plc.read("TscPump") is True


def test_a_code_in_no_table_is_still_alarm_1021(plc):
    plc.strobe("M", 77)
    plc.run(2000)
    assert 1021 in plc.rt.alarms and not plc.nc.get("MFinish")


def test_standard_functions_keep_their_timing_with_a_table(plc):
    # M9 finishes after the check delay, as without a table
    assert plc.function("M", 9) == 50


def test_without_a_table_a_table_code_is_unknown():
    p = Plc()
    p.ready()
    p.strobe("M", 31)
    p.run(500)
    assert 1021 in p.rt.alarms


def test_the_section_is_plain_ladder_of_the_table():
    text = section_text(TABLE[:2])
    assert "XIC MStrobe EQU MCode 31 TON TmrM31 100" in text
    assert "XIC MStrobe EQU MCode 31 OTL ChipConveyor" in text
    assert "XIC MStrobe EQU MCode 33 OTU ChipConveyor" in text
    assert "BST EQU MCode 31 NXB EQU MCode 33 BND OTE MTabKnown" in text


def test_table_runs_before_the_m_decode_rungs():
    with open(PROGRAM_PATH, encoding="utf-8") as f:
        program, _ = parse_program(f.read(), PROGRAM_PATH)
    n = len(program.rungs)
    merged = with_m_functions(program, TABLE)
    assert [r.number for r in merged.rungs] == list(range(len(merged.rungs)))
    # 4 timers, 3 bits set or cleared, MTabKnown, MTabDone
    assert len(merged.rungs) == n + 9
    slot = next(i for i, r in enumerate(merged.rungs) if r.comment and "@m-functions" in r.comment)
    decode = format_elements(merged.rungs[slot].elements)
    assert decode.startswith("XIC MStrobe ONS MStrobeOs")  # the M decode, after the table
    assert format_elements(merged.rungs[slot - 1].elements).endswith("OTE MTabDone")
    assert format_elements(merged.rungs[slot - 2].elements).endswith("OTE MTabKnown")


def test_a_program_without_the_slot_is_refused():
    program, _ = parse_program("PROGRAM p\nTAG A : BOOL\nXIC A OTE A\n", "p.ld")
    with pytest.raises(MTableError, match="no '// @m-functions' comment line"):
        with_m_functions(program, TABLE)


@pytest.mark.parametrize(
    ("entries", "where", "message"),
    [
        ({3: {"ms": 10}}, "m_codes.3", "M3 is handled by the NC or the standard PLC program"),
        ({19: {}}, "m_codes.19", "handled by the NC"),
        ({10000: {}}, "m_codes.10000", "0..9999"),
        ({31: {"ms": 30000}}, "m_codes.31.ms", "0..29000 ms"),
        ({31: {"ms": 1.5}}, "m_codes.31.ms", "an integer"),
        ({31: {"sets": "2bad"}}, "m_codes.31.sets", "not a PLC tag name"),
    ],
)
def test_bad_table_entries(entries, where, message):
    with pytest.raises(MTableError, match=message) as exc:
        table_from(entries)
    assert exc.value.where == where
