"""Modal settings word by word (cnc/interp/modes.py): units, feed mode, F, spindle mode, S,
plane, distance, arc distance, return level, path control (G61 G64 G103 G187).

Each case states the value worked out by hand from the code's documented meaning; they are
the table `make mutation` holds cnc/interp/modes.py against (tests/mutation.py).
"""

import math

import pytest

from cnc.canon import PathMode, SetPathMode, Spindle, SpindleDirection, StraightFeed
from cnc.canon import StraightTraverse as T
from cnc.interp import Interpreter, ToolOffset
from cnc.params import AxisParams, MachineParams
from tests.cnc.interp_tables import cases, refused

BIG = tuple(AxisParams(a, -1000, 1000, 30000, 3000, 5e4) for a in "XYZ")
MILL = MachineParams(axes=BIG)  # default_path_tolerance 0.01 mm, no spindle clamp
LATHE = MachineParams(
    kind="lathe",
    axes=(AxisParams("X", -500, 500, 1e4, 1e3, 1e4), AxisParams("Z", -500, 500, 1e4, 1e3, 1e4)),
)
TOOLS = {1: ToolOffset(length=100.0, radius=5.0)}
CW = SpindleDirection.CW
EXACT, CONT = PathMode.EXACT_STOP, PathMode.CONTINUOUS


def interp(text: str, params: MachineParams = MILL, **kw) -> tuple[Interpreter, list]:
    kw.setdefault("tools", TOOLS)
    it = Interpreter(params, **kw)
    return it, list(it.run(text))


def cmds(text: str, params: MachineParams = MILL, **kw) -> list:
    return interp(text, params, **kw)[1]


def state(text: str, params: MachineParams = MILL, **kw):
    return interp(text, params, **kw)[0].state


# --- the modal state a program leaves (gcodes, units) -----------------------------------
# (name, program, machine, state group, expected code)
# fmt: off
STATES = [
    ("G20 is inch", "G20", MILL, "units", "G20"),
    ("G21 after G20 before motion", "G20\nG21", MILL, "units", "G21"),
    ("G95 per revolution", "G95", MILL, "feed_mode", "G95"),
    ("G94 after G95", "G95\nG94", MILL, "feed_mode", "G94"),
    ("lathe powers on in G99", "", LATHE, "feed_mode", "G99"),
    ("lathe G98 per minute", "G98", LATHE, "feed_mode", "G98"),
    ("lathe G99 after G98", "G98\nG99", LATHE, "feed_mode", "G99"),
    ("G96 surface speed", "G96 S100", LATHE, "spindle_mode", "G96"),
    ("G97 after G96", "G96 S100\nG97 S500", LATHE, "spindle_mode", "G97"),
    ("G18 plane", "G18", MILL, "plane", "G18"),
    ("G17 after G19", "G19\nG17", MILL, "plane", "G17"),
    ("G91 incremental", "G91", MILL, "distance", "G91"),
    ("G90 after G91", "G91\nG90", MILL, "distance", "G90"),
    ("G90.1 absolute centres", "G90.1", MILL, "arc_distance", "G90.1"),
    ("G91.1 after G90.1", "G90.1\nG91.1", MILL, "arc_distance", "G91.1"),
    ("G99 return to R", "G99", MILL, "return_level", "G99"),
    ("G98 after G99", "G99\nG98", MILL, "return_level", "G98"),
    ("G61 exact stop", "G61", MILL, "path_mode", "G61"),
    ("G64 after G61", "G61\nG64", MILL, "path_mode", "G64"),
]
# fmt: on


@cases("prog,params,group,code", STATES)
def test_modal_group_state(prog, params, group, code) -> None:
    assert state(prog, params).gcodes[group] == code


def test_units_programmed_is_set_by_g20_or_g21_only() -> None:
    # `nc check` warns about a program that never says its unit
    assert interp("G0 X1\n")[0].units_programmed is False
    assert interp("G21\nG0 X1\n")[0].units_programmed is True
    assert interp("G20\n")[0].units_programmed is True


def test_units_state_names_the_unit() -> None:
    assert state("G20").units == "inch"
    assert state("G20\nG21").units == "mm"


