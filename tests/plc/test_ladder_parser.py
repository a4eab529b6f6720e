"""Parser and checker: the tree, comments, and every error at its exact line and column."""

from __future__ import annotations

import pytest

from plc.ladder import LadderError, check_text, compile_text, format_program, parse_program
from plc.ladder.ast import Branch, Instr

HEAD = "TAG A : BOOL AT %IX0.0\nTAG Q : BOOL AT %QX0.0\nTAG W : INT AT %MW0\nTAG T : TIMER\n"


def test_parse_tree_comments_and_continuation():
    text = (
        "PROGRAM demo\n"
        "TAG Start : BOOL AT %IX0.0   // start button\n"
        "TAG Hold : BOOL AT %I0.1\n"
        "TAG Run : BOOL RETAIN\n"
        "\n"
        "// seal-in of the cycle\n"
        "// second line\n"
        "SOR BST XIC Start NXB XIC Run BND \\\n"
        "    xio Hold OTE Run EOR  // trailing\n"
    )
    program, sink = parse_program(text, "d.ld")
    assert not sink.items
    assert program.name == "demo"
    assert [t.name for t in program.tags] == ["Start", "Hold", "Run"]
    assert program.tags[0].comment == "start button" and program.tags[2].retain
    (rung,) = program.rungs
    assert rung.line == 8 and rung.comment == "seal-in of the cycle\nsecond line\ntrailing"
    branch, xio, ote = rung.elements
    assert isinstance(branch, Branch) and len(branch.legs) == 2
    assert isinstance(xio, Instr) and xio.mnemonic == "XIO" and (xio.line, xio.col) == (9, 5)
    assert ote.operands[0].text == "Run"


def test_format_round_trip():
    text = HEAD + "XIC A BST XIO Q NXB GRT W 5 BND TON T T#1s\nXIC T.DN OTE Q\n"
    program, _ = parse_program(text, "r.ld")
    again, sink = parse_program(format_program(program), "r.ld")
    assert not sink.items
    assert format_program(again) == format_program(program)
    assert compile_text(format_program(program), "r2.ld").tags["T"].type == "TIMER"


ERRORS = [
    # (rung text, line, col, message fragment); the rung is on line 5
    ("XIC A FOO Q", 5, 7, "unknown instruction 'FOO'"),
    ("XIC Nope OTE Q", 5, 5, "undeclared tag 'Nope'"),
    ("XIC A OTE W", 5, 11, "a word where a bit is needed"),
    ("EQU A 3 OTE Q", 5, 5, "a bit where a word is needed"),
    ("EQU %IX0.1 3 OTE Q", 5, 5, "a bit where a word is needed"),
    ("MOV 3 %IX0.0", 5, 7, "a bit where a word is needed"),
    ("XIC A OTE %IX0.1", 5, 11, "cannot write the input"),
    ("MOV 1 %IW2", 5, 7, "cannot write the input"),
    ("XIC A BST XIC Q NXB XIO Q OTE Q", 5, 7, "never closed (BND missing)"),
    ("XIC A NXB XIC Q OTE Q", 5, 7, "NXB outside a branch"),
    ("XIC A BND OTE Q", 5, 7, "BND outside a branch"),
    ("BST XIC A BND OTE Q", 5, 1, "single leg"),
    ("BST XIC A NXB NXB XIC Q BND OTE Q", 5, 15, "empty branch leg"),
    ("XIC A OTE", 5, 7, "OTE expects 1 operand(s), the rung ends"),
    ("XIC OTE Q", 5, 5, "XIC expects 1 operand(s), found 'OTE'"),
    ("XIC A TON T", 5, 7, "TON expects 2 operand(s)"),
    ("XIC A", 5, 1, "rung has no output instruction"),
    ("XIC A OTE Q XIC A", 5, 13, "rung ends with the input instruction XIC"),
    ("XIC A TON W 100", 5, 11, "needs a TIMER tag here, got INT tag 'W'"),
    ("XIC T OTE Q", 5, 5, "use a member such as .DN"),
    ("XIC T.XX OTE Q", 5, 5, "TIMER has no member .XX"),
    ("XIC A OTE T.DN", 5, 11, "written by the timer instruction only"),
    ("XIC A MOV 4 T.PRE", 5, 13, "set the preset through the instruction's operand"),
    ("XIC A MOV 40000 W", 5, 11, "does not fit INT"),
    ("XIC A TON T T#5x", 5, 13, "malformed time literal"),
    ("XIC %IX0.8 OTE Q", 5, 5, "bit number 8"),
    ("XIC %IX200.0 OTE Q", 5, 5, "outside the image"),
    ("XIC %QW1.2 OTE Q", 5, 5, "takes no .bit"),
    ("XIC A OTE Q $", 5, 13, "unexpected characters '$'"),
    ("XIC A JMP nowhere", 5, 11, "undefined label NOWHERE"),
    ("XIC A LBL x OTE Q", 5, 7, "LBL must be the first instruction"),
    ("3 OTE Q", 5, 1, "expected an instruction, found '3'"),
]


