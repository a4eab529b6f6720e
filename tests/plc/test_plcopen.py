"""PLCopen TC6 XML import: graph -> series/parallel rungs, blocks, edges, and errors with
the XML line and column. The fixture is hand-written after the tc6_0201 schema."""

from __future__ import annotations

from pathlib import Path

import pytest

from plc.ladder import LadderError, check_file, format_program, import_plcopen, load_file
from plc.runtime import Runtime

FIXTURE = Path(__file__).parent / "programs" / "openplc_seal_in.xml"


def test_import_rebuilds_series_parallel_structure():
    program, sink = import_plcopen(str(FIXTURE))
    assert not sink.items
    text = format_program(program)
    assert "BST XIC Start NXB XIC Motor BND XIO Stop OTE Motor" in text
    assert "XIC Motor TON T1 T#2s" in text and "XIC T1.DN OTE Lamp" in text
    assert "MOV T1.ACC Elapsed" in text and "XIC Reset OTE _R15" in text
    # IEC CTU: R has priority, CU counts on its own edge (helper bits, see docs/ladder.md)
    assert "XIC _R15 RES C1" in text and "XIC _C15 XIO _R15 CTU C1 3" in text
    assert "XIC C1.DN OTL Alarm" in text and "XIC Reset OTU Alarm" in text
    assert "XIC Stop OTN Ready" in text
    # the edge helper runs before the counter that uses it
    lines = text.splitlines()
    assert lines.index("XIC Pulse ONS _E12_S OTE _E12") < lines.index(
        "XIC _E12 ONS _C15_S OTE _C15"
    )
    tags = {t.name: t for t in program.tags}
    assert tags["Start"].comment == "Start push button" and tags["T1"].type == "TIMER"


def test_imported_program_runs():
    rt = Runtime(load_file(str(FIXTURE)))

    def step(t, **inputs):
        for name, value in inputs.items():
            rt.write_once(name, value)
        rt.scan(t)

    step(0, Start=True)
    assert rt.read("Motor") is True and rt.read("Ready") is True
    step(10, Start=False)
    assert rt.read("Motor") is True
    step(1000)
    assert rt.read("Elapsed") == 1000 and rt.read("Lamp") is False
    step(2010)
    assert rt.read("Lamp") is True
    for k in range(3):
        step(3000 + 20 * k, Pulse=True)
        step(3010 + 20 * k, Pulse=False)
    assert rt.read("Count") == 3 and rt.read("Alarm") is True
    step(4000, Reset=True, Stop=True)
    assert rt.read("Count") == 0 and rt.read("Alarm") is False
    assert rt.read("Motor") is False and rt.read("Ready") is False


def test_text_and_import_agree(tmp_path):
    program, _ = import_plcopen(str(FIXTURE))
    path = tmp_path / "same.ld"
    path.write_text(format_program(program))
    a, b = Runtime(load_file(str(FIXTURE))), Runtime(load_file(str(path)))
    for t, (start, pulse) in enumerate([(1, 0), (0, 1), (0, 0), (0, 1), (0, 0), (0, 1)]):
        for rt in (a, b):
            rt.write_once("Start", start)
            rt.write_once("Pulse", pulse)
            rt.scan(t * 500)
        assert a.snapshot.qx == b.snapshot.qx and a.snapshot.mw == b.snapshot.mw


LD_HEAD = """<?xml version="1.0"?>
<project xmlns="http://www.plcopen.org/xml/tc6_0201">
<types><pous><pou name="p" pouType="program">
<interface><localVars>
<variable name="A" address="%IX0.0"><type><BOOL/></type></variable>
<variable name="Q" address="%QX0.0"><type><BOOL/></type></variable>
<variable name="F"><type><REAL/></type></variable>
</localVars></interface>
<body><LD>
<leftPowerRail localId="1"><connectionPointOut formalParameter=""/></leftPowerRail>
"""
LD_TAIL = "</LD></body></pou></pous></types></project>\n"


@pytest.mark.parametrize(
    "body, line, fragment",
    [
        (
            '<contact localId="2"><connectionPointIn><connection refLocalId="1"/></connectionPointIn>'
            '<variable>Nope</variable></contact>\n<coil localId="3"><connectionPointIn>'
            '<connection refLocalId="2"/></connectionPointIn><variable>Q</variable></coil>\n',
            11,
            "undeclared tag 'Nope'",
        ),
        (
            '<coil localId="3"><connectionPointIn><connection refLocalId="9"/></connectionPointIn>'
            "<variable>Q</variable></coil>\n",
            11,
            "unknown localId '9'",
        ),
        ('<coil localId="3"><variable>Q</variable></coil>\n', 11, "not connected"),
        ('<block localId="4" typeName="CTUD" instanceName="x"/>\n', 11, "unsupported block 'CTUD'"),
        ('<step localId="5" name="s"/>\n', 11, "unsupported LD element 'step'"),
        (
            '<coil localId="3"><connectionPointIn><connection refLocalId="1"/></connectionPointIn>'
            "<variable>A</variable></coil>\n",
            11,
            "cannot write the input",
        ),
        (
            '<coil localId="3"><connectionPointIn><connection refLocalId="3"/></connectionPointIn>'
            "<variable>Q</variable></coil>\n",
            11,
            "feedback loop",
        ),
    ],
)
def test_import_errors_carry_xml_positions(tmp_path, body, line, fragment):
    path = tmp_path / "bad.xml"
    path.write_text(LD_HEAD + body + LD_TAIL)
    diags = check_file(str(path))
    assert any(d.line == line and fragment in d.message and d.file == str(path) for d in diags), [
        str(d) for d in diags
    ]
    assert any("type REAL is not supported" in d.message and d.line == 7 for d in diags)
    with pytest.raises(LadderError):
        load_file(str(path))


def test_malformed_xml_and_wrong_root(tmp_path):
    bad = tmp_path / "x.xml"
    bad.write_text("<project>\n<types>\n</project>\n")
    (d,) = check_file(str(bad))
    assert d.line == 3 and "malformed XML" in d.message
    other = tmp_path / "y.xml"
    other.write_text("<svg/>")
    (d,) = check_file(str(other))
    assert "not a PLCopen TC6 project" in d.message


def test_no_ld_program(tmp_path):
    path = tmp_path / "st.xml"
    path.write_text(
        '<project xmlns="http://www.plcopen.org/xml/tc6_0201"><types><pous>'
        '<pou name="p" pouType="program"><body><ST/></body></pou></pous></types></project>'
    )
    (d,) = check_file(str(path))
    assert "no program POU with an LD body" in d.message