# --- units scale every length word ----------------------------------------------------
# fmt: off
UNIT_MOVES = [
    ("G20 X1 is 25.4 mm", "G20 G0 X1", [T(1, (25.4, 0.0, 0.0))]),
    ("G21 after G20 is mm again", "G20\nG21\nG0 X1", [T(3, (1.0, 0.0, 0.0))]),
    ("G21 after G20: incremental X in mm", "G20\nG21\nG91 G0 X1", [T(3, (1.0, 0.0, 0.0))]),
    ("G21 after G20: F in mm/min", "G20\nG21\nG1 X1 F100", [StraightFeed(3, (1.0, 0.0, 0.0), 100.0)]),
    ("the same unit again after motion", "G21 G0 X1\nG21\nG0 X2", [T(1, (1.0, 0.0, 0.0)), T(3, (2.0, 0.0, 0.0))]),
    ("G20 F is in/min", "G20 G1 X1 F10", [StraightFeed(1, (25.4, 0.0, 0.0), 254.0)]),
    # a G28 without axis words is no programmed motion: the unit may still be set (Haas)
    ("G28 then G20", "G28\nG20 G0 X1", [T(1, (0.0, 0.0, 0.0)), T(2, (25.4, 0.0, 0.0))]),
]
# fmt: on


@cases("prog,expected", UNIT_MOVES)
def test_units_scale_lengths(prog, expected) -> None:
    assert cmds(prog) == expected


# --- distance mode --------------------------------------------------------------------
# fmt: off
DISTANCES = [
    ("G91 adds", "G91 G0 X1\nX1", [T(1, (1.0, 0.0, 0.0)), T(2, (2.0, 0.0, 0.0))]),
    ("G90 after G91 is absolute", "G91\nG90\nG0 X1\nX1", [T(3, (1.0, 0.0, 0.0)), T(4, (1.0, 0.0, 0.0))]),
]
# fmt: on


@cases("prog,expected", DISTANCES)
def test_distance_mode(prog, expected) -> None:
    assert cmds(prog) == expected


def test_arc_centre_absolute_with_g90_1_incremental_with_g91_1() -> None:
    # from (10, 0) to (0, 10) counter-clockwise about the origin: I J are the centre itself
    # under G90.1, the centre minus the start under G91.1 (the default)
    (arc,) = cmds("G0 X10\nG90.1 G3 X0 Y10 I0 J0 F100\n")[1:]
    assert arc.center == (0.0, 0.0, 0.0)
    (arc,) = cmds("G90.1\nG91.1\nG0 X10\nG3 X0 Y10 I-10 J0 F100\n")[1:]
    assert arc.center == (0.0, 0.0, 0.0)


# --- feed mode --------------------------------------------------------------------------


def test_lathe_feed_per_revolution_and_per_minute() -> None:
    # G99: F0.2 mm/rev at 1000 rpm is 200 mm/min; G98: F150 is 150 mm/min
    moves = cmds("G97 S1000 M3\nG98\nG99 G1 W-1 F0.2\nG98 G1 W-1 F150\n", LATHE)[1:]
    assert [m.feed for m in moves] == [200.0, 150.0]


def test_mill_g95_then_g94() -> None:
    moves = cmds("S500 M3\nG95 G1 X1 F0.5\nG94 X2 F300\n")[1:]
    assert [m.feed for m in moves] == [250.0, 300.0]


# --- spindle mode and speed -------------------------------------------------------------
RPM_100 = 1000.0 * 200.0 / (math.pi * 100.0)  # 200 m/min at diameter 100 mm: 636.62 rpm


def test_g96_without_s_reissues_a_turning_spindle_at_the_surface_speed() -> None:
    # the S500 set under G97 becomes 500 m/min under G96: at diameter 100, 1591.5 rpm
    out = cmds("G0 X100 Z10\nS500 M3\nG96\n", LATHE)
    assert out[-1] == Spindle(3, CW, 1000.0 * 500.0 / (math.pi * 100.0), 500.0, None)


def test_g97_without_s_keeps_the_speed_turning_now() -> None:
    it, out = interp("G0 X100 Z10\nG96 S200 M3\nG97\n", LATHE)
    assert out[1] == Spindle(2, CW, pytest.approx(RPM_100), 200.0, None)
    assert out[2] == Spindle(3, CW, pytest.approx(RPM_100))
    assert it.state.spindle_rpm == pytest.approx(RPM_100)
    assert it.state.surface_speed is None


def test_g96_again_does_not_reissue_the_spindle() -> None:
    out = cmds("G0 X100 Z10\nG96 S200 M3\nG96\n", LATHE)
    assert [c.line for c in out if isinstance(c, Spindle)] == [2]