@pytest.mark.parametrize("rung, line, col, fragment", ERRORS)
def test_errors_point_at_line_and_column(rung, line, col, fragment):
    diags = check_text(HEAD + rung + "\n", "bad.ld")
    errors = [d for d in diags if d.severity == "error"]
    assert errors, f"no error for {rung!r}"
    assert any(d.line == line and d.col == col and fragment in d.message for d in errors), [
        str(d) for d in errors
    ]
    with pytest.raises(LadderError) as info:
        compile_text(HEAD + rung + "\n", "bad.ld")
    assert str(info.value).startswith("bad.ld:")


TAG_ERRORS = [
    ("TAG A : BOOL", 5, 5, "already declared on line 1"),
    ("TAG X : BOOL AT %IW3", 5, 17, "needs a bit address"),
    ("TAG X : INT AT %QX0.3", 5, 16, "needs a word address"),
    ("TAG X : TIMER AT %MW4", 5, 18, "cannot be located"),
    ("TAG X : REAL", 5, 9, "expected a type"),
    ("TAG X BOOL", 5, 7, "expected ':'"),
    ("TAG XIC : BOOL", 5, 5, "is a keyword"),
    ("TAG S_OVERFLOW : BOOL", 5, 5, "system tag"),
    ("TAG X : INT := 70000", 5, 5, "does not fit INT"),
    ("TAG X : BOOL AT", 5, 16, "AT needs an address"),
    ("TAG X : BOOL RETAIN FOO", 5, 21, "unexpected 'FOO'"),
]


@pytest.mark.parametrize("decl, line, col, fragment", TAG_ERRORS)
def test_tag_table_errors(decl, line, col, fragment):
    diags = check_text(HEAD + decl + "\nXIC A OTE Q\n", "tags.ld")
    assert any(d.line == line and d.col == col and fragment in d.message for d in diags), [
        str(d) for d in diags
    ]


def test_backward_jump_refused():
    diags = check_text(HEAD + "LBL top XIC A OTE Q\nXIC A JMP top\n", "j.ld")
    (err,) = [d for d in diags if d.severity == "error"]
    assert (err.line, err.col) == (6, 11) and "backward JMP" in err.message


def test_duplicate_label():
    diags = check_text(HEAD + "XIC A JMP L\nLBL L XIC A OTE Q\nLBL L XIC A OTL Q\n", "l.ld")
    assert any("label L already defined on line 6" in d.message and d.line == 7 for d in diags)


def test_warnings_do_not_stop_compilation():
    text = (
        HEAD
        + "TAG B : BOOL AT %QX0.0\nXIC A OTE Q\nXIO A OTE %QX0.0\nXIC A TON T 5\nXIC A TON T 9\n"
    )
    program = compile_text(text, "w.ld")
    messages = [str(w) for w in program.warnings]
    assert any("w.ld:5:17: warning: %QX0.0 is also the address of tag 'Q'" in m for m in messages)
    assert any(
        ":7:11: warning: duplicate output: %QX0.0 is also written by OTE on line 6" in m
        for m in messages
    )
    assert any(":9:11: warning: T is also driven by TON on line 8" in m for m in messages)


def test_many_errors_reported_at_once():
    diags = check_text(HEAD + "XIC Nope OTE Q\nFOO\nXIC A OTE W\n", "m.ld")
    assert [(d.line, d.col) for d in diags if d.severity == "error"] == [(5, 5), (6, 1), (7, 11)]


def test_watchdog_estimate():
    text = HEAD + "XIC A OTL Q\n" * 50
    assert any(
        "exceeds the watchdog" in d.message and d.severity == "error"
        for d in check_text(text, "big.ld", watchdog_ms=0.001)
    )
    assert any(
        "over half the watchdog" in d.message and d.severity == "warning"
        for d in check_text(text, "big.ld", watchdog_ms=0.02)
    )
    assert not check_text(text, "big.ld", watchdog_ms=100.0)[1:]


def test_case_insensitive_names_and_hex_literals():
    text = "TAG Motor : BOOL AT %QX0.0\nTAG w : INT\nxic MOTOR ote motor\nXIC motor MOV 16#7F W\n"
    program = compile_text(text, "c.ld")
    assert program.tag("MOTOR").area == "QX" and "127" in program.python_source


def test_alarm_is_a_valid_tag_name():
    text = 'TAG Alarm : BOOL AT %QX0.0\nALARM 7 Alarm "latched alarm"\nXIC %IX0.0 OTL Alarm\n'
    program = compile_text(text, "al.ld")
    assert program.alarms[0].number == 7 and program.alarms[0].area == "QX"
    again, sink = parse_program(format_program(parse_program(text, "al.ld")[0]), "al.ld")
    assert not sink.items and again.alarms[0].text == "latched alarm"
