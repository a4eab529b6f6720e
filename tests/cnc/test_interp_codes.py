"""Table tests: every supported G and M code produces the expected canonical commands."""

import pytest

from cnc.canon import (
    ArcFeed,
    AuxFunction,
    Coolant,
    Dwell,
    PathMode,
    ProgramStop,
    SetPathMode,
    Spindle,
    SpindleDirection,
    StopKind,
    StraightFeed,
    StraightTraverse,
    ToolChange,
    ToolSelect,
)
from cnc.errors import NcError
from cnc.interp import Interpreter, ToolOffset
from cnc.params import AxisParams, MachineParams

BIG = tuple(AxisParams(a, -1000, 1000, 30000, 3000, 5e4) for a in "XYZ")
MILL = MachineParams(axes=BIG)
TOOLS = {1: ToolOffset(length=100.0, radius=5.0), 2: ToolOffset(length=50.0, radius=2.0)}
T, F = StraightTraverse, StraightFeed
CW, CCW, STOP, ORIENT = (SpindleDirection.CW, SpindleDirection.CCW, SpindleDirection.STOP,
                         SpindleDirection.ORIENT)  # fmt: skip


def run(text: str, **kw) -> list:
    kw.setdefault("tools", TOOLS)
    return list(Interpreter(kw.pop("params", MILL), **kw).run(text))


CASES = [
    # (name, program, expected commands from the last block)
    ("G0", "G0 X1 Y2 Z3", [T(1, (1.0, 2.0, 3.0))]),
    ("G1", "G1 X1 F50", [F(1, (1.0, 0.0, 0.0), 50.0)]),
    ("G9", "G9 G1 X1 F50", [F(1, (1.0, 0.0, 0.0), 50.0, True)]),
    ("G4 P", "G4 P250", [Dwell(1, 0.25)]),
    ("G4 X", "G4 X1.5", [Dwell(1, 1.5)]),
    ("G61", "G61", [SetPathMode(1, PathMode.EXACT_STOP)]),
    ("G64", "G64", [SetPathMode(1, PathMode.CONTINUOUS, 0.01)]),
    ("G64 P", "G64 P0.2", [SetPathMode(1, PathMode.CONTINUOUS, 0.2)]),
    ("G20 G64 P", "G20 G64 P0.1", [SetPathMode(1, PathMode.CONTINUOUS, 2.54)]),
    ("M0", "M0", [ProgramStop(1, StopKind.PROGRAM_STOP)]),
    ("M1", "M1", [ProgramStop(1, StopKind.OPTIONAL_STOP)]),
    ("M2", "M2", [ProgramStop(1, StopKind.PROGRAM_END)]),
    ("M30", "M30", [ProgramStop(1, StopKind.PROGRAM_END_REWIND)]),
    ("M3 S", "S800 M3", [Spindle(1, CW, 800.0)]),
    ("M4", "S800 M4", [Spindle(1, CCW, 800.0)]),
    ("M5", "M5", [Spindle(1, STOP, 0.0)]),
    ("M19", "S100 M19", [Spindle(1, ORIENT, 100.0)]),
    ("M7", "M7", [Coolant(1, True, False)]),
    ("M8", "M8", [Coolant(1, False, True)]),
    ("M7 M8", "M7 M8", [Coolant(1, True, True)]),
    ("M9", "M9", [Coolant(1, False, False)]),
    ("T", "T7", [ToolSelect(1, 7)]),
    ("T M6", "T7 M6", [ToolSelect(1, 7), ToolChange(1, 7)]),
    ("other M -> PLC", "M60", [AuxFunction(1, 60)]),
    ("two aux M", "M10 M11", [AuxFunction(1, 10), AuxFunction(1, 11)]),
]


@pytest.mark.parametrize(("name", "prog", "expected"), CASES, ids=[c[0] for c in CASES])
def test_single_block_codes(name: str, prog: str, expected: list) -> None:
    assert run(prog) == expected


def test_s_change_while_running_reissues_spindle() -> None:
    cmds = run("S500 M3\nS900\nM5\nS100\n")
    assert cmds == [Spindle(1, CW, 500.0), Spindle(2, CW, 900.0), Spindle(3, STOP, 900.0)]


def test_g17_g18_g19_plane_state() -> None:
    it = Interpreter(MILL)
    list(it.run("G18\n"))
    assert it.state.gcodes["plane"] == "G18"
    list(it.run("G19\n"))
    assert it.state.gcodes["plane"] == "G19"


