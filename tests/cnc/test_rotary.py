"""Rotary axes A/B/C in the NC kernel: words, offsets, limits, joint-space planning."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cnc.canon import PathMode, SetPathMode, StraightFeed, StraightTraverse
from cnc.config import builtin_machine
from cnc.errors import NcError
from cnc.interp import Interpreter
from cnc.interpolator import Motion
from cnc.params import AxisParams, DecimalStyle, MachineParams
from tests.cnc.test_planner_helpers import EPS, REL, derivatives, run

A_AXIS = AxisParams("A", -720.0, 720.0, 10800.0, 720.0, 14400.0)
MILL4 = MachineParams(axes=(*MachineParams().axes, A_AXIS))
START4 = (-100.0, -100.0, -100.0, 0.0)


def moves(program: str, params: MachineParams = MILL4, **kw):
    ip = Interpreter(params, start=kw.pop("start", START4), **kw)
    return [c for c in ip.run(program) if isinstance(c, StraightTraverse | StraightFeed)]


def ends(program: str, params: MachineParams = MILL4, **kw):
    return [c.end for c in moves(program, params, **kw)]


# --- rotary words ------------------------------------------------------------------------

ROTARY_WORDS = [
    # program, A at the end of each move (degrees, machine coordinates)
    ("G90 G0 A30\nA45", [30.0, 45.0]),
    ("G91 G0 A30\nA45", [30.0, 75.0]),
    ("G90 G0 A30\nG91 A-50\nG90 A10", [30.0, -20.0, 10.0]),
    ("G20 G90 G0 A90", [90.0]),  # degrees: never scaled by G20
    ("G20 G91 G0 X1 A10", [10.0]),  # ... while X is (X = 25.4 mm, below)
    ("G0 A10.5 X-90", [10.5]),
    ("G0 A90\nG92 A0\nG0 A10", [90.0, 100.0]),  # G92: the current angle is program zero
    ("G0 A90\nG53 A5", [90.0, 5.0]),  # G53: machine angle, offsets ignored
    ("G0 A90\nG28 G91 A0", [90.0, 0.0]),  # G28: the named rotary axis goes home
    ("G1 A30 F3600\nG1 X-90 A60", [30.0, 60.0]),
    ("G0 A30\nG68 X0 Y0 R90\nG0 A40", [30.0, 40.0]),  # rotation turns X Y, not A
]


@pytest.mark.parametrize(("program", "angles"), ROTARY_WORDS)
def test_rotary_words(program, angles):
    got = ends(program)
    assert [e[3] for e in got] == pytest.approx(angles, abs=1e-9)
    assert all(len(e) == 4 for e in got)


def test_g20_scales_x_but_not_a():
    (end,) = ends("G20 G91 G0 X1 A10")
    assert end[0] == pytest.approx(-100.0 + 25.4) and end[3] == 10.0


def test_least_increment_style_reads_a_without_a_point_in_thousandths_of_a_degree():
    params = replace(MILL4, decimal_style=DecimalStyle.LEAST_INCREMENT)
    assert [e[3] for e in ends("G0 A90\nA90.", params)] == pytest.approx([0.09, 90.0])


def test_a_work_offset_with_a_rotary_component_shifts_a():
    # work offsets given as X Y Z A: G54 puts program A0 at machine A 15
    got = ends("G54 G0 A10", work_offsets={1: (0.0, 0.0, 0.0, 15.0)})
    assert got[0][3] == 25.0


def test_a_rotary_only_block_keeps_x_y_z_and_feeds_in_degrees_per_minute():
    (cmd,) = moves("G1 A90 F3600")
    assert cmd.end == (*START4[:3], 90.0) and cmd.feed == 3600.0


def test_three_axis_machine_keeps_three_axis_poses():
    assert all(len(e) == 3 for e in ends("G0 X-10 Y-10 Z-10", MachineParams(), start=None))


# --- bad input ---------------------------------------------------------------------------

BAD = [
    # program, machine, line:col, words in the message
    (
        "G0 X-10\nG0 X-20 A30",
        MachineParams(),
        "2:9",
        "unknown address A (axis A is not configured)",
    ),
    ("G0 X-10 B30", MILL4, "1:9", "unknown address B (axis B is not configured)"),
    ("G0 A30\nG0 A800", MILL4, "2:4", "axis A move to 800.0000 deg is beyond the soft limit"),
    ("G91 G0 A700\nA30", MILL4, "2:1", "beyond the soft limit [-720, 720] deg"),
    ("G2 X-90 Y-100 R5 A10 F100", MILL4, "1:18", "moves only with G0/G1"),
    ("G81 X-90 Z-110 R-95 A10 F100", MILL4, "1:21", "not in a circle or a canned cycle"),
    ("G41 D1 G1 X-90 F100\nG1 X-80 A10", MILL4, "2:9", "with cutter compensation active"),
    ("G4 P1 A10", MILL4, "1:7", "moves only with G0/G1"),
]


@pytest.mark.parametrize(("program", "params", "where", "text"), BAD)
def test_bad_rotary_input_names_line_and_column(program, params, where, text):
    with pytest.raises(NcError) as exc:
        list(Interpreter(params, start=None, tools=None).run(program))
    err = exc.value
    assert f"{err.line}:{err.col}" == where, str(err)
    assert text in err.message


def test_a_continuous_axis_has_no_soft_limit():
    c = replace(A_AXIS, name="C", continuous=True)
    params = MachineParams(axes=(*MachineParams().axes, c))
    assert ends("G91 G0 C3600\nC3600", params)[-1][3] == 7200.0


# --- planning in joint space -------------------------------------------------------------


def _pose_limits(params: MachineParams):
    """(velocity, accel, jerk) per pose component, in the pose's order."""
    by = {a.name: a for a in params.axes}
    axes = [by[n] for n in params.pose_axes]
    return [(a.max_velocity / 60.0, a.max_accel, a.max_jerk) for a in axes]


