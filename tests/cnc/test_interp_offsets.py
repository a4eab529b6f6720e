"""Coordinate systems word by word (cnc/interp/offsets.py): G54..G59 and G54.1 P, G28/G30
(with rotary axes and on a lathe), G53, and their refusals.

Each case states the machine position worked out by hand: machine = program + work offset
(+ EXT + G92 + tool length), a lathe X word being a diameter (machine X is the radius).
They are the table `make mutation` holds cnc/interp/offsets.py against (tests/mutation.py);
G10 / G92 / G43 are in test_interp_codes.py and test_machine_data.py.
"""

from dataclasses import replace

import pytest

from cnc.canon import StraightFeed as F
from cnc.canon import StraightTraverse as T
from cnc.interp import Interpreter, ToolOffset
from cnc.params import AxisParams, MachineParams
from tests.cnc.interp_tables import cases, refused

BIG = tuple(AxisParams(a, -1000, 1000, 30000, 3000, 5e4) for a in "XYZ")
MILL = MachineParams(axes=BIG)
# a mill whose G30 point is not its home (home is the origin)
MILL_G30 = MachineParams(axes=BIG, second_reference_mm=(-5.0, -6.0, -7.0))
A_AXIS = AxisParams("A", -720.0, 720.0, 10800.0, 720.0, 14400.0, home_mm=10.0)
# a 4-axis mill: A homes to 10 deg, its G30 angle is 45 deg
MILL4 = MachineParams(axes=(*BIG, A_AXIS), second_reference_mm=(-5.0, -6.0, -7.0, 45.0))
# a lathe whose reference point is X150 (radius) Z300
LATHE = MachineParams(
    kind="lathe",
    axes=(
        AxisParams("X", -500, 500, 1e4, 1e3, 1e4, home_mm=150.0),
        AxisParams("Z", -500, 500, 1e4, 1e3, 1e4, home_mm=300.0),
    ),
)
# its G30 point, one figure per axis as the configuration gives it: X -100 (radius), Z -50
LATHE_G30 = replace(LATHE, second_reference_mm=(-100.0, -50.0))
TOOLS = {1: ToolOffset(length=100.0, radius=5.0)}


def interp(text: str, params: MachineParams = MILL, **kw) -> tuple[Interpreter, list]:
    kw.setdefault("tools", TOOLS)
    it = Interpreter(params, **kw)
    return it, list(it.run(text))


def cmds(text: str, params: MachineParams = MILL, **kw) -> list:
    return interp(text, params, **kw)[1]


# --- work offsets: G54..G59, G54.1 P1..P48 -----------------------------------------------
WOFS = {2: (20.0, 0.0, 0.0), 6: (60.0, 6.0, 0.0)}  # G54 stays 0
WOFS |= {7: (5.0, 6.0, 7.0), 8: (8.0, 0.0, 0.0), 54: (1.0, 2.0, 3.0)}

# (name, program, last move, work offset shown)
# fmt: off
WORK_OFFSETS = [
    ("G54.1 P1 is slot 7", "G54.1 P1 G0 X1 Y1 Z1", T(1, (6.0, 7.0, 8.0)), "G54.1 P1"),
    ("G54.1 P2 is slot 8", "G54.1 P2 G0 X1", T(1, (9.0, 0.0, 0.0)), "G54.1 P2"),
    ("G54.1 P48 is slot 54", "G54.1 P48 G0 X0 Y0 Z0", T(1, (1.0, 2.0, 3.0)), "G54.1 P48"),
    ("G59 is slot 6", "G59 G0 X1 Y1", T(1, (61.0, 7.0, 0.0)), "G59"),
    ("G54 after G54.1", "G54.1 P1\nG54 G0 X1", T(2, (1.0, 0.0, 0.0)), "G54"),
    ("G55 after G54.1 P1", "G54.1 P1\nG55 G0 X1", T(2, (21.0, 0.0, 0.0)), "G55"),
]
# fmt: on