def test_g28_via_intermediate_point_then_home() -> None:
    cmds = run("G0 X10 Y10 Z10\nG28 Z20\n")
    assert cmds[-2:] == [T(2, (10.0, 10.0, 20.0)), T(2, (10.0, 10.0, 0.0))]
    cmds = run("G0 X10 Y10 Z10\nG91 G28 X0 Y0\n")
    assert cmds[-1] == T(2, (0.0, 0.0, 10.0))


def test_g30_second_reference() -> None:
    params = MachineParams(axes=BIG, second_reference_mm=(-5.0, -6.0, -7.0))
    cmds = run("G0 X10 Y10 Z10\nG30 Z15\n", params=params)
    assert cmds[-1] == T(2, (10.0, 10.0, -7.0))


def test_g53_machine_coordinates_ignore_work_offset() -> None:
    cmds = run("G10 L2 P1 X100 Y100\nG0 X1 Y1\nG53 G0 X-5 Y-6\nG0 X2\n")
    assert cmds == [T(2, (101.0, 101.0, 0.0)), T(3, (-5.0, -6.0, 0.0)), T(4, (102.0, -6.0, 0.0))]


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5, 6])
def test_g54_to_g59_with_g10_l2(n: int) -> None:
    g = 53 + n
    cmds = run(f"G10 L2 P{n} X{n}0 Y-{n} Z1\nG{g} G0 X1 Y1 Z1\n")
    assert cmds == [T(2, (n * 10 + 1.0, -n + 1.0, 2.0))]


def test_g10_l2_incremental_and_common_offset() -> None:
    cmds = run("G10 L2 P1 X10\nG91 G10 L2 P1 X5\nG10 L2 P0 Y7\nG90 G0 X0 Y0\n")
    assert cmds == [T(4, (15.0, 7.0, 0.0))]


def test_work_offsets_constructor_and_switching_keeps_machine_position() -> None:
    it = Interpreter(MILL, work_offsets={1: (10.0, 0.0, 0.0), 2: (20.0, 0.0, 0.0)})
    cmds = list(it.run("G0 X1\nG55\nG0 X1\n"))
    assert [c.end[0] for c in cmds] == [11.0, 21.0]
    assert it.state.work_offset == "G55"


def test_g92_sets_current_position_without_moving() -> None:
    it = Interpreter(MILL)
    cmds = list(it.run("G0 X10 Y10\nG92 X0 Y0\nG0 X5\n"))
    assert cmds == [T(1, (10.0, 10.0, 0.0)), T(3, (15.0, 10.0, 0.0))]
    assert it.state.work_position == (5.0, 0.0, 0.0)


def test_tv_int_7_pendulum_g92_shift() -> None:
    sub = "O100\nG1 X1 Z-1 F100\nG0 Z0\nX0\nM99\n"
    cmds = run("M98 P100\nM00\nG92 X-50 Z-5\nM98 P100\nG92 X50 Z5\nM30\n", programs={100: sub})
    moves = [c.end for c in cmds if isinstance(c, F | T)]
    first, second = moves[:3], moves[3:6]
    assert all(
        b[0] - a[0] == 50.0 and b[2] - a[2] == 5.0 for a, b in zip(first, second, strict=True)
    )


def test_g94_g95_feed_per_revolution() -> None:
    cmds = run("S1000 M3\nG95 G1 X1 F0.1\nG94 X2 F300\n")
    assert cmds[1] == F(2, (1.0, 0.0, 0.0), 100.0) and cmds[2].feed == 300.0
    with pytest.raises(NcError, match="no spindle speed"):
        run("G95 G1 X1 F0.1\n")


def test_g96_css_rpm_follows_x_with_clamp() -> None:
    lathe = MachineParams(
        kind="lathe",
        axes=(AxisParams("X", -5, 500, 1e4, 1e3, 1e4), AxisParams("Z", -500, 500, 1e4, 1e3, 1e4)),
    )
    cmds = run("G0 X100 Z10\nG50 S2000\nG96 S200 M3\nG97 S500\n", params=lathe)
    sp = [c for c in cmds if isinstance(c, Spindle)]
    assert sp[0].surface_speed == 200.0 and sp[0].max_rpm == 2000.0
    assert sp[0].rpm == pytest.approx(1000 * 200 / (3.141592653589793 * 100))
    assert sp[1] == Spindle(4, CW, 500.0)
    cmds = run("G0 X1 Z10\nG50 S2000\nG96 S200 M3\n", params=lathe)
    assert cmds[-1].rpm == 2000.0  # clamped near the spindle axis


