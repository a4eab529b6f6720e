"""Bad input never crashes the parser, checker or importer: only diagnostics come back."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from plc.ladder import check_text, compile_text, import_plcopen
from plc.ladder.diagnostics import LadderError

WORDS = [
    "XIC",
    "XIO",
    "OTE",
    "OTL",
    "TON",
    "CTU",
    "ADD",
    "MOV",
    "BST",
    "NXB",
    "BND",
    "JMP",
    "LBL",
    "ONS",
    "OSR",
    "LIM",
    "RES",
    "TAG",
    ":",
    ":=",
    "BOOL",
    "INT",
    "TIMER",
    "AT",
    "RETAIN",
    "%IX0.0",
    "%QX0.1",
    "%MW3",
    "%IW9999",
    "A",
    "T",
    "T.DN",
    "T.ACC",
    "5",
    "-40000",
    "T#2s",
    "T#x",
    "\\",
    "//",
    "$",
    "\n",
    "x.y.z",
    "16#FFFF",
    "SOR",
    "EOR",
]
HEAD = "TAG A : BOOL AT %IX0.1\nTAG T : TIMER\n"


@settings(max_examples=300, deadline=None)
@given(st.lists(st.sampled_from(WORDS), max_size=40))
def test_token_soup_gives_diagnostics_not_crashes(words):
    text = HEAD + " ".join(words) + "\n"
    diags = check_text(text, "soup.ld")
    assert all(d.file == "soup.ld" and d.line >= 1 and d.col >= 1 for d in diags)
    try:
        program = compile_text(text, "soup.ld")
    except LadderError as exc:
        assert exc.errors
    else:
        assert not [d for d in diags if d.severity == "error"]
        program.scan_fn(
            [False] * 1024,
            [False] * 1024,
            [False] * 1024,
            [0] * 1024,
            [0] * 1024,
            [0] * 1024,
            list(program.v_init),
            10,
        )


@settings(max_examples=200, deadline=None)
@given(st.text(max_size=200))
def test_arbitrary_text(text):
    for d in check_text(text, "any.ld"):
        assert d.line >= 1 and d.col >= 1


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=300))
def test_arbitrary_xml_bytes(data):
    _, sink = import_plcopen(b"<project>" + data, "x.xml")
    assert all(d.line >= 0 for d in sink.items)


def test_deep_branch_nesting_is_refused():
    text = "BST " * 100 + "XIC %IX0.0 NXB XIC %IX0.1 BND" * 100 + " OTE %QX0.0\n"
    (err,) = [d for d in check_text(text, "deep.ld") if d.severity == "error"]
    assert "nested deeper than 32" in err.message and err.col == 1 + 4 * 32


def test_very_long_rung_compiles():
    program = compile_text("XIC %IX0.0 " * 3000 + "OTE %QX0.0\n", "long.ld")
    assert program.rungs[0].number == 0