@cases("prog,last,shown", WORK_OFFSETS)
def test_work_offset_selection(prog, last, shown) -> None:
    it, out = interp(prog, work_offsets=WOFS)
    assert out[-1] == last
    assert it.state.work_offset == shown


def test_g54_1_shows_its_group_code() -> None:
    it, _ = interp("G54.1 P3", work_offsets=WOFS)
    assert it.state.gcodes["work_offset"] == "G54.1"


def test_changing_the_work_offset_keeps_the_machine_still_and_renames_the_position() -> None:
    # machine X 5 (G54 offset 0 -> program 5); under G55 (offset 20) that point is program -15
    it, out = interp("G0 X5\nG55\n", work_offsets=WOFS)
    assert out == [T(1, (5.0, 0.0, 0.0))]
    assert it.state.work_position == (-15.0, 0.0, 0.0)
    # an incremental move after the change starts from the same machine point
    assert cmds("G0 X5\nG55\nG91 G0 X1\n", work_offsets=WOFS)[-1] == T(3, (6.0, 0.0, 0.0))


def test_the_same_work_offset_again_is_no_change() -> None:
    it, out = interp("G55 G0 X0\nG55\nG91 X1\n", work_offsets=WOFS)
    assert out[-1] == T(3, (21.0, 0.0, 0.0))
    assert it.state.work_position == (1.0, 0.0, 0.0)


# --- G28 / G30 ------------------------------------------------------------------------------
# (name, program, machine, the moves of the last block)
# fmt: off
RETURNS = [
    ("G28 Z: the intermediate point then home", "G0 X10 Y10 Z10\nG28 Z20", MILL,
     [T(2, (10.0, 10.0, 20.0)), T(2, (10.0, 10.0, 0.0))]),
    ("G9 G28: both moves exact stop", "G0 X10 Y10 Z10\nG9 G28 X5", MILL,
     [T(2, (5.0, 10.0, 10.0), True), T(2, (0.0, 10.0, 10.0), True)]),
    ("G30 without P: the second reference", "G0 X10 Y10 Z10\nG30 Y3", MILL_G30,
     [T(2, (10.0, 3.0, 10.0)), T(2, (10.0, -6.0, 10.0))]),
    ("G30 without axis words: every axis", "G0 X10 Y10 Z10\nG30", MILL_G30,
     [T(2, (-5.0, -6.0, -7.0))]),
    ("G28 X Y Z names all three", "G0 X10 Y10 Z10\nG28 X1 Y2 Z3", MILL_G30,
     [T(2, (1.0, 2.0, 3.0)), T(2, (0.0, 0.0, 0.0))]),
    ("G28 in a work offset: the intermediate point is in it", "G55 G0 X10\nG28 X5", MILL,
     [T(2, (25.0, 0.0, 0.0)), T(2, (0.0, 0.0, 0.0))]),
    # lathe: X words are diameters, U and W incremental; machine Y stays 0
    ("lathe G28 U0: X home only", "G0 X100 Z50\nG28 U0", LATHE,
     [T(2, (50.0, 0.0, 50.0)), T(2, (150.0, 0.0, 50.0))]),
    ("lathe G28 W0: Z home only", "G0 X100 Z50\nG28 W0", LATHE,
     [T(2, (50.0, 0.0, 50.0)), T(2, (50.0, 0.0, 300.0))]),
    ("lathe G28 U-20 W10: via the incremental point", "G0 X100 Z50\nG28 U-20 W10", LATHE,
     [T(2, (40.0, 0.0, 60.0)), T(2, (150.0, 0.0, 300.0))]),
    ("lathe G28 X: X home only", "G0 X100 Z50\nG28 X80", LATHE,
     [T(2, (40.0, 0.0, 50.0)), T(2, (150.0, 0.0, 50.0))]),
    ("lathe G28 without words: X and Z", "G0 X100 Z50\nG28", LATHE,
     [T(2, (150.0, 0.0, 300.0))]),
    # (these three raised IndexError: the lathe's X Z figures were read as X Y Z)
    ("lathe G30 U0: X to its G30 point", "G0 X100 Z50\nG30 U0", LATHE_G30,
     [T(2, (50.0, 0.0, 50.0)), T(2, (-100.0, 0.0, 50.0))]),
    ("lathe G30 W0: Z to its G30 point", "G0 X100 Z50\nG30 W0", LATHE_G30,
     [T(2, (50.0, 0.0, 50.0)), T(2, (50.0, 0.0, -50.0))]),
    ("lathe G30 without words: X and Z", "G0 X100 Z50\nG30", LATHE_G30,
     [T(2, (-100.0, 0.0, -50.0))]),
    # rotary axes (A homes to 10, G30 angle 45): a named A goes straight to its reference
    ("G28 alone homes A too", "G0 X10 A90\nG28", MILL4, [T(2, (0.0, 0.0, 0.0, 10.0))]),
    ("G30 alone takes A to its G30 angle", "G0 X10 A90\nG30", MILL4,
     [T(2, (-5.0, -6.0, -7.0, 45.0))]),
    ("G28 A: only A, no intermediate point", "G0 X10 A90\nG28 A0", MILL4,
     [T(2, (10.0, 0.0, 0.0, 10.0))]),
    ("G30 A: only A, to 45", "G0 X10 A90\nG30 A0", MILL4, [T(2, (10.0, 0.0, 0.0, 45.0))]),
    ("G28 X A: A home, X via the intermediate point", "G0 X10 A90\nG28 X5 A0", MILL4,
     [T(2, (5.0, 0.0, 0.0, 10.0)), T(2, (0.0, 0.0, 0.0, 10.0))]),
    ("G30 X A", "G0 X10 A90\nG30 X5 A0", MILL4,
     [T(2, (5.0, 0.0, 0.0, 45.0)), T(2, (-5.0, 0.0, 0.0, 45.0))]),
]
# fmt: on


