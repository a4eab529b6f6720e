"""Tool length compensation G43 / G44 / G49 with H, and the D word (cnc/interp/compensation.py).

Machine Z = program Z + the offset's length under G43, minus it under G44, nothing under G49;
the values are worked out by hand from the tool table below. The path of G41/G42 itself is
tested in test_interp_cutter_comp.py; these are the handlers' choices of H and D.
"""

import pytest

from cnc.canon import StraightTraverse as T
from cnc.interp import Interpreter, ToolOffset
from cnc.params import AxisParams, MachineParams
from tests.cnc.interp_tables import cases, refused

BIG = tuple(AxisParams(a, -1000, 1000, 30000, 3000, 5e4) for a in "XYZ")
MILL = MachineParams(axes=BIG)
LATHE = MachineParams(
    kind="lathe",
    axes=(AxisParams("X", -500, 500, 1e4, 1e3, 1e4), AxisParams("Z", -500, 500, 1e4, 1e3, 1e4)),
)
TOOLS = {1: ToolOffset(length=100.0, radius=5.0), 2: ToolOffset(length=50.0, radius=2.0)}


def interp(text: str, params: MachineParams = MILL) -> tuple[Interpreter, list]:
    it = Interpreter(params, tools=TOOLS)
    return it, list(it.run(text))


# (name, program, machine Z of the last move, H shown, length group shown)
# fmt: off
LENGTH = [
    ("G43 H1 adds 100", "G43 H1 G0 Z10", 110.0, 1, "G43"),
    ("G44 H1 takes 100 off", "G44 H1 G0 Z10", -90.0, 1, "G44"),
    ("G49 cancels", "G43 H1\nG49 G0 Z10", 10.0, 1, "G49"),
    ("G43 without H takes the last H", "G43 H1\nG49\nG43 G0 Z10", 110.0, 1, "G43"),
    ("H alone under G43 applies at once", "G43 H1\nH2 G0 Z10", 60.0, 2, "G43"),
    ("H alone under G44 applies at once", "G44 H1\nH2 G0 Z10", -40.0, 2, "G44"),
    ("H alone under G49 only selects", "H2 G0 Z10", 10.0, 2, "G49"),
    ("H selected, then G43", "H2\nG43 G0 Z10", 60.0, 2, "G43"),
    ("G43 H0 is no length", "G43 H1\nG43 H0 G0 Z10", 10.0, 0, "G43"),
    ("G44 to G43 with the same H", "G44 H2\nG43 G0 Z10", 60.0, 2, "G43"),
    # the offset is not a move of its own: an incremental Z0 after G43 moves by the length
    ("G91 Z0 after G43 moves by the length", "G0 Z10\nG43 H1\nG91 G0 Z0", 110.0, 1, "G43"),
    ("G91 Z0 after G49 moves back", "G43 H1 G0 Z10\nG49\nG91 G0 Z0", 10.0, 1, "G49"),
]
# fmt: on


@cases("prog,z,h,code", LENGTH)
def test_tool_length_compensation(prog, z, h, code) -> None:
    it, out = interp(prog)
    assert out[-1] == T(out[-1].line, (0.0, 0.0, z))  # along Z only
    assert it.state.length_offset == h
    assert it.state.gcodes["length_comp"] == code


def test_the_program_position_keeps_the_programmed_z_under_g43() -> None:
    # G43 H1 at Z10: the machine is at 110, the program still says 10
    it, _ = interp("G43 H1 G0 Z10\n")
    assert it.state.work_position == (0.0, 0.0, 10.0)
    assert it.state.machine_position == (0.0, 0.0, 110.0)


@pytest.mark.parametrize(
    ("prog", "shown"),
    [
        ("D2", 2),
        ("D2\nD0", 0),
        ("G41 D1 G1 X10 F100\nG40 X20", 1),
        ("D2\nG41 G1 X10 F100", 2),
        # (a D in a G40 block was dropped)
        ("D1\nG40 D2", 2),
        ("G41 D1 G1 X10 F100\nG40 D2 X20", 2),
    ],
    ids=["D alone", "D0", "G41 D", "G41 takes the D before it", "G40 D", "G40 D cancelling"],
)
def test_d_word_selects_the_radius_offset(prog, shown) -> None:
    assert interp(prog)[0].state.radius_offset == shown


def test_a_d_word_in_a_g40_block_is_the_next_g41s_radius() -> None:
    # D2 (radius 2) given with G40: the G41 after it offsets the path by 2, not by D1's 5
    out = interp("G41 D1 G1 X10 F100\nG40 D2 X20 Y0\nG41 G1 X30 Y0\nX40\nG40 X50\n")[1]
    assert [c.end[1] for c in out[2:4]] == [2.0, 2.0]


def test_a_lathe_d_word_alone_selects_the_radius_offset() -> None:
    assert interp("D2\n", LATHE)[0].state.radius_offset == 2


def test_a_lathe_cycle_d_is_the_cycle_word_not_a_radius_offset() -> None:
    head = "G18 G21 G40 G80 G99\nG97 S1000 M3\nG0 X30 Z2\n"
    it, _ = interp(head + "G71 P10 Q20 D3 F0.2\nN10 G0 X20\nG1 Z-10\nN20 X30\n", LATHE)
    assert it.state.radius_offset == 0


# (name, program, message, line, column)
# fmt: off
REFUSALS = [
    ("D not an integer", "G0 X1 D1.5", "D needs a non-negative integer", 1, 7),
    ("H not an integer", "G43 H1.5", "H needs a non-negative integer", 1, 5),
    ("H alone not an integer", "G0 X1 H-1", "H needs a non-negative integer", 1, 7),
    ("G43 with an unknown H", "G43 H9", "H9: no such tool offset", 1, 5),
    ("H alone under G43 unknown", "G43 H1\nG0 X1 H9", "H9: no such tool offset", 2, 7),
    ("G44 with an unknown H", "H9\nG44", "H9: no such tool offset", 2, 1),
]
# fmt: on


@cases("prog,message,line,col", REFUSALS)
def test_refusals(prog, message, line, col) -> None:
    assert refused(lambda: interp(prog)) == (message, line, col)
