"""G40/G41/G42 through the interpreter: cnc.cutter_comp integration, order and errors."""

import math

import pytest

from cnc.canon import ArcFeed, Coolant, StraightFeed, StraightTraverse
from cnc.errors import NcError
from cnc.interp import Interpreter, ToolOffset
from cnc.params import AxisParams, MachineParams

BIG = tuple(AxisParams(a, -1000, 1000, 30000, 3000, 5e4) for a in "XYZ")
MILL = MachineParams(axes=BIG)
TOOLS = {1: ToolOffset(radius=5.0), 2: ToolOffset(radius=50.0)}


def run(text: str, **kw) -> list:
    return list(Interpreter(MILL, tools=TOOLS, **kw).run(text))


def test_tv_int_16_left_and_right_of_a_line_along_x() -> None:
    left = run("G0 X0 Y0\nG41 D1 G1 X10 Y0 F100\nX50\nG40 G1 X60 Y0\nM30\n")
    mid = [c for c in left if isinstance(c, StraightFeed) and c.line == 3][0]
    assert mid.end[1] == pytest.approx(5.0)
    right = run("G0 X0 Y0\nG42 D1 G1 X10 Y0 F100\nX50\nG40 G1 X60 Y0\nM30\n")
    mid = [c for c in right if isinstance(c, StraightFeed) and c.line == 3][0]
    assert mid.end[1] == pytest.approx(-5.0)


def test_inside_corner_trim_and_order_of_non_motion_commands() -> None:
    cmds = run("G0 X0 Y0 Z0\nG41 D1 G1 X10 F100\nX20\nM8\nY10\nG40 X30 Y20\nM30\n")
    kinds = [type(c).__name__ for c in cmds]
    assert kinds.index("Coolant") > max(
        i for i, c in enumerate(cmds) if isinstance(c, StraightFeed) and c.line == 3
    )
    ends = {c.line: c.end for c in cmds if isinstance(c, StraightFeed)}
    assert ends[3] == pytest.approx((15.0, 5.0, 0.0))  # inside corner: stops short
    assert ends[5] == pytest.approx((15.0, 10.0, 0.0))
    assert ends[6] == pytest.approx((30.0, 20.0, 0.0))  # cancel move ends uncompensated
    assert any(isinstance(c, Coolant) for c in cmds)


def test_outside_corner_gets_an_arc_and_z_plunge_passes_through() -> None:
    cmds = run("G0 X0 Y0 Z5\nG42 D1 G1 X10 F100\nZ-1\nX20\nY10\nG40 X30 Y20\nM30\n")
    assert any(isinstance(c, ArcFeed) for c in cmds)  # right turn... left side: outside
    z = [c for c in cmds if isinstance(c, StraightFeed) and c.line == 3][0]
    assert z.end[2] == -1.0


def test_compensated_arc_radius_grows_or_shrinks_by_the_tool_radius() -> None:
    prog = "G0 X-20 Y-30\nG41 D1 G1 X0 Y-20 F100\nG3 X0 Y20 I0 J20\nG40 G1 X-20 Y30\nM30\n"
    arcs = [c for c in run(prog) if isinstance(c, ArcFeed) and c.line == 3]
    a = arcs[0]
    r = math.hypot(a.end[0] - a.center[0], a.end[1] - a.center[1])
    assert r == pytest.approx(15.0)  # G41 on a CCW arc: tool inside, R - r


def test_gouge_is_an_error_with_line() -> None:
    with pytest.raises(NcError) as ei:
        run("G0 X0 Y0\nG41 D2 G1 X10 F100\nX20\nY5\nX30\nG40 X40 Y0\nM30\n")
    assert 2 <= ei.value.line <= 6


def test_radius_comes_from_d_and_missing_d_is_an_error() -> None:
    with pytest.raises(NcError, match="D9: no such tool offset"):
        run("G41 D9 G1 X1 F100\n")


def test_g41_refused_with_canned_cycle_and_plane_change() -> None:
    with pytest.raises(NcError, match="canned cycle with cutter compensation"):
        run("G0 Z10\nG41 D1 G1 X10 F100\nG81 X20 Z-1 R2\n")
    with pytest.raises(NcError, match="plane change"):
        run("G41 D1 G1 X10 F100\nG18\n")


def test_rapid_moves_under_compensation_stay_rapid() -> None:
    cmds = run("G0 X0 Y0\nG41 D1 X10\nG1 X20 F100\nG40 G0 X30\nM30\n")
    assert isinstance([c for c in cmds if c.line == 2][0], StraightTraverse)


def test_mirror_swaps_the_compensation_side() -> None:
    prog = "G0 X0 Y0\n{m}G41 D1 G1 X10 F100\nX50\nG40 G1 X60\nM30\n"
    plain = [c for c in run(prog.format(m="")) if isinstance(c, StraightFeed) and c.line == 3]
    mirrored = [
        c for c in run(prog.format(m="G51.1 X0\n")) if isinstance(c, StraightFeed) and c.line == 4
    ]
    assert plain[0].end == pytest.approx((50.0, 5.0, 0.0))
    # mirrored in X: the path runs towards -X and the tool keeps to the mirrored side (+Y),
    # i.e. G41 acts as G42 on the machine, as on a Fanuc with programmable mirror image
    assert mirrored[0].end == pytest.approx((-50.0, 5.0, 0.0))


def test_g41_refused_clearly_when_the_compensation_module_is_missing(monkeypatch) -> None:
    import sys

    monkeypatch.setitem(sys.modules, "cnc.cutter_comp", None)
    with pytest.raises(NcError, match="cutter radius compensation is not available") as ei:
        run("G0 X0 Y0\nG41 D1 G1 X10 F100\n")
    assert (ei.value.line, ei.value.col) == (2, 1)


def test_a_helix_of_rounded_arcs_is_no_gouge() -> None:
    # Near-full CCW turns (355 deg) of R 12.7 with end points rounded to 3 decimals: the end
    # radii differ by up to 0.00045, so the interpreter moves each centre onto its chord's
    # bisector, by about 0.005 for a 1.1 mm chord. Layer after layer the tool path (R 10.2,
    # r 2.5) then runs ~0.009 closer than r to the next turn's corrected contour: the
    # interpreter's own correction, allowed (without it this was refused at line 5).
    prog = (
        "G17 G21 G90\nG0 X0 Y0\nG1 Z-1 F500\nG41 D3 X12.7 Y0\n"
        "G3 X12.652 Y-1.107 I-12.7 J0 Z-2\n"
        "G3 X12.507 Y-2.205 I-12.652 J1.107 Z-3\n"
        "G3 X12.267 Y-3.287 I-12.507 J2.205 Z-4\n"
        "G40 G1 X0 Y0\nM30\n"
    )
    cmds = list(Interpreter(MILL, tools={3: ToolOffset(radius=2.5)}).run(prog))
    arcs = [c for c in cmds if isinstance(c, ArcFeed)]
    assert sorted({a.line for a in arcs}) == [5, 6, 7]
    # each turn on the offset circle of its own (corrected) centre; a micro corner arc of
    # radius r where the rounded turns meet slightly off tangent
    radii = sorted(round(math.dist(a.end[:2], a.center[:2]), 2) for a in arcs)
    assert set(radii) <= {2.5, 10.2} and radii.count(10.2) == 3