@cases("prog,params,last", RETURNS)
def test_reference_returns(prog, params, last) -> None:
    out = cmds(prog, params, work_offsets=WOFS if params is MILL else None)
    assert out[-len(last) :] == last
    assert all(c.line == 2 for c in out[-len(last) :]) and out[-len(last) - 1].line == 1


def test_after_g28_the_program_position_is_the_home_in_the_work_system() -> None:
    # home machine X 0 under G55 (offset 20) is program X -20; an incremental move goes on
    it, out = interp("G55 G0 X10\nG28 X5\nG91 G0 X1\n", work_offsets=WOFS)
    assert out[-1] == T(3, (1.0, 0.0, 0.0))
    assert it.state.work_position == (-19.0, 0.0, 0.0)


def test_a_lathe_home_position_in_diameter() -> None:
    it, _ = interp("G0 X100 Z50\nG28 U0 W0\n", LATHE)
    assert it.state.work_position == (300.0, 0.0, 300.0)  # radius 150 shown as diameter
    assert it.state.machine_position == (150.0, 0.0, 300.0)


# --- G53 ---------------------------------------------------------------------------------
# (name, program, machine, work offsets, last move)
# fmt: off
MACHINE_MOVES = [
    ("G53 ignores the work offset", "G55 G0 X1\nG53 G0 X5", MILL, WOFS, T(2, (5.0, 0.0, 0.0))),
    ("G9 G53 G0", "G9 G53 G0 X5", MILL, None, T(1, (5.0, 0.0, 0.0), True)),
    ("G9 G53 G1", "G9 G53 G1 X5 F100", MILL, None, F(1, (5.0, 0.0, 0.0), 100.0, True)),
    ("G53 in inch", "G20 G53 G0 X1", MILL, None, T(1, (25.4, 0.0, 0.0))),
    ("lathe G53 X is a diameter", "G53 G0 X100 Z-20", LATHE, None, T(1, (50.0, 0.0, -20.0))),
    ("lathe G53 Z only", "G0 X100 Z50\nG53 G0 Z-20", LATHE, None, T(2, (50.0, 0.0, -20.0))),
    ("G53 A is the machine angle", "G53 G0 A5", MILL4, {1: (0.0, 0.0, 0.0, 30.0)},
     T(1, (0.0, 0.0, 0.0, 5.0))),
    ("an A move in the work offset", "G0 A5", MILL4, {1: (0.0, 0.0, 0.0, 30.0)},
     T(1, (0.0, 0.0, 0.0, 35.0))),
]
# fmt: on