def test_g97_with_a_clamp_s_keeps_the_speed_turning_now() -> None:
    # the S of `G50 S2000` is the clamp, not a speed: G97 keeps 636.6 rpm (was: 200 rpm, the
    # surface speed's figure read as a speed)
    it, out = interp("G0 X100 Z10\nG96 S200 M3\nG97 G50 S2000\n", LATHE)
    assert out[-1] == Spindle(3, CW, pytest.approx(RPM_100))
    assert it.state.spindle_rpm == pytest.approx(RPM_100)


def test_g97_with_s_takes_the_new_speed() -> None:
    out = cmds("G0 X100 Z10\nG96 S200 M3\nG97 S700\n", LATHE)
    assert out[-1] == Spindle(3, CW, 700.0)


# (name, program, machine, surface speed, rpm)
# fmt: off
SPEEDS = [
    ("G96 in inch: S is ft/min", "G20 G96 S100", LATHE, 30.48),
    ("G96 in mm: S is m/min", "G21 G96 S100", LATHE, 100.0),
    ("S0 is a speed", "S0", MILL, 0.0),
]
# fmt: on


@cases("prog,params,expected", SPEEDS)
def test_speed_word(prog, params, expected) -> None:
    s = state(prog, params)
    got = s.surface_speed if s.gcodes["spindle_mode"] == "G96" else s.spindle_rpm
    assert got == pytest.approx(expected)


def test_g97_in_inch_is_rpm() -> None:
    assert state("G20 G97 S100", LATHE).spindle_rpm == 100.0


@pytest.mark.parametrize(
    ("prog", "params"),
    [("S500 M3\nG50 S2000\n", LATHE), ("S500 M3\nG92 S2000\n", MILL)],
    ids=["lathe G50 S", "mill G92 S"],
)
def test_s_of_a_clamp_code_is_not_the_spindle_speed(prog, params) -> None:
    it, out = interp(prog, params)
    assert out == [Spindle(1, CW, 500.0)]  # not re-issued at 2000
    assert it.state.spindle_rpm == 500.0


# --- path control: G61 G64 G103 G187 --------------------------------------------------
# (name, program, the last SetPathMode): default tolerance 0.01 mm
# fmt: off
PATH = [
    ("G61", "G61", SetPathMode(1, EXACT, 0.0, 0)),
    ("G64", "G64", SetPathMode(1, CONT, 0.01, 0)),
    ("G64 P0", "G64 P0", SetPathMode(1, CONT, 0.0, 0)),
    ("G64 P", "G64 P0.2", SetPathMode(1, CONT, 0.2, 0)),
    ("G64 P in inch", "G20 G64 P0.01", SetPathMode(1, CONT, 0.254, 0)),
    ("G64 after G64 P is the default again", "G64 P0.2\nG61\nG64", SetPathMode(3, CONT, 0.01, 0)),
    ("G61 keeps the look-ahead", "G103 P5\nG61", SetPathMode(2, EXACT, 0.0, 5)),
    ("G64 P keeps the look-ahead", "G103 P5\nG64 P0.2", SetPathMode(2, CONT, 0.2, 5)),
    ("G103 alone: the machine's", "G103 P5\nG103", SetPathMode(2, CONT, 0.01, 0)),
    ("G103 P0", "G103 P0", SetPathMode(1, CONT, 0.01, 0)),
    ("G103 P1", "G103 P1", SetPathMode(1, CONT, 0.01, 1)),
    ("G103 P15", "G103 P15", SetPathMode(1, CONT, 0.01, 15)),
    ("G103 under G61", "G61\nG103 P3", SetPathMode(2, EXACT, 0.0, 3)),
    ("G103 keeps the G64 P", "G64 P0.3\nG103 P2", SetPathMode(2, CONT, 0.3, 2)),
    ("G187 alone: the default", "G64 P0.3\nG187", SetPathMode(2, CONT, 0.01, 0)),
    ("G187 P1 rough: 4x", "G187 P1", SetPathMode(1, CONT, 0.04, 0)),
    ("G187 P2 medium: 1x", "G187 P2", SetPathMode(1, CONT, 0.01, 0)),
    ("G187 P3 finish: 1/4", "G187 P3", SetPathMode(1, CONT, 0.0025, 0)),
    ("G187 E", "G187 E0.05", SetPathMode(1, CONT, 0.05, 0)),
    ("G187 E above 1 mm", "G187 E1.5", SetPathMode(1, CONT, 1.5, 0)),
    ("G187 E wins over P", "G187 P1 E0.05", SetPathMode(1, CONT, 0.05, 0)),
    ("G187 E in inch", "G20 G187 E0.01", SetPathMode(1, CONT, 0.254, 0)),
    ("G187 keeps the look-ahead", "G103 P4\nG187 P3", SetPathMode(2, CONT, 0.0025, 4)),
    ("G187 under G61", "G61\nG187 P1", SetPathMode(2, EXACT, 0.0, 0)),
]
# fmt: on


