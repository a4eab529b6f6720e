"""Bad input never crashes the parser, checker or importer: only diagnostics come back. Where
two implementations answer the same question they are held to each other: compile and check
give the same diagnostics, a program exported as text recompiles to the same behaviour, and a
rung drawn in PLCopen LD XML scans like the same rung written as text."""

from __future__ import annotations

import itertools

from hypothesis import given, settings
from hypothesis import strategies as st

from plc.ladder import (
    check_text,
    compile_program,
    compile_text,
    format_program,
    import_plcopen,
    parse_program,
)
from plc.ladder.diagnostics import LadderError
from plc.runtime import Runtime

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
        # the compiler refuses with exactly what the checker reports, warnings included
        assert [str(d) for d in exc.diagnostics] == [str(d) for d in diags]
    else:
        assert not [d for d in diags if d.severity == "error"]
        # exported as text and compiled again, it is the same program: same tags, same
        # rungs, the same images after the same scans
        tree, _ = parse_program(text, "soup.ld")
        again = compile_text(format_program(tree), "again.ld")
        assert {n: t.type for n, t in again.tags.items()} == {
            n: t.type for n, t in program.tags.items()
        }
        assert len(again.rungs) == len(program.rungs)
        assert _scans(again) == _scans(program)


def _scans(program) -> list:
    """The images after three scans with the same input pattern (bits and words set)."""
    ix = [k % 3 == 0 for k in range(1024)]
    iw = [(7 * k) % 50_000 for k in range(1024)]
    qx, mx, qw, mw = [False] * 1024, [False] * 1024, [0] * 1024, [0] * 1024
    v = list(program.v_init)
    for now in (10, 20, 2030):
        program.scan_fn(ix, qx, mx, iw, qw, mw, v, now)
    return [qx, mx, qw, mw, v]


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


# ------------------------------------------------------------------ text vs PLCopen LD
INPUTS = ["I0", "I1", "I2", "I3"]
OUTPUTS = ["Q0", "Q1", "Q2"]
COILS = {"OTE": {}, "OTN": {"negated": "true"}, "OTL": {"storage": "set"}, "OTU": {"storage": "reset"}}  # fmt: skip

leaf = st.tuples(st.sampled_from(["XIC", "XIO"]), st.sampled_from(INPUTS + OUTPUTS))
network = st.recursive(
    leaf,
    lambda kids: st.one_of(
        st.tuples(st.just("series"), st.lists(kids, min_size=2, max_size=3)),
        st.tuples(st.just("parallel"), st.lists(kids, min_size=2, max_size=3)),
    ),
    max_leaves=8,
)
rungs = st.lists(
    st.tuples(network, st.sampled_from(list(COILS)), st.sampled_from(OUTPUTS)),
    min_size=1,
    max_size=4,
)


def _text(net) -> str:
    if net[0] in ("XIC", "XIO"):
        return f"{net[0]} {net[1]}"
    parts = [_text(k) for k in net[1]]
    return " ".join(parts) if net[0] == "series" else "BST " + " NXB ".join(parts) + " BND"


def as_text(program) -> str:
    head = [f"TAG {n} : BOOL AT %IX0.{k}" for k, n in enumerate(INPUTS)]
    head += [f"TAG {n} : BOOL AT %QX0.{k}" for k, n in enumerate(OUTPUTS)]
    return "\n".join(head + [f"{_text(net)} {coil} {out}" for net, coil, out in program]) + "\n"


def as_plcopen(program) -> str:
    """The same rungs drawn as an OpenPLC Editor LD body: contacts wired in series, parallel
    legs joined by several connections into one point, one coil per rung."""
    ids = itertools.count(2)
    body = ['<leftPowerRail localId="1"><connectionPointOut formalParameter=""/></leftPowerRail>']

    def wire(sources: list[int]) -> str:
        conns = "".join(f'<connection refLocalId="{s}"/>' for s in sources)
        return f"<connectionPointIn>{conns}</connectionPointIn>"

    def draw(net, sources: list[int]) -> list[int]:
        if net[0] in ("XIC", "XIO"):
            lid = next(ids)
            negated = ' negated="true"' if net[0] == "XIO" else ""
            body.append(
                f'<contact localId="{lid}"{negated}>{wire(sources)}'
                f"<variable>{net[1]}</variable></contact>"
            )
            return [lid]
        if net[0] == "series":
            for kid in net[1]:
                sources = draw(kid, sources)
            return sources
        return [end for kid in net[1] for end in draw(kid, sources)]

    for net, coil, out in program:
        ends = draw(net, [1])
        attrs = "".join(f' {k}="{v}"' for k, v in COILS[coil].items())
        body.append(
            f'<coil localId="{next(ids)}"{attrs}>{wire(ends)}<variable>{out}</variable></coil>'
        )
    variables = [
        f'<variable name="{n}" address="%IX0.{k}"><type><BOOL/></type></variable>'
        for k, n in enumerate(INPUTS)
    ] + [
        f'<variable name="{n}" address="%QX0.{k}"><type><BOOL/></type></variable>'
        for k, n in enumerate(OUTPUTS)
    ]
    return (
        '<?xml version="1.0"?>\n<project xmlns="http://www.plcopen.org/xml/tc6_0201">'
        '<types><pous><pou name="fuzz" pouType="program"><interface><localVars>'
        + "\n".join(variables)
        + "</localVars></interface><body><LD>\n"
        + "\n".join(body)
        + "\n</LD></body></pou></pous></types></project>\n"
    )


@settings(max_examples=150, deadline=None)
@given(rungs, st.lists(st.integers(0, 15), min_size=1, max_size=8))
def test_a_rung_drawn_in_plcopen_scans_like_the_same_rung_as_text(program, input_words):
    from_text = Runtime(compile_text(as_text(program), "fuzz.ld"))
    tree, sink = import_plcopen(as_plcopen(program), "fuzz.xml")
    assert not sink.has_errors, [str(d) for d in sink.sorted()]
    from_xml = Runtime(compile_program(tree, sink))
    for t, word in enumerate(input_words):
        for rt in (from_text, from_xml):
            for k, name in enumerate(INPUTS):
                rt.write_once(name, bool(word >> k & 1))
            rt.scan(10 * t)
        got = {n: (from_text.read(n), from_xml.read(n)) for n in OUTPUTS}
        assert all(a == b for a, b in got.values()), (as_text(program), got)