def test_g43_g44_g49_tool_length() -> None:
    cmds = run("G43 H1 G0 Z10\nG44 H2 Z10\nG49 Z10\n")
    assert [c.end[2] for c in cmds] == [110.0, -40.0, 10.0]


def test_g43_missing_offset_is_an_error() -> None:
    with pytest.raises(NcError, match="H9: no such tool offset"):
        run("G43 H9 Z1\n")


def test_tv_int_18_tool_length_compensation() -> None:
    # Z_PA = Z_NA - Z_PN: the same spindle travel with a 120 mm tool ends 120 mm higher
    cmds = run("G43 H1 G0 Z250\n", tools={1: ToolOffset(length=-120.0)})
    assert cmds[-1].end[2] == 130.0


def test_g15_g16_polar_tv_int_14() -> None:
    expected = {60: (60.0, 52.321), 120: (40.0, 52.321), 180: (30.0, 35.0),
                240: (40.0, 17.679), 300: (60.0, 17.679), 360: (70.0, 35.0)}  # fmt: skip
    prog = "G10 L2 P1 X50 Y35\nG16\n" + "".join(f"G1 X20 Y{a} F100\n" for a in expected)
    ends = [c.end for c in run(prog)]
    for (x, y), end in zip(expected.values(), ends, strict=True):
        assert end[0] == pytest.approx(x, abs=5e-4) and end[1] == pytest.approx(y, abs=5e-4)
    assert run("G16\nG15\nG0 X20 Y60\n")[-1].end == (20.0, 60.0, 0.0)


def test_g51_1_mirror_flips_arcs_and_g50_1_cancels() -> None:
    cmds = run("G51.1 X0\nG1 X10 Y5 F100\nG2 X20 Y5 R5\nG50.1 X0\nG1 X10 Y5\n")
    assert cmds[0].end == (-10.0, 5.0, 0.0)
    assert isinstance(cmds[1], ArcFeed) and cmds[1].clockwise is False
    assert cmds[2].end == (10.0, 5.0, 0.0)


def test_tv_int_13_mirror_quadrants() -> None:
    sub = "O7\nG0 X20 Y10\nX40\nY30\nX20\nM99\n"
    prog = "M98 P7\nG51.1 X0\nM98 P7\nG51.1 Y0\nM98 P7\nG50.1 X0\nM98 P7\nG50.1\nM30\n"
    ends = [c.end[:2] for c in run(prog, programs={7: sub}) if isinstance(c, T)]
    assert len(ends) == 16
    assert ends[:4] == [(20, 10), (40, 10), (40, 30), (20, 30)]
    assert ends[4:8] == [(-20, 10), (-40, 10), (-40, 30), (-20, 30)]
    assert ends[8:12] == [(-20, -10), (-40, -10), (-40, -30), (-20, -30)]
    assert ends[12:] == [(20, -10), (40, -10), (40, -30), (20, -30)]


def test_g51_scaling_and_g50_cancel() -> None:
    cmds = run("G51 X10 Y0 P2\nG1 X20 Y5 F100\nG2 X30 Y5 R5\nG50\nG1 X0 Y0\n")
    assert cmds[0].end == (30.0, 10.0, 0.0)
    assert cmds[1].end == (50.0, 10.0, 0.0) and cmds[1].center == (40.0, 10.0, 0.0)
    assert cmds[2].end == (0.0, 0.0, 0.0)
    with pytest.raises(NcError, match="unequal in-plane scaling"):
        run("G51 I2 J1\nG2 X10 Y0 R5 F100\n")


def test_g68_rotation_and_g69() -> None:
    cmds = run("G68 X10 Y0 R90\nG1 X20 Y0 F100\nG3 X10 Y10 R10\nG69\nG1 X0 Y0\n")
    assert cmds[0].end[0] == pytest.approx(10.0) and cmds[0].end[1] == pytest.approx(10.0)
    assert cmds[1].end[0] == pytest.approx(0.0) and cmds[1].end[1] == pytest.approx(0.0)
    assert cmds[1].clockwise is False
    assert cmds[2].end == (0.0, 0.0, 0.0)