def assert_joint_limits(params, samples, start):
    ipo = params.ipo_cycle_s
    vmax, amax, jmax, scale = derivatives(samples, start, ipo)
    floor = [2 * EPS * scale / ipo, 4 * EPS * scale / ipo**2, 8 * EPS * scale / ipo**3]
    for i, (v, a, j) in enumerate(_pose_limits(params)):
        assert vmax[i] <= v * (1 + REL) + floor[0], ("vel", i, vmax[i], v)
        assert amax[i] <= a * (1 + REL) + floor[1], ("acc", i, amax[i], a)
        assert jmax[i] <= j * (1 + REL) + floor[2], ("jerk", i, jmax[i], j)
    return vmax


def test_a_rotary_move_is_limited_by_the_rotary_axis():
    # 100 mm of X and 400 degrees of A: A's 180 deg/s caps X at 45 mm/s (2700 mm/min)
    cmds = [StraightFeed(1, (0.0, -100.0, -100.0, 400.0), 6000.0)]
    samples, _ = run(MILL4, cmds, start=START4)
    vmax = assert_joint_limits(MILL4, samples, START4)
    assert vmax[3] == pytest.approx(180.0, rel=1e-3)
    assert vmax[0] == pytest.approx(45.0, rel=1e-3)
    assert samples[-1].pose == (0.0, -100.0, -100.0, 400.0)


def test_a_pure_rotary_move_runs_at_f_degrees_per_minute():
    cmds = [StraightFeed(1, (*START4[:3], 90.0), 3600.0)]  # 60 deg/s
    samples, _ = run(MILL4, cmds, start=START4)
    v = max(s.velocity for s in samples)
    assert v == pytest.approx(60.0, rel=1e-6)
    assert all(s.pose[:3] == START4[:3] for s in samples)


def test_the_rotary_axis_moves_linearly_with_the_path():
    end = (-80.0, -100.0, -100.0, 30.0)
    samples, _ = run(MILL4, [StraightFeed(1, end, 1200.0)], start=START4)
    for s in samples:
        frac = (s.pose[0] - START4[0]) / 20.0
        assert s.pose[3] == pytest.approx(30.0 * frac, abs=1e-9)


angle = st.floats(min_value=-180.0, max_value=180.0, allow_nan=False).map(lambda x: round(x, 2))
coord = st.floats(min_value=-20.0, max_value=20.0, allow_nan=False).map(lambda x: round(x, 3))


@st.composite
def rotary_programs(draw):
    n = draw(st.integers(min_value=1, max_value=6))
    tol = draw(st.sampled_from([0.001, 0.01, 0.1]))
    cmds: list = [SetPathMode(1, PathMode.CONTINUOUS, tol)]
    pos = list(START4)
    for i in range(n):
        kind = draw(st.sampled_from(["g1", "g1", "g0", "rotary", "linear"]))
        end = list(pos)
        if kind != "rotary":
            end[0] = START4[0] + draw(coord)
            end[1] = START4[1] + draw(coord)
            end[2] = START4[2] + draw(coord)
        if kind != "linear":
            end[3] = draw(angle)
        f = draw(st.sampled_from([600.0, 3000.0, 12000.0]))
        cmd = (
            StraightTraverse(i + 2, tuple(end))
            if kind == "g0"
            else StraightFeed(i + 2, tuple(end), f)
        )
        cmds.append(cmd)
        pos = end
    return cmds, tuple(pos)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(rotary_programs())
def test_joint_space_interpolation_respects_every_axis_limit(prog):
    cmds, end = prog
    samples, _ = run(MILL4, cmds, start=START4)
    assert_joint_limits(MILL4, samples, START4)
    assert samples[-1].pose == pytest.approx(end, abs=1e-9)


def test_five_axis_poses_plan_with_both_rotary_axes():
    params = builtin_machine("mill5").params
    start = (0.0, 0.0, 50.0, 0.0, 0.0)
    cmds = [StraightFeed(1, (10.0, 5.0, 40.0, 20.0, 90.0), 3000.0),
            StraightFeed(2, (20.0, 5.0, 30.0, 25.0, 120.0), 3000.0)]  # fmt: skip
    m = Motion(params, start=start)
    samples, _ = run(params, cmds, start=start, motion=m)
    assert_joint_limits(params, samples, start)
    assert samples[-1].pose == (20.0, 5.0, 30.0, 25.0, 120.0)


