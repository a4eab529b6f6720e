"""Interpreter: motion words, arcs, distance modes, units and the seed test vectors."""

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cnc.canon import ArcFeed, Plane, StraightFeed, StraightTraverse
from cnc.errors import NcError
from cnc.interp import Interpreter
from cnc.params import AxisParams, DecimalStyle, MachineParams

BIG = (
    AxisParams("X", -1000, 1000, 30000, 3000, 5e4),
    AxisParams("Y", -1000, 1000, 30000, 3000, 5e4),
    AxisParams("Z", -1000, 1000, 30000, 3000, 5e4),
)
MILL = MachineParams(axes=BIG)
LATHE = MachineParams(
    kind="lathe",
    axes=(AxisParams("X", -500, 500, 1e4, 1e3, 1e4), AxisParams("Z", -500, 500, 1e4, 1e3, 1e4)),
)


def run(text: str, params: MachineParams = MILL, **kw) -> list:
    return list(Interpreter(params, **kw).run(text))


def moves(text: str, params: MachineParams = MILL, **kw) -> list:
    return [
        c
        for c in run(text, params, **kw)
        if isinstance(c, StraightTraverse | StraightFeed | ArcFeed)
    ]


def close(a, b, tol=1e-9) -> bool:
    return all(abs(x - y) <= tol for x, y in zip(a, b, strict=True))


def test_g0_g1_canonical_commands_carry_lines() -> None:
    cmds = moves("G0 X10 Y5\nG1 Z-2 F300\n")
    assert cmds == [
        StraightTraverse(1, (10.0, 5.0, 0.0)),
        StraightFeed(2, (10.0, 5.0, -2.0), 300.0),
    ]


def test_tv_int_1_absolute_equals_incremental() -> None:
    a = moves("G90 G0 X2 Z2\nG90 G01 X7 Z4 F100\n")[-1]
    b = moves("G90 G0 X2 Z2\nG91 G01 X5 Z2 F100\n")[-1]
    assert a == b and close(a.end, (7.0, 0.0, 4.0))


def test_003_abs_incr_mill() -> None:
    ends = [m.end for m in moves("G90 G00 X10. Y10.\nG91 X5.\nG90 X5.\n")]
    assert ends == [(10.0, 10.0, 0.0), (15.0, 10.0, 0.0), (5.0, 10.0, 0.0)]


def test_003_lathe_u_w_incremental_diameter() -> None:
    it = Interpreter(LATHE)
    cmds = list(it.run("G00 X20. Z5.\nU-4. W-2.\n"))
    assert cmds[-1].end == (8.0, 0.0, 3.0)  # machine X is a radius
    assert it.state.work_position == (16.0, 0.0, 3.0)  # work X shown as a diameter


def test_003_inch_g20_feed_and_distance() -> None:
    inch = moves("G20\nG0 X0\nG01 X1.0 F10.\n")[-1]
    assert close(inch.end, (25.4, 0.0, 0.0)) and inch.feed == pytest.approx(254.0)
    mm = moves("G21\nG0 X0\nG01 X1.0 F10.\n")[-1]
    assert mm.end == (1.0, 0.0, 0.0) and mm.feed == 10.0


@pytest.mark.parametrize(
    ("style", "unit", "word", "expected_mm"),
    [
        (DecimalStyle.LEAST_INCREMENT, "G21", "X25.", 25.0),
        (DecimalStyle.LEAST_INCREMENT, "G21", "X25", 0.025),
        (DecimalStyle.LEAST_INCREMENT, "G21", "X1", 0.001),
        (DecimalStyle.LEAST_INCREMENT, "G21", "X2.5", 2.5),
        (DecimalStyle.LEAST_INCREMENT, "G21", "X-0.5", -0.5),
        (DecimalStyle.LEAST_INCREMENT, "G21", "X.5", 0.5),
        (DecimalStyle.LEAST_INCREMENT, "G21", "X0", 0.0),
        (DecimalStyle.LEAST_INCREMENT, "G21", "X1000000", 1000.0),  # TV-PRG-1
        (DecimalStyle.LEAST_INCREMENT, "G21", "X50000", 50.0),  # TV-PRG-1 Philips
        (DecimalStyle.LEAST_INCREMENT, "G20", "X25", 0.0025 * 25.4),
        (DecimalStyle.LEAST_INCREMENT, "G20", "X1", 0.0001 * 25.4),
        (DecimalStyle.LEAST_INCREMENT, "G20", "X25.", 25 * 25.4),
        (DecimalStyle.CALCULATOR, "G21", "X25", 25.0),
        (DecimalStyle.CALCULATOR, "G20", "X25", 25 * 25.4),
        (DecimalStyle.CALCULATOR, "G21", "X2.5", 2.5),
    ],
)
def test_003_decimal_point_rules(style, unit, word, expected_mm) -> None:
    params = MachineParams(axes=BIG, decimal_style=style)
    m = moves(f"{unit}\nG0 {word}\n", params)[-1]
    assert m.end[0] == pytest.approx(expected_mm, abs=1e-12)


