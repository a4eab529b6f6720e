"""Lexer: word-address format, comments, block delete, numbers, and where errors point."""

import pytest

from cnc.errors import NcError
from cnc.gcode import parse_line


def test_words_any_order_signs_leading_zeros() -> None:
    b = parse_line("N0010 X-010.5 G01 Y+.5 F0100", 7)
    assert b is not None and b.line == 7
    assert b.g == [10]
    assert b.words == {"N": 10.0, "X": -10.5, "Y": 0.5, "F": 100.0}


def test_lowercase_spaces_and_tabs() -> None:
    b = parse_line("g1\tx 10 y - 2.5", 1)
    assert b.g == [10] and b.words == {"X": 10.0, "Y": -2.5}


@pytest.mark.parametrize(
    ("text", "g"),
    [("G0", [0]), ("G00", [0]), ("G50.1", [501]), ("G51.1 G17", [511, 170]), ("G90.1", [901])],
)
def test_g_numbers_keep_decimal_subcodes(text: str, g: list[int]) -> None:
    assert parse_line(text, 1).g == g


def test_comments_paren_and_semicolon() -> None:
    b = parse_line("G1 (move (not nested X1) X2 ; rest Y9", 1)
    assert b.words == {"X": 2.0}


@pytest.mark.parametrize(
    ("text", "words"),
    [
        # '(' control out, ')' control in: the first ')' ends the comment (no nesting) and a
        # ')' outside a comment is a control-in with nothing to end, ignored as on the tape
        # reader (norn93-peck-pockets.nc line 12: a comment-only line)
        ("( Drilling hole at (61.045, 67.745) )", None),
        ("G1 X10 )", {"X": 10.0}),
        ("G1 (a (b) X2 ) Y3", {"X": 2.0, "Y": 3.0}),
        (")", None),
    ],
)
def test_a_control_in_outside_a_comment_is_ignored(text: str, words: dict | None) -> None:
    b = parse_line(text, 12)
    assert (b.words if b is not None else None) == words


def test_comment_only_and_blank_lines_are_none() -> None:
    assert parse_line("   ", 1) is None
    assert parse_line("(just a comment)", 1) is None
    assert parse_line("; remark", 1) is None


def test_tape_mark_block_delete_and_program_numbers() -> None:
    assert parse_line("%", 1).tape
    b = parse_line("/N20 G0 X1", 1)
    assert b.delete and b.words["X"] == 1.0
    assert parse_line("/2 X1", 1).delete
    assert parse_line("O1234 (MAIN)", 1).program == 1234
    assert parse_line(":0042", 1).program == 42
    assert parse_line("O80000001(MAIN)", 1).program == 80000001  # 8 digits (Fanuc option)
    assert parse_line("O410000", 1).program == 410000
    assert parse_line("O99999999", 1).program == 99999999


def test_least_increment_marks_words_without_point() -> None:
    b = parse_line("X25 Y25. Z2.5 F100", 1, least_increment=True)
    assert b.nopoint == {"X", "F"}
    assert parse_line("X25", 1).nopoint is None  # calculator style: nothing to scale


def test_text_after_a_leading_percent_is_skipped_as_fanuc_reads_a_tape() -> None:
    # Fanuc skips the data between the first '%' and the next LF: O1200 is not read.
    blk = parse_line("%O1200(TOKARKA)", 1, "p.nc")
    assert blk is not None and blk.tape and blk.program is None and not blk.words


@pytest.mark.parametrize(
    ("text", "col", "fragment"),
    [
        ("G1 X10 (open", 8, "unterminated comment"),
        ("O (MAIN)", 1, "PS0005 program number O needs digits"),
        (":(SOLVE FOR B)", 1, "PS0005 program number ':' (the ISO form of O) needs digits"),
        ("G1 X1.2.3", 4, "malformed number"),
        ("G1 X", 4, "without a value"),
        ("G01 X1/8", 7, "fractions not allowed"),
        ("G1 X10 $", 8, "unexpected character"),
        ("12 G1", 1, "without an address"),
        ("#1 = 10 X", 9, "PS0127"),
        ("G1 X[#1+2", 10, "PS0114 ']' expected"),
        ("IF [#1 GT 2] GOTO", 18, "PS0114 expression expected"),
        ("WHILE #1 LT 3 DO1", 7, "PS0125 WHILE needs a [condition]"),
        ("WHILE", 6, "PS0125 WHILE needs a [condition]"),
        ("GOTO 10 X1", 9, "PS0127"),
        ("X1 X2", 4, "appears twice"),
        ("G1 X1 % ", 7, "must stand alone"),
        ("G1.23 X1", 1, "unknown G code"),
        ("M3.5", 1, "malformed M code"),
        ("G1 O12", 4, "must start the block"),
        ("  O123456789", 3, "more than 8 digits (O1..O99999999)"),
        ("G1 X" + "9" * 40, 4, "out of range"),
        ("M" + "9" * 40, 1, "malformed M code"),
    ],
)
def test_errors_name_line_column_and_reason(text: str, col: int, fragment: str) -> None:
    with pytest.raises(NcError) as ei:
        parse_line(text, 12, "p.nc")
    err = ei.value
    assert (err.line, err.col, err.file) == (12, col, "p.nc")
    assert fragment in err.message
    assert str(err).startswith(f"p.nc:12:{col}: ")


def test_columns_survive_comments() -> None:
    with pytest.raises(NcError) as ei:
        parse_line("(abc) G1 X1 X2", 1)
    assert ei.value.col == 13