@cases("prog,expected", PATH)
def test_path_control(prog, expected) -> None:
    last = [c for c in cmds(prog) if isinstance(c, SetPathMode)][-1]
    assert last.line == expected.line and last.mode is expected.mode
    assert last.tolerance == pytest.approx(expected.tolerance, abs=1e-12)
    assert last.lookahead == expected.lookahead


def test_g187_p_scales_the_machine_default_tolerance() -> None:
    params = MachineParams(axes=BIG, default_path_tolerance=0.02)
    assert [c.tolerance for c in cmds("G187\nG187 P1\nG187 P3\n", params)] == [
        0.02,
        0.08,
        0.005,
    ]


# --- refusals: message, line, column ----------------------------------------------------
# (name, program, machine, message, line, column)
# fmt: off
REFUSALS = [
    ("unit change after motion", "G0 X1\nG20", MILL,
     "G20/G21 unit change after motion (use one unit per program)", 2, 1),
    ("unit change after motion names its G", "G0 X1\nG0 G20 X2", MILL,
     "G20/G21 unit change after motion (use one unit per program)", 2, 4),
    ("unit change after G53", "G53 G0 X5\nG20", MILL,
     "G20/G21 unit change after motion (use one unit per program)", 2, 1),
    ("unit change after a G28 intermediate point", "G28 X5\nG20", MILL,
     "G20/G21 unit change after motion (use one unit per program)", 2, 1),
    ("negative S", "G0 X1 S-5", MILL, "S must not be negative", 1, 7),
    ("plane change in cutter compensation", "G41 D1 G1 X10 F100\nG1 X20\nG18", MILL,
     "plane change while cutter compensation is active", 3, 1),
    ("plane change in cutter compensation names its G", "G41 D1 G1 X10 F100\nG1 X20\nG1 G18 X30",
     MILL, "plane change while cutter compensation is active", 3, 4),
    ("negative F on a block with other codes", "G91 G1 X5 F-1", MILL, "F must not be negative", 1, 11),
    ("plane change in G68", "G68 R30\nG0 X1 G19", MILL,
     "plane change while G68 rotation is active", 2, 7),
    ("negative G64 P", "G64 P-0.1", MILL, "G64 P tolerance must not be negative", 1, 5),
    ("G187 P4", "G187 P4", MILL, "G187 P must be 1 (rough), 2 (medium) or 3 (finish)", 1, 6),
    ("G187 P0", "G187 P0", MILL, "G187 P must be 1 (rough), 2 (medium) or 3 (finish)", 1, 6),
    ("G187 E0", "G187 E0", MILL, "G187 E (corner rounding tolerance) must be > 0", 1, 6),
    ("G187 E<0", "G187 P2 E-1", MILL, "G187 E (corner rounding tolerance) must be > 0", 1, 9),
    ("G103 P16", "G103 P16", MILL, "G103 P (blocks of look-ahead) must be 0..15", 1, 6),
    ("G103 P-1", "G103 P-1", MILL, "G103 P (blocks of look-ahead) must be 0..15", 1, 6),
    ("G103 P1.5", "G103 P1.5", MILL, "G103 P (blocks of look-ahead) must be 0..15", 1, 6),
]
# fmt: on


@cases("prog,params,message,line,col", REFUSALS)
def test_refusals(prog, params, message, line, col) -> None:
    assert refused(lambda: cmds(prog, params)) == (message, line, col)


def test_the_same_plane_again_in_cutter_compensation_is_no_change() -> None:
    out = cmds("G41 D1 G1 X10 F100\nG17\nG1 X20\nG40 X30\n")
    assert out[-1] == StraightFeed(4, (30.0, 0.0, 0.0), 100.0)
