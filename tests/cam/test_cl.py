"""CL data: reader and writer round-trip exactly, stream, and police tool-axis vectors."""

from __future__ import annotations

import io
import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from cam.cl import LINE_WIDTH, ClRecord, format_record, read_cl, write_cl
from cam.errors import CamError

TABLE1 = [
    (20, 0, -155, 0.6327447124, 0.465569252, 0.6187742456),
    (100, 0, -150, 0.628284235, 0.461387437, 0.62640867),
    (200, 0, -146, 0.623829809, 0.457180279, 0.634039219),
    (300, 0, -139, 0.618938519, 0.452948814, 0.6416794216),
]


def table1_cl() -> str:
    return "MULTAX/ON\n" + "".join("GOTO/" + ",".join(str(v) for v in p) + "\n" for p in TABLE1)


def test_table1_parses_and_normalises_with_warnings() -> None:
    warnings: list = []
    recs = list(read_cl(table1_cl(), "t1.cl", warnings.append))
    assert [r.word for r in recs] == ["MULTAX", "GOTO", "GOTO", "GOTO", "GOTO"]
    for r, p in zip(recs[1:], TABLE1, strict=True):
        assert r.args[:3] == p[:3]
        assert math.sqrt(sum(v * v for v in r.args[3:])) == pytest.approx(1, abs=1e-9)
    # P3 is |v| = 1.0000916: accepted, normalised, with its line; P4 (|v| - 1 = -7e-10)
    # is unit length as far as 10 printed digits go and is kept as written
    assert [w.line for w in warnings] == [2, 3, 4]
    assert recs[4].args[3:] == TABLE1[3][3:]
    assert "1.0000915" in warnings[2].message


@pytest.mark.parametrize(
    ("text", "line", "why"),
    [
        ("GOTO/1,2,3,0,0,1.002", 1, "not a unit vector"),
        ("FROM/0,0,0\nGOTO/1,2,3,0,0,0", 2, "not a unit vector"),
        ("GOTO/1,2", 1, "needs 3 or 6 numbers"),
        ("GOTO/1,2,X", 1, "numbers only"),
        ("GOTO/1,,2", 1, "empty argument"),
        ("GOTO/1,2,nan", 1, "numbers only"),
        ("GOTO/1,2,1e999", 1, "not a finite number"),
        ("CIRCLE/1,2,3,0,0,1", 1, "7 numbers"),
        ("12/3", 1, "not a CL major word"),
        ("RAPID\nGOTO/1,$\n2,$\n", 2, "past the end"),
        ("TLAXIS/0,0,2", 1, "not a unit vector"),
    ],
)
def test_bad_records_are_refused_with_their_line(text: str, line: int, why: str) -> None:
    with pytest.raises(CamError) as ei:
        list(read_cl(text, "bad.cl"))
    assert ei.value.line == line and ei.value.file == "bad.cl" and why in ei.value.message


def test_continuation_comments_and_text_records() -> None:
    text = "PARTNO  BRACKET $$ not a comment here\n$$ a comment\n\nGOTO/1.0,$\n  2.0,$\n 3.0 $$ end\nPPRINT/HELLO, WORLD\nFINI\n"
    recs = list(read_cl(text))
    assert recs == [
        ClRecord("PARTNO", (), " BRACKET $$ not a comment here"),
        ClRecord("GOTO", (1.0, 2.0, 3.0)),
        ClRecord("PPRINT", (), "HELLO, WORLD"),
        ClRecord("FINI"),
    ]
    assert [r.line for r in recs] == [1, 4, 7, 8]


def test_long_records_continue_with_dollar() -> None:
    rec = ClRecord("GOTO", (123.456789012345,) * 3 + (0.5773502691896258,) * 3)
    lines = format_record(rec)
    assert len(lines) > 1 and all(len(x) <= LINE_WIDTH for x in lines)
    assert all(x.endswith("$") for x in lines[:-1])
    assert list(read_cl("\n".join(lines))) == [rec]


def test_reader_streams() -> None:
    pulled = 0

    def lines():
        nonlocal pulled
        for i in range(1_000_000):
            pulled += 1
            yield f"GOTO/{i}.0,0.0,0.0\n"

    it = read_cl(lines())
    first = [next(it) for _ in range(3)]
    assert [r.args[0] for r in first] == [0.0, 1.0, 2.0]
    assert pulled <= 4  # nothing read ahead: memory flat in the file's size


_num = st.floats(allow_nan=False, allow_infinity=False, width=64)
_word = st.from_regex(r"[A-Z][A-Z0-9]{0,5}", fullmatch=True)
_text = st.from_regex(r"[A-Za-z0-9 ,.()/=*+-]{0,40}", fullmatch=True).map(str.rstrip)


@st.composite
def records(draw) -> ClRecord:
    kind = draw(st.sampled_from(["goto", "goto6", "text", "generic", "bare"]))
    if kind == "goto":
        return ClRecord("GOTO", tuple(draw(st.lists(_num, min_size=3, max_size=3))))
    if kind == "goto6":
        v = draw(st.lists(st.floats(-1, 1), min_size=3, max_size=3))
        n = math.sqrt(sum(x * x for x in v))
        if n < 0.1:
            v, n = [0.0, 0.0, 1.0], 1.0
        axis = tuple(x / n for x in v)
        axis = axis if abs(math.sqrt(sum(x * x for x in axis)) - 1) <= 1e-9 else (0.0, 0.0, 1.0)
        return ClRecord("GOTO", tuple(draw(st.lists(_num, min_size=3, max_size=3))) + axis)
    if kind == "text":
        return ClRecord(draw(st.sampled_from(["PARTNO", "PPRINT", "INSERT"])), (), draw(_text))
    if kind == "bare":
        return ClRecord(draw(st.sampled_from(["RAPID", "FINI", "END", "STOP"])))
    word = draw(
        _word.filter(
            lambda w: (
                w
                not in (
                    "GOTO",
                    "FROM",
                    "TLAXIS",
                    "CIRCLE",
                    "INDIRV",
                    "PARTNO",
                    "PPRINT",
                    "INSERT",
                    "REMARK",
                )
            )
        )
    )
    args = draw(st.lists(st.one_of(_num, _word), min_size=1, max_size=12))
    return ClRecord(word, tuple(args))


@given(st.lists(records(), max_size=20))
def test_records_text_records_round_trip_exactly(recs: list[ClRecord]) -> None:
    buf = io.StringIO()
    write_cl(recs, buf)
    text = buf.getvalue()
    back = list(read_cl(io.StringIO(text)))
    assert back == recs
    buf2 = io.StringIO()
    write_cl(back, buf2)
    assert buf2.getvalue() == text  # the writer's text is a fixed point