def test_a_rotary_axis_in_a_circle_is_refused_by_the_planner():
    from cnc.canon import ArcFeed, Plane

    m = Motion(MILL4, start=START4)
    arc = ArcFeed(7, (-90.0, -100.0, -100.0, 10.0), (-95.0, -100.0, -100.0, 0.0), Plane.XY,
                  True, 600.0)  # fmt: skip
    with pytest.raises(NcError, match="rotary axis cannot turn in a circular"):
        m.push(arc)


def test_planner_refuses_a_pose_of_the_wrong_length():
    m = Motion(MILL4, start=START4)
    with pytest.raises(NcError, match="pose has 3 axes, machine has 4"):
        m.push(StraightFeed(3, (0.0, 0.0, 0.0), 100.0))


def test_mill5_tool_tip_of_the_home_pose_is_the_programmed_point():
    from cnc.kinematics import MillBC45, bc45_inverse, kinematics_for

    kin = kinematics_for(builtin_machine("mill5").params)
    assert isinstance(kin, MillBC45) and kin.d == 100.0
    j = bc45_inverse((20.0, 0.0, -155.0), (0.6327447124, 0.465569252, 0.6187742456), 100.0)
    tip = kin.tool_tip((j.x, j.y, j.z, j.b, j.c))
    assert tip == pytest.approx((20.0, 0.0, -155.0), abs=1e-9)
    assert math.isfinite(j.c)


# --- Macro B system variables of the rotary 4th axis (#5004 family, #52x4 offsets) --------

# G54 carries an A component of 10 deg, so program and machine angles differ by 10.
G54_A10 = {1: (0.0, 0.0, 0.0, 10.0)}
ROTARY_VARIABLES = [
    # program (the value read into #100), expected #100, in degrees
    ("G90 G0 A30\n#100=#5004", 30.0),  # block end point, program angle
    ("G90 G0 A30\n#100=#5024", 40.0),  # machine angle = program + G54 A
    ("G90 G0 A30\n#100=#5044", 30.0),  # current position, program angle
    ("G90 G0 A30\n#100=#5064", 30.0),  # skip position (no G31 on A: where it stands)
    ("G90 G0 A30\n#100=#5084", 0.0),  # tool length offset along A: none
    ("G90 G0 A30\n#100=#5104", 0.0),  # servo deviation: the interpreter's axes are ideal
    ("G20 G90 G0 A30\n#100=#5004", 30.0),  # degrees: never scaled by G20
    ("G91 G0 A-45\n#100=#5024", -35.0),  # start at machine 10 (program 0), then -45
    ("#100=#5224", 10.0),  # G54's A component
    ("#100=#5204", 0.0),  # EXT's: none
    ("G55 G90 G0 A30\n#100=#5044", 30.0),  # G55 has no A offset: machine = program
    ("G55 G90 G0 A30\n#100=#5024", 30.0),
    ("#5224=25.\nG90 G0 A5\n#100=#5024", 30.0),  # a written offset moves the next A move
    ("G90 G0 A30\n#5224=0\n#100=#5004", 40.0),  # ... and the program angle of the table
    ("#7004=7.\nG54.1 P1 G90 G0 A0\n#100=#5024", 7.0),  # G54.1 P1's A component
    ("G90 G0 A30\n#100=#5005", 0.0),  # no 5th axis on a mill4: 0, as X Y Z's #5004 on mill3
]


def _read(program: str, params: MachineParams = MILL4, **kw) -> float | None:
    kw = {"start": (-100.0, -100.0, -100.0, 10.0), "work_offsets": G54_A10, **kw}
    ip = Interpreter(params, **kw)
    list(ip.run(program + "\nM30\n"))
    return ip.vars.common.get(100)


@pytest.mark.parametrize(("program", "value"), ROTARY_VARIABLES)
def test_rotary_axis_system_variables(program, value):
    assert _read(program) == pytest.approx(value, abs=1e-9)


def test_rotary_variables_on_the_shipped_mill4_and_a_mill_without_a():
    mill4 = builtin_machine("mill4").params
    ip = Interpreter(mill4, machine_data=builtin_machine("mill4").machine_data.initial())
    list(ip.run("G90 G54 G0 A-90.\n#100=#5004\n#101=#5024\nM30\n"))
    assert (ip.vars.common[100], ip.vars.common[101]) == (-90.0, -90.0)
    # a 3-axis mill has no 4th axis: reading gives 0, writing its offset is refused
    assert _read("#100=#5004", MachineParams(), start=None, work_offsets=None) == 0.0
    with pytest.raises(NcError, match=r"PS0115 variable #5224 does not exist"):
        list(Interpreter(MachineParams()).run("#5224=5.\nM30\n"))