@cases("prog,params,wofs,last", MACHINE_MOVES)
def test_machine_moves(prog, params, wofs, last) -> None:
    assert cmds(prog, params, work_offsets=wofs)[-1] == last


@pytest.mark.parametrize(
    ("prog", "last"),
    [("G53 G0 Z-20", T(1, (50.0, 0.0, -20.0))), ("G28 W0", T(1, (50.0, 0.0, 300.0)))],
    ids=["G53", "G28"],
)
def test_a_lathe_machine_move_keeps_y_at_zero(prog, last) -> None:
    # a lathe has no Y: a start pose that says otherwise is put back on the X Z plane
    assert cmds(prog, LATHE, start=(50.0, 7.0, 20.0))[-1] == last


def test_after_g53_the_program_position_follows_the_machine() -> None:
    it, out = interp("G55 G0 X1\nG53 G0 X5\nG91 G0 X1\n", work_offsets=WOFS)
    assert out[-1] == T(3, (6.0, 0.0, 0.0))
    assert it.state.work_position == (-14.0, 0.0, 0.0)


# --- refusals: message, line, column ------------------------------------------------------
LIMIT_X = (
    "axis X move to 2000.0000 mm is beyond the soft limit [-1000, 1000] mm (machine coordinates)"
)
COMP = "G28/G30 with cutter compensation active (cancel with G40)"
# (name, program, machine, message, line, column)
# fmt: off
REFUSALS = [
    ("G28 in cutter compensation", "G41 D1 G1 X10 F100\nG1 X20\nG28 Z5", MILL, COMP, 3, 1),
    ("G30 in cutter compensation", "G41 D1 G1 X10 F100\nG1 X20\nG1 G30 Z5", MILL, COMP, 3, 4),
    ("G53 in cutter compensation", "G41 D1 G1 X10 F100\nG1 X20\nG0 G53 Z5", MILL,
     "G53 with cutter compensation active", 3, 4),
    ("G53 with G2", "G2 G53 X1 Y0 I1 F10", MILL, "G53 moves only with G0 or G1", 1, 4),
    ("G53 G1 without F", "G53 G1 X5", MILL, "feed move without F", 1, 1),
    ("G30 P3", "G30 P3 X1", MILL, "G30 P3/P4 (third/fourth reference) is not configured", 1, 5),
    ("G30 beyond the soft limit", "G0 X1\nG30 X5",
     MachineParams(axes=BIG, second_reference_mm=(2000.0, 0.0, 0.0)), LIMIT_X, 2, 5),
    ("G28 home beyond the soft limit", "G28 Y1",
     MachineParams(axes=(AxisParams("X", -1000, 1000, 3e4, 3e3, 5e4, home_mm=2000.0), *BIG[1:])),
     LIMIT_X, 1, 1),
    ("G53 beyond the soft limit", "G0 X1\nG53 G0 Y1 X2000", MILL, LIMIT_X, 2, 11),
    ("G54.1 P0", "G54.1 P0", MILL, "G54.1 P0: extended work offsets are P1..P48", 1, 7),
    ("G54.1 P49", "G54.1 P49", MILL, "G54.1 P49: extended work offsets are P1..P48", 1, 7),
    ("G54.1 P1.5", "G54.1 P1.5", MILL, "G54.1 P1.5: extended work offsets are P1..P48", 1, 7),
]
# fmt: on


@cases("prog,params,message,line,col", REFUSALS)
def test_refusals(prog, params, message, line, col) -> None:
    assert refused(lambda: cmds(prog, params)) == (message, line, col)