def test_modal_state_snapshot() -> None:
    it = Interpreter(MILL, tools=TOOLS)
    list(it.run("N5 G91 G18 G95 G43 H1 G56 G61 G99 G20\nS300 M4 M8 T2 M6\nG1 F0.01\n"))
    s = it.state
    assert s.gcodes["distance"] == "G91" and s.gcodes["plane"] == "G18"
    assert s.gcodes["feed_mode"] == "G95" and s.gcodes["length_comp"] == "G43"
    assert s.gcodes["path_mode"] == "G61" and s.gcodes["return_level"] == "G99"
    assert s.work_offset == "G56" and s.units == "inch" and s.length_offset == 1
    assert (s.spindle, s.spindle_rpm, s.coolant_flood) == ("M4", 300.0, True)
    assert (s.tool_selected, s.tool_in_spindle) == (2, 2)
    assert s.feed == pytest.approx(0.01) and s.line == 3 and s.block_number == 5


def test_block_delete_switch() -> None:
    prog = "G0 X1\n/G0 X2\n/1 G0 X3\n"
    assert len(run(prog)) == 3
    assert len(run(prog, block_delete=True)) == 1


# G53 and G28/G30 word by word (mutation survivors in cnc/interp/offsets.py)
# fmt: off
MACHINE_MOVES = [
    ("G53 G1 feeds at the modal F", "G1 X0 F100\nG53 G1 X5 Y6 Z-7\n", [F(2, (5.0, 6.0, -7.0), 100.0)]),
    ("G53 takes the modal motion", "G1 X1 F100\nG53 X5\n", [F(2, (5.0, 0.0, 0.0), 100.0)]),
    ("G53 G1 stays modal", "G0 X1\nG53 G1 X5 F80\nX2\n", [F(3, (2.0, 0.0, 0.0), 80.0)]),
    ("G53 G0 is modal G0 too", "G1 X1 F100\nG53 G0 Z5\nX2\n", [T(3, (2.0, 0.0, 5.0))]),
    ("G53 moves only the named axes", "G0 X1 Y2 Z3\nG53 G0 Y-6\n", [T(2, (1.0, -6.0, 3.0))]),
    ("G28 without axis words goes home directly", "G0 X10 Y10 Z10\nG28\n", [T(2, (0.0, 0.0, 0.0))]),
    ("G28 X: only X goes home", "G0 X10 Y10 Z10\nG28 X4\n", [T(2, (4.0, 10.0, 10.0)), T(2, (0.0, 10.0, 10.0))]),
    ("G28 Y: only Y goes home", "G0 X10 Y10 Z10\nG28 Y4\n", [T(2, (10.0, 4.0, 10.0)), T(2, (10.0, 0.0, 10.0))]),
]
# fmt: on


@pytest.mark.parametrize(
    ("prog", "last"), [c[1:] for c in MACHINE_MOVES], ids=[c[0] for c in MACHINE_MOVES]
)
def test_machine_moves_and_reference_returns(prog, last) -> None:
    cmds = run(prog)
    assert cmds[-len(last) :] == last


def test_g30_p2_is_the_second_reference_and_p1_the_first() -> None:
    params = MachineParams(axes=BIG, second_reference_mm=(-5.0, -6.0, -7.0))
    assert run("G0 X10 Y10 Z10\nG30 P2 Z15\n", params=params)[-1] == T(2, (10.0, 10.0, -7.0))
    assert run("G0 X10 Y10 Z10\nG30 P1 Z15\n", params=params)[-1] == T(2, (10.0, 10.0, -7.0))
    with pytest.raises(NcError, match="G30 P3/P4"):
        run("G30 P4 Z1\n", params=params)


def test_g53_refusals() -> None:
    with pytest.raises(NcError, match="G53 moves only with G0 or G1"):
        run("G53 G2 X1 Y0 I1 F10\n")
    with pytest.raises(NcError, match="G53 moves only with G0 or G1"):
        run("G3 X1 Y1 R1 F10\nG53 X1\n")


def test_g53_under_g91_moves_by_the_increment() -> None:
    # O919100 (a Kitamura HMC's tool measuring macro): `G91 G53 G00 X#21 Y#22` goes by the
    # increment from where the tool stands, as Fanuc (G53 ignored under G91) and Mitsubishi
    params = MachineParams(axes=BIG)
    cmds = run("G0 X10 Y10 Z10\nG91 G53 G0 X-5 Y2\nG53 G1 Z-3 F100\n", params=params)
    assert [c.end for c in cmds[-2:]] == [(5.0, 12.0, 10.0), (5.0, 12.0, 7.0)]
    assert isinstance(cmds[-1], StraightFeed)


@pytest.mark.parametrize("p", ["0", "49", "1.5"])
def test_g54_1_outside_p1_to_p48_is_refused(p: str) -> None:
    with pytest.raises(NcError, match=rf"G54.1 P{p}: extended work offsets are P1..P48"):
        run(f"G54.1 P{p}\n")
