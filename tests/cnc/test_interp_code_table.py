"""The declared G/M code table (cnc.interp.codes): its consistency, the docs rendered from
it, the word check, the order of execution, G54.1 P, and adding a code as one row."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from cnc.canon import Coolant, Dwell, Spindle, StraightTraverse, ToolChange, ToolSelect
from cnc.errors import NcError
from cnc.gcode.lexer import parse_line
from cnc.interp import Interpreter, codes, docgen
from cnc.params import AxisParams, MachineParams

BIG = tuple(AxisParams(a, -1000, 1000, 30000, 3000, 5e4) for a in "XYZ")
MILL = MachineParams(axes=BIG)
LATHE = MachineParams(
    kind="lathe",
    axes=(AxisParams("X", -500, 500, 1e4, 1e3, 1e4), AxisParams("Z", -500, 500, 1e4, 1e3, 1e4)),
)
DOC = Path(__file__).resolve().parents[2] / "docs" / "gcode.md"


def run(text: str, params: MachineParams = MILL) -> list:
    return list(Interpreter(params).run(text))


# --- the table --------------------------------------------------------------------------


@pytest.mark.parametrize("row", codes.CODES, ids=lambda r: f"{r.name}-{'-'.join(sorted(r.kinds))}")
def test_row_is_consistent(row: codes.Code) -> None:
    blk = parse_line(row.name, 1, "t")
    assert (blk.g if row.letter == "G" else blk.m) == [row.number]  # the lexer's number
    assert row.group in codes.GROUPS
    assert row.kinds and row.kinds <= codes.BOTH
    assert (row.handler is None) == bool(row.refused)
    if row.handler is not None:
        # handlers live in the family modules, never in the interpreter class
        assert row.handler.__module__.startswith("cnc.interp.")
        assert row.handler.__module__ != "cnc.interp.interpreter"
    for kind in row.kinds:
        for alt in row.needs_for(kind):
            assert alt and set(alt) <= row.words_for(kind)


@pytest.mark.parametrize("kind", ["mill", "lathe"])
def test_one_power_on_code_per_group_and_kind(kind: str) -> None:
    defaults: dict[str, list[str]] = {}
    for row in codes.CODES:
        if kind in row.kinds and row.default:
            defaults.setdefault(row.group, []).append(row.name)
    assert all(len(v) == 1 for v in defaults.values()), defaults
    interp = Interpreter(MILL if kind == "mill" else LATHE)
    state = interp.state.gcodes
    for group, (name,) in defaults.items():
        if group in state:
            assert state[group] == name, group


def test_every_step_has_a_doc_text_and_runs_in_order() -> None:
    assert [s.value for s in codes.Step] == list(range(len(codes.Step)))
    text = codes.render_order()
    assert text.index("M6") < text.index("M3/M4") < text.index("G4") < text.index("plane")


# --- the docs ---------------------------------------------------------------------------


def test_docs_tables_equal_the_table() -> None:
    text = DOC.read_text(encoding="utf-8")
    assert docgen.generated_sections(text) == ["g-codes", "m-codes", "order"]
    assert docgen.sync_docs(text) == text, (
        "docs/gcode.md differs from cnc/interp/codes.py: run python -m cnc.interp.docgen docs/gcode.md"
    )


def test_docs_check_notices_a_changed_row(monkeypatch) -> None:
    text = DOC.read_text(encoding="utf-8")
    g4 = next(r for r in codes.CODES if r.name == "G4")
    changed = tuple(dataclasses.replace(r, doc="pause") if r is g4 else r for r in codes.CODES)
    monkeypatch.setattr(codes, "CODES", changed)
    assert docgen.sync_docs(text) != text


# --- words ------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("prog", "line", "col", "fragment"),
    [
        ("G1 X10 R5 F100\n", 1, 8, "R word with no code in this block"),
        ("G0 X1 I2\n", 1, 7, "I word"),
        ("G0 X1\nY2 Q1\n", 2, 4, "Q word"),
        ("M3 P5 S100\n", 1, 4, "P word"),
        ("G28 X0 R1\n", 1, 8, "R word"),
        ("G90 G17 L2\n", 1, 9, "L word"),
        ("M98\n", 1, 1, "M98 needs P"),
        ("G10 P1 X0\n", 1, 1, "G10 needs L"),
        ("G4\n", 1, 1, "G4 needs P or X"),
        ("N5 G54.1 X1\n", 1, 4, "G54.1 needs P"),
        ("G54.1 P0\n", 1, 7, "P1..P48"),
        ("G54.1 P49\n", 1, 7, "P1..P48"),
        ("G54.1 P2.5\n", 1, 7, "P1..P48"),
        ("G7 X1\n", 1, 1, "unsupported G code G7"),
        ("G55 G54 X1\n", 1, 5, "modal group 'work_offset'"),
    ],
)
def test_word_and_code_refusals_name_line_and_column(prog, line, col, fragment) -> None:
    with pytest.raises(NcError) as ei:
        run(prog)
    assert fragment in ei.value.message
    assert (ei.value.line, ei.value.col) == (line, col)


@pytest.mark.parametrize(
    "prog",
    [
        "G0 X0 Y0 Z10\nG81 X5 Y5 Z-1 R2 F100\nX10 Y10 Q1 K2\nG80\n",  # the modal cycle's words
        "G43 Z5 H0\n",  # Z belongs to the modal G0
        "G0 X0 Y0\nG2 X10 Y0 R5 F100\nX20 Y0 I5 J0\n",  # the modal G2's centre words
        "G4 X1.5\n",
        "G64 P0.01\n",
        "G92 X0 Y0 S2000\n",
        "D1 H1\n",
        "G0 X0 Y0\nG2 X0 Y0 I5 P2 F100\n",
    ],
)
def test_words_a_code_uses_are_accepted(prog: str) -> None:
    run(prog)


def test_lathe_words() -> None:
    run("G4 U1.5\nG0 X20 Z5\nG1 U-2 W-3 F0.1 S100 M3\n", LATHE)
    with pytest.raises(NcError, match="unknown address J"):
        run("G0 X20 Z5\nG2 X10 Z0 J1\n", LATHE)
    with pytest.raises(NcError, match="Y word|lathe has no Y"):
        run("G90 X10 Y1 Z-5 F0.1\n", LATHE)  # the lathe turning cycle has no Y


# --- order of execution -----------------------------------------------------------------


def test_one_block_runs_in_the_standard_order() -> None:
    cmds = run("G4 P100 M8 M3 S1000 M6 T2\n")
    assert [type(c) for c in cmds] == [ToolSelect, ToolChange, Spindle, Coolant, Dwell]
    # G20 first: F10 and X1 are inches
    cmds = run("G1 X1 G20 F10\n")
    assert cmds[-1].feed == pytest.approx(254.0)
    assert cmds[-1].end[0] == pytest.approx(25.4)
    with pytest.raises(NcError, match="cannot share a block"):
        run("G4 P100 G1 X1 F10\n")  # G4's X is a time: no motion beside it


def test_stop_and_subprogram_come_after_the_motion() -> None:
    cmds = run("G0 X5 M0\n")
    assert type(cmds[0]) is StraightTraverse
    assert cmds[1].kind.name == "PROGRAM_STOP"


# --- G54.1 P1..P48 ----------------------------------------------------------------------


def test_g54_1_selects_the_extended_work_offset() -> None:
    interp = Interpreter(MILL)
    interp._wofs[6 + 3] = [100.0, 200.0, -50.0]  # slot 6+P (G10 L20 P3 writes it)
    cmds = list(interp.run("G54.1 P3 G0 X1 Y2 Z3\n"))
    assert cmds[-1].end == (101.0, 202.0, -47.0)
    assert interp.state.work_offset == "G54.1 P3"
    assert interp.state.gcodes["work_offset"] == "G54.1"
    list(interp.run("G54 G0 X1 Y2 Z3\n"))
    assert interp.state.work_offset == "G54"


# --- adding a code is one row and one handler ---------------------------------------------


def test_a_new_code_is_one_row(monkeypatch) -> None:
    seen = []

    def handler(ip, run) -> None:
        seen.append((run.g["nonmodal"], run.words["P"]))
        ip._emit(Dwell(run.line, run.words["P"]))

    row = codes.Code(
        "G7", "nonmodal", codes.MILL, codes.Step.DWELL, handler, words="P", needs=("P",)
    )
    monkeypatch.setattr(codes, "CODES", (*codes.CODES, row))
    codes.for_kind.cache_clear()
    try:
        cmds = run("G7 P2\n")
        assert seen == [(70, 2.0)] and isinstance(cmds[0], Dwell)
        with pytest.raises(NcError, match="G7 needs P"):
            run("G7\n")
        assert "| G7 | nonmodal (00) | mill | P | P |" in codes.render_g_table()
    finally:
        monkeypatch.undo()
        codes.for_kind.cache_clear()
    with pytest.raises(NcError, match="unsupported G code G7"):
        run("G7 P2\n")


def test_named_numbers_are_the_table_rows() -> None:
    from cnc.interp import gnum

    rows = {(r.name, r.number) for r in codes.CODES}
    names = {r.name for r in codes.CODES}
    for attr in dir(gnum):
        if attr[0] in "GM" and attr[1:2].isdigit() and attr != "M7_M8":
            name = attr.replace("_", ".")
            assert name in names, name
            assert (name, getattr(gnum, attr)) in rows, attr
