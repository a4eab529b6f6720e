"""Bad input: every refusal is an NcError naming line, column and reason; check() finds all."""

import pytest

from cnc.errors import NcError
from cnc.interp import Interpreter, ToolOffset, check
from cnc.params import AxisParams, MachineParams

BIG = tuple(AxisParams(a, -1000, 1000, 30000, 3000, 5e4) for a in "XYZ")
MILL = MachineParams(axes=BIG)
LATHE = MachineParams(
    kind="lathe",
    axes=(AxisParams("X", -500, 500, 1e4, 1e3, 1e4), AxisParams("Z", -500, 500, 1e4, 1e3, 1e4)),
)


@pytest.mark.parametrize(
    ("prog", "line", "col", "fragment"),
    [
        ("G0 X1\nG1 E5 F10\n", 2, 4, "E word with no code in this block that uses it"),
        ("G0 X1\nG1 V5 F10\n", 2, 4, "unknown address V"),
        ("G0 X1 A5\n", 1, 7, "axis A is not configured"),
        ("G0 G1 X1\n", 1, 4, "modal group 'motion'"),
        ("G90 G91 X1\n", 1, 5, "modal group 'distance'"),
        ("G1 G81 X1\n", 1, 4, "modal group"),
        ("G81 G0 X1\n", 1, 5, "modal group"),
        ("G17 G18\n", 1, 5, "modal group 'plane'"),
        ("M3 M4\n", 1, 4, "M group 'spindle'"),
        ("M0 M30\n", 1, 4, "M group 'stop'"),
        ("G1 X5\n", 1, 1, "feed move without F"),
        ("G1 X5 F0\n", 1, 7, "F0"),
        ("G1 X5 F-1\n", 1, 7, "must not be negative"),
        ("G0 X0 Y0\nG2 X10 Y0 I4 F10\n", 2, 11, "differ by"),
        ("G0 X2000\n", 1, 4, "axis X"),
        ("G65 P9000 A1\n", 1, 5, "PS0076 G65: program O9000 not found"),
        ("G66 P9000\n", 1, 5, "PS0076 G66: program O9000 not found"),
        ("#0=5\n", 1, 1, "PS0116 #0 is always vacant"),
        ("G1 X[1/0]\n", 1, 7, "PS0112 division by zero"),
        ("G7 X1\n", 1, 1, "unsupported G code G7"),
        ("G43 H3 Z1\n", 1, 5, "H3: no such tool offset"),
        ("G4\n", 1, 1, "needs P"),
        ("G4 P1.5\n", 1, 4, "milliseconds"),
        ("T1.5\n", 1, 1, "integer"),
        ("G10 L2 P9 X1\n", 1, 8, "P0..P6"),
        ("G10 L5 P1 X1\n", 1, 5, "not supported"),
        ("G51.1\n", 1, 1, "mirror axis"),
        ("G51 P0\n", 1, 5, "factor 0"),
        ("G0 X0 Y0\nG2 X10 Y0 F10\n", 2, 1, "needs R or a centre"),
        ("G0 X0 Y0\nG2 X10 Y0 R5 I1 F10\n", 2, 11, "both R and I"),
        ("G68 R30\nG18\n", 2, 1, "rotation is active"),
        ("G0 X1 (unterminated\n", 1, 7, "unterminated comment"),
        ("G0 X1.2.3\n", 1, 4, "malformed number"),
        ("G30 P3 X1\n", 1, 5, "third/fourth"),
    ],
)
def test_refusals_name_line_column_reason(prog, line, col, fragment) -> None:
    with pytest.raises(NcError) as ei:
        list(Interpreter(MILL, file="t.nc", tools={}).run(prog))
    e = ei.value
    assert fragment in e.message
    assert (e.line, e.col, e.file) == (line, col, "t.nc")


@pytest.mark.parametrize(
    ("prog", "fragment"),
    [
        ("G0 Y1\n", "lathe has no Y axis"),
        ("G71 P1 Q2 D1 F1\n", "PS0063 G71: no block with sequence number N1"),
        ("G90 X1 Z1\n", "feed move without F"),
        ("G92 X1 Z1 F1\n", "thread cutting with no spindle speed"),
        ("G81 X1 Z1\n", "unsupported G code G81"),
        ("T0909\n", "no tool offset number 9"),
    ],
)
def test_lathe_refusals(prog, fragment) -> None:
    with pytest.raises(NcError, match=fragment):
        list(Interpreter(LATHE, tools={}).run(prog))


def test_lathe_g50_coordinate_set_and_tool_offsets() -> None:
    it = Interpreter(LATHE, tools={1: ToolOffset(x=1.0, z=-2.0)})
    cmds = list(it.run("G0 X100 Z50\nG50 X50 Z0\nT0101\nG0 X40 Z-10\n"))
    # G50: current point becomes diameter 50 (radius 25) at Z0; offsets then shift the tip
    assert cmds[-1].end == (50.0 - 5.0 + 1.0, 0.0, 40.0 - 2.0)


def test_check_reports_all_errors_and_recovers() -> None:
    prog = "G0 X1\nG1 X2\nQ\nG5 X1\nG0 X1 E2\nG1 X3 F100\nG2 X9 Y9 I1\nM30\n"
    errs = check(prog, MILL, file="p.nc")
    assert [(e.line, e.col) for e in errs] == [(2, 1), (3, 1), (4, 1), (5, 7), (7, 10)]
    assert [str(e).split(": ", 1)[0] for e in errs][0] == "p.nc:2:1"


def test_check_of_a_valid_program_is_empty() -> None:
    assert check("G0 X1\nG1 Y1 F100\nM30\n", MILL) == []


def test_check_is_bounded() -> None:
    errs = check("G5\n" * 5000, MILL)
    assert len(errs) == 1000


def test_check_reports_errors_inside_subprograms_with_their_file() -> None:
    errs = check("M98 P5\nG0 X1\nM30\n", MILL, programs={5: "O5\nG1 X1\nM99\n"})
    assert [(e.file, e.line) for e in errs] == [("O5", 2)]