def test_least_increment_leaves_f_s_t_literal() -> None:
    params = MachineParams(axes=BIG, decimal_style=DecimalStyle.LEAST_INCREMENT)
    m = moves("G1 X1000 F100\n", params)[-1]
    assert m.end[0] == pytest.approx(1.0) and m.feed == 100.0


def test_unit_change_after_motion_is_refused() -> None:
    with pytest.raises(NcError, match="unit change after motion") as ei:
        run("G21\nG00 X60.0\nG20\n")
    assert ei.value.line == 3
    run("G21\nG0 X1\nG21\nG0 X2\n")  # restating the same unit is fine


def test_arc_ijk_incremental_centre() -> None:
    a = moves("G0 X10 Y0\nG3 X0 Y10 I-10 J0 F100\n")[-1]
    assert isinstance(a, ArcFeed) and not a.clockwise
    assert close(a.center, (0.0, 0.0, 0.0)) and close(a.end, (0.0, 10.0, 0.0))
    assert a.plane is Plane.XY and a.turns == 0


def test_arc_r_short_and_long() -> None:
    short = moves("G0 X0 Y0\nG2 X10 Y10 R10 F100\n")[-1]
    assert close(short.center, (10.0, 0.0, 0.0), 1e-9)
    long_ = moves("G0 X0 Y0\nG2 X10 Y10 R-10 F100\n")[-1]
    assert close(long_.center, (0.0, 10.0, 0.0), 1e-9)
    ccw = moves("G0 X0 Y0\nG3 X10 Y10 R10 F100\n")[-1]
    assert close(ccw.center, (0.0, 10.0, 0.0), 1e-9)


def test_full_circle_and_helix_and_turns() -> None:
    full = moves("G0 X10 Y0\nG2 X10 Y0 I-10 F100\n")[-1]
    assert full.end == (10.0, 0.0, 0.0) and full.center == (0.0, 0.0, 0.0)
    helix = moves("G0 X10 Y0\nG3 X-10 Y0 Z-5 I-10 F100\n")[-1]
    assert helix.end == (-10.0, 0.0, -5.0) and helix.center[2] == 0.0
    turns = moves("G0 X10 Y0\nG3 X10 Y0 Z-6 I-10 P3 F100\n")[-1]
    assert turns.turns == 2


@pytest.mark.parametrize(
    ("start", "block", "ok"),
    [
        ((19.85, 2.0), "G03 X18.225 Z-2.106 I13.850 K2", True),  # TV-INT-2
        ((1.072, 19.971), "G03 X19.850 Z2 I0 K0", False),  # TV-INT-3 at 0.01 mm
        ((0.0, 94.0), "G03 X11.943 Z83.165 I0 K82", True),  # TV-INT-4
        ((19.905, 1.951), "G03 X-19.905 Z1.951 I0 K0", True),  # TV-INT-5
        ((-2.45, -6.4), "G02 X-6.768 Z1.078 I-11.084 K-6.4", True),  # TV-INT-6
    ],
)
def test_tv_int_arc_consistency_absolute_centres(start, block, ok) -> None:
    prog = f"G18 G90.1\nG0 X{start[0]} Z{start[1]}\nF100\n{block}\n"
    if ok:
        a = moves(prog, arc_tolerance=0.01)[-1]
        assert isinstance(a, ArcFeed) and a.plane is Plane.ZX
    else:
        with pytest.raises(NcError, match=r"differ by 0\.049") as ei:
            run(prog, arc_tolerance=0.01)
        assert (ei.value.line, ei.value.col) == (4, 19)  # the K word
        moves(prog, arc_tolerance=0.05)  # accepted with the looser tolerance


def test_arc_radius_too_small_and_r_full_circle_refused() -> None:
    with pytest.raises(NcError, match="smaller than half the chord"):
        run("G0 X0 Y0\nG2 X10 Y0 R4 F100\n")
    with pytest.raises(NcError, match="full circle"):
        run("G0 X0 Y0\nG2 X0 Y0 R4 F100\n")


def test_planes_g18_g19_centres() -> None:
    a = moves("G18\nG0 X0 Z10\nG2 X10 Z0 K-10 F100\n")[-1]
    assert a.plane is Plane.ZX and close(a.center, (0.0, 0.0, 0.0))
    b = moves("G19\nG0 Y10 Z0\nG3 Y0 Z10 J-10 F100\n")[-1]
    assert b.plane is Plane.YZ and close(b.center, (0.0, 0.0, 0.0))


def test_soft_limits_name_axis_line_and_column() -> None:
    with pytest.raises(NcError) as ei:
        list(Interpreter(MachineParams()).run("G0 X-10\nG0 Y-10 X5\n"))
    e = ei.value
    assert (e.line, e.col) == (2, 9) and "axis X" in e.message and "soft limit" in e.message


def test_arc_extent_beyond_soft_limit() -> None:
    params = MachineParams(
        axes=(AxisParams("X", -100, 100, 1, 1, 1), AxisParams("Y", -5, 100, 1, 1, 1), BIG[2])
    )
    with pytest.raises(NcError, match="arc extent: axis Y"):
        list(Interpreter(params).run("G0 X10 Y0\nG2 X-10 Y0 I-10 F100\n"))  # dips to Y=-10
    list(Interpreter(params).run("G0 X10 Y0\nG3 X-10 Y0 I-10 F100\n"))  # goes over the top


def test_feed_without_f_refused() -> None:
    with pytest.raises(NcError, match="feed move without F") as ei:
        run("G1 X10\n")
    assert ei.value.line == 1


coords = st.floats(-200, 200, allow_nan=False).map(lambda v: round(v, 3))


@settings(max_examples=150, deadline=None)
@given(coords, coords, st.floats(0.5, 100), st.floats(0, 2 * math.pi), st.floats(0.05, 6.2),
       st.booleans(), st.booleans())  # fmt: skip
def test_property_arc_end_and_radius(cx, cy, r, a0, sweep, cw, use_r) -> None:
    sx, sy = cx + r * math.cos(a0), cy + r * math.sin(a0)
    a1 = a0 - sweep if cw else a0 + sweep
    ex, ey = cx + r * math.cos(a1), cy + r * math.sin(a1)
    g = "G2" if cw else "G3"
    if use_r:
        rr = r if sweep <= math.pi else -r
        word = f"R{rr:.12f}"
    else:
        word = f"I{cx - sx:.12f} J{cy - sy:.12f}"
    prog = f"G0 X{sx:.12f} Y{sy:.12f}\n{g} X{ex:.12f} Y{ey:.12f} {word} F500\n"
    a = moves(prog)[-1]
    assert close(a.end, (float(f"{ex:.12f}"), float(f"{ey:.12f}"), 0.0), 1e-9)
    r_start = math.hypot(sx - a.center[0], sy - a.center[1])
    r_end = math.hypot(a.end[0] - a.center[0], a.end[1] - a.center[1])
    assert abs(r_start - r_end) < 1e-6 and abs(r_start - r) < 1e-5
    assert a.clockwise == cw


def test_determinism() -> None:
    prog = "G0 X1 Y2\nG1 X5 F100\nG2 X9 Y2 R2\nG3 X1 Y2 R-4\n" * 20
    assert repr(run(prog)) == repr(run(prog))


def test_003_tv2_g20_is_modal_for_every_length_word() -> None:
    cmds = moves("G20\nG00 X1.0\nG01 X2.0 F10.\n")
    assert [c.end[0] for c in cmds] == pytest.approx([25.4, 50.8])


def test_003_tv14_dwell_p_ms_and_x_seconds() -> None:
    from cnc.canon import Dwell

    assert run("G04 P1000\nG04 X1.0\n") == [Dwell(1, 1.0), Dwell(2, 1.0)]
    li = MachineParams(axes=BIG, decimal_style=DecimalStyle.LEAST_INCREMENT)
    assert run("G04 X1000\nG04 P1000\n", li) == [Dwell(1, 1.0), Dwell(2, 1.0)]


def test_tv_int_5_g04_x1_is_one_second() -> None:
    from cnc.canon import Dwell

    assert run("N15 G04 X1\n") == [Dwell(1, 1.0)]


def test_lathe_arcs_in_g18_by_default_with_radius_i() -> None:
    a = moves("G98 G0 X20 Z0\nG2 X40 Z-10 I10 K0 F100\n", LATHE)[-1]  # G98: mm/min
    assert a.plane is Plane.ZX and a.end == (20.0, 0.0, -10.0)
    assert a.center == (20.0, 0.0, 0.0)  # start radius 10 + I10 = 20 on X (radius)


block_st = st.tuples(
    st.sampled_from(["G0", "G1", ""]),
    st.lists(st.sampled_from("XYZ"), min_size=0, max_size=3, unique=True),
    st.lists(st.integers(-300, 300), min_size=3, max_size=3),
)


@settings(max_examples=100, deadline=None)
@given(st.lists(block_st, min_size=1, max_size=30), st.sampled_from(["G90", "G91"]))
def test_property_fast_path_equals_full_path(blocks, dist) -> None:
    lines = [f"{dist} G1 F500"]
    for g, axes, vals in blocks:
        lines.append(" ".join([g] + [f"{a}{v / 10}" for a, v in zip(axes, vals, strict=False)]))
    fast = "\n".join(lines)
    slow = "\n".join(line + " G17" for line in lines)  # a modal word forces the full path
    assert run(fast) == run(slow)
