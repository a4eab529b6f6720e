"""Lathe cycles (Fanuc T, system A): each cycle's generated path against a hand-computed pass
list, the contour reader, and the bad input each with its line, column and alarm number.

Conventions of the pass lists: `G0`/`G1`/`G2`/`G3` then X as a DIAMETER and Z, in mm, as
the program writes them (the canonical moves carry the radius; the helper doubles it).
Threading moves are `G1` whose feed is lead x rpm. Every program starts with the spindle at
a fixed speed (G97) so a feed per revolution is a known mm/min.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cnc.canon import ArcFeed, Spindle, StraightFeed, StraightTraverse
from cnc.errors import NcError
from cnc.interp import Interpreter
from cnc.interp import lathe_geometry as lg
from cnc.params import AxisParams, MachineParams

LATHE = MachineParams(
    kind="lathe",
    axes=(
        AxisParams("X", -1000, 1000, 20000, 4000, 60000),
        AxisParams("Z", -1000, 1000, 24000, 3000, 50000),
    ),
)
HEAD = "G18 G21 G40 G80 G99\nG97 S1000 M3\n"  # F0.2 mm/rev = 200 mm/min


def run(text: str, params: MachineParams = LATHE, **kw) -> list:
    return list(Interpreter(params, **kw).run(text))


def moves(cmds: list, line: int | None = None) -> list[str]:
    out = []
    for c in cmds:
        if line is not None and c.line != line:
            continue
        if isinstance(c, StraightTraverse):
            k = "G0"
        elif isinstance(c, StraightFeed):
            k = "G1"
        elif isinstance(c, ArcFeed):
            k = "G2" if c.clockwise else "G3"
        else:
            continue
        out.append(f"{k} X{round(c.end[0] * 2, 3):g} Z{round(c.end[2], 3):g}")
    return out


def feeds(cmds: list, line: int) -> list[float]:
    return [c.feed for c in cmds if isinstance(c, StraightFeed) and c.line == line]


# --- single cycles ------------------------------------------------------------------------


def test_g90_turning_cycle_is_modal_and_repeats_with_a_new_x() -> None:
    # A = X50 Z2. Each pass: rapid X to the cut diameter, feed Z to -20, feed out to X50,
    # rapid back to Z2. The second block gives only X35: Z-20 is kept.
    cmds = run(HEAD + "G0 X50 Z2\nG90 X40 Z-20 F0.2\nX35\nG0 X60\n")
    assert moves(cmds, 4) == ["G0 X40 Z2", "G1 X40 Z-20", "G1 X50 Z-20", "G0 X50 Z2"]
    assert moves(cmds, 5) == ["G0 X35 Z2", "G1 X35 Z-20", "G1 X50 Z-20", "G0 X50 Z2"]
    assert moves(cmds, 6) == ["G0 X60 Z2"]  # G0 ended the cycle
    assert feeds(cmds, 4) == [200.0, 200.0]


def test_g90_taper_r_is_the_radius_difference_start_minus_end() -> None:
    # the cut starts 2 mm (radius) below the end: X36 at Z2 to X40 at Z-20.
    cmds = run(HEAD + "G0 X50 Z2\nG90 X40 Z-20 R-2 F0.2\n")
    assert moves(cmds, 4) == ["G0 X36 Z2", "G1 X40 Z-20", "G1 X50 Z-20", "G0 X50 Z2"]


def test_g94_facing_cycle() -> None:
    # A = X52 Z2: rapid Z to -2, feed X to 10, feed back to Z2, rapid out to X52.
    cmds = run(HEAD + "G0 X52 Z2\nG94 X10 Z-2 F0.2\nZ-4\nG80\n")
    assert moves(cmds, 4) == ["G0 X52 Z-2", "G1 X10 Z-2", "G1 X10 Z2", "G0 X52 Z2"]
    assert moves(cmds, 5) == ["G0 X52 Z-4", "G1 X10 Z-4", "G1 X10 Z2", "G0 X52 Z2"]


def test_g92_threading_cycle_feed_is_lead_times_rpm() -> None:
    # S500, lead 1.5: the thread feeds 750 mm/min; three passes X19.2, X18.8, X18.376.
    prog = "G97 S500 M3\nG0 X30 Z5\nG92 X19.2 Z-20 F1.5\nX18.8\nX18.376\nG0 X40\n"
    cmds = run(prog)
    assert moves(cmds, 3) == ["G0 X19.2 Z5", "G1 X19.2 Z-20", "G0 X30 Z-20", "G0 X30 Z5"]
    assert moves(cmds, 5) == ["G0 X18.376 Z5", "G1 X18.376 Z-20", "G0 X30 Z-20", "G0 X30 Z5"]
    assert feeds(cmds, 3) == [750.0]
    assert feeds(cmds, 4) == [750.0]


def test_g32_thread_feed_and_taper_thread_lead_on_the_long_axis() -> None:
    # Straight: lead 2 at 400 rpm = 800 mm/min on Z. Taper X20 -> X24 (radius +2) over
    # Z 0 -> -20: the lead is along Z (the long axis), so the path feed is
    # 800 x sqrt(2^2 + 20^2) / 20 = 804.0 mm/min.
    cmds = run("G97 S400 M3\nG0 X20 Z2\nG32 Z-20 F2\nG0 X30\nZ0\nX20\nG32 X24 Z-20\n")
    assert feeds(cmds, 3) == [800.0]
    assert feeds(cmds, 7) == [pytest.approx(800.0 * math.hypot(2, 20) / 20)]


# --- G71 / G72 ----------------------------------------------------------------------------

G71_TYPE1 = (
    HEAD
    + "G0 X50 Z2\n"  # 3: A = X50 Z2 (radius 25)
    + "G71 U2 R0.5\n"  # 4: depth 2 (radius), retract 0.5
    + "G71 P10 Q20 U0.5 W0.1 F0.2\n"  # 5
    + "N10 G0 X20\n"  # 6: A' = X20 (X only: type I)
    + "G1 Z-20\n"
    + "X30 Z-30\n"
    + "Z-40\n"
    + "N20 X50\n"  # 10: B
    + "G0 X100 Z50\n"  # 11: execution resumes here, after N20
)


def test_g71_type1_passes() -> None:
    # Contour translated by U/2 = 0.25 (radius) and W = 0.1: (10.25, 2.1) -> (10.25, -19.9)
    # -> (15.25, -29.9) -> (15.25, -39.9) -> (25.25, -39.9).
    # Levels from x0 = 25 down by 2 above 10.25: 23 21 19 17 15 13 11 (diameters 46..22).
    # Levels 23..17 (dia 46..34) meet the contour at the last element, Z-39.9; level 15
    # (dia 30) meets the taper at 10.25 + 10 t = 15 -> t = 0.475... no: the taper runs
    # x 10.25 -> 15.25 over z -19.9 -> -29.9, so x = 15 at z = -19.9 - 10 x 4.75/5 = -29.4;
    # level 13 (dia 26) at -19.9 - 10 x 2.75/5 = -25.4; level 11 (dia 22) at -21.4.
    # Each pass: G0 X level, G1 Z end, G1 45-degree pull-off by 0.5 (dia +1, Z +0.5), G0 Z2.
    cmds = run(G71_TYPE1)
    got = moves(cmds, 5)
    ends = {46: -39.9, 42: -39.9, 38: -39.9, 34: -39.9, 30: -29.4, 26: -25.4, 22: -21.4}
    want = []
    for dia, z in ends.items():
        want += [
            f"G0 X{dia} Z2",
            f"G1 X{dia} Z{z:g}",
            f"G1 X{dia + 1} Z{z + 0.5:g}",
            f"G0 X{dia + 1} Z2",
        ]
    # the contour pass: to A' (translated), the contour at feed, out to x0, back to A
    want += [
        "G0 X20.5 Z2",
        "G0 X20.5 Z2.1",
        "G1 X20.5 Z-19.9",
        "G1 X30.5 Z-29.9",
        "G1 X30.5 Z-39.9",
        "G1 X50.5 Z-39.9",
        "G0 X50 Z-39.9",
        "G0 X50 Z2",
    ]
    assert got == want
    assert set(feeds(cmds, 5)) == {200.0}
    # the contour blocks were skipped: the next move is line 11's
    assert [c.line for c in cmds if isinstance(c, StraightTraverse | StraightFeed)][-1] == 11
    assert moves(cmds, 11) == ["G0 X100 Z50"]


def test_g71_type2_pocket() -> None:
    # A = X42 Z2 (radius 21), depth 3, retract 0.5, no allowance. Contour (radius):
    # (10,2) (10,-10) (16,-10) (16,-20) (11,-25) (11,-30) (16,-35) (21,-35): a pocket
    # between Z-20 and Z-35. The ns block names Z: type II.
    # Level 18 (dia 36): one span to Z-35.
    # Level 15 (dia 30): spans Z2..-10 and -21..-34 (the flanks cross x=15 at t=1/5, 4/5).
    # Level 12 (dia 24): spans Z2..-10 and -24..-31.
    # Pocket after pocket (depth first): the region at the start down to level 12, then the
    # pocket from level 15 to 12. A pocket pass: out to x0, along Z to its start, down to
    # the level above in rapid, feed to the level, feed along, pull off; after the last
    # pocket out to x0 and back to z0.
    prog = (
        HEAD
        + "G0 X42 Z2\nG71 U3 R0.5\nG71 P10 Q20 F0.2\n"
        + "N10 G0 X20 Z2\nG1 Z-10\nX32\nZ-20\nX22 Z-25\nZ-30\nX32 Z-35\nN20 X42\n"
    )
    got = moves(run(prog), 5)
    assert got == [
        "G0 X36 Z2", "G1 X36 Z-35", "G1 X37 Z-34.5", "G0 X37 Z2",
        "G0 X30 Z2", "G1 X30 Z-10", "G1 X31 Z-9.5", "G0 X31 Z2",
        "G0 X24 Z2", "G1 X24 Z-10", "G1 X25 Z-9.5",
        "G0 X42 Z-9.5", "G0 X42 Z-21", "G0 X36 Z-21", "G1 X30 Z-21", "G1 X30 Z-34",
        "G1 X31 Z-33.5",
        "G0 X42 Z-33.5", "G0 X42 Z-24", "G0 X30 Z-24", "G1 X24 Z-24", "G1 X24 Z-31",
        "G1 X25 Z-30.5", "G0 X42 Z-30.5", "G0 X42 Z2",
        "G0 X20 Z2", "G1 X20 Z-10", "G1 X32 Z-10", "G1 X32 Z-20", "G1 X22 Z-25",
        "G1 X22 Z-30", "G1 X32 Z-35", "G1 X42 Z-35", "G0 X42 Z2",
    ]  # fmt: skip


def test_type2_cuts_pocket_after_pocket_depth_first() -> None:
    # levels (radius) with their spans of material in the contour's order: the start region,
    # a shallow pocket ending at level 15 and a deep one down to level 9.
    levels = [(18.0, [(2.0, -35.0)]),
              (15.0, [(2.0, -10.0), (-12.0, -18.0), (-21.0, -34.0)]),
              (12.0, [(2.0, -10.0), (-24.0, -31.0)]),
              (9.0, [(2.0, -10.0), (-26.0, -29.0)])]  # fmt: skip
    assert lg._pocket_order(levels) == [
        (0, 0),
        (1, 0),
        (2, 0),
        (3, 0),  # the start region down to level 9
        (1, 1),  # the shallow pocket (one level)
        (1, 2),
        (2, 1),
        (3, 1),  # the deep pocket, top to bottom
    ]
    assert lg._pocket_order([]) == []


def test_g71_one_block_haas_format_and_the_contour_before_the_cycle() -> None:
    # Haas/Fanuc 0-TC: G71 P Q U W D F in one block. The second G71 refers to the same
    # contour, now behind it: it is read again from the program text.
    contour = "N10 G0 X20\nG1 Z-10\nN20 X30\n"
    prog = HEAD + "G0 X30 Z2\nG71 P10 Q20 D3 F0.2\n" + contour + "G0 X30 Z2\nG71 P10 Q20 D3 F0.2\n"
    cmds = run(prog)
    # x0 15 -> levels 12 (dia 24) only (15 - 2 x 3 = 9 is below A' = 10); then the contour
    want = [
        "G0 X24 Z2", "G1 X24 Z-10", "G1 X25 Z-9.5", "G0 X25 Z2",
        "G0 X20 Z2", "G1 X20 Z-10", "G1 X30 Z-10", "G0 X30 Z2",
    ]  # fmt: skip
    assert moves(cmds, 4) == want
    assert moves(cmds, 9) == want


def test_g71_contour_with_arcs_and_a_trailing_retract() -> None:
    # A = X40 Z2; contour (radius): (5,2) -> G1 (5,0) -> G3 to (10,-5) about (5,-5)
    # (a quarter round, R5) -> G1 (10,-15) -> (20,-15); then a G0 retract Z2, which is not
    # part of the shape. Depth 5: levels 15 (dia 30) and 10 (dia 20).
    # Level 15 meets the last element at Z-15. Level 10 meets the arc's end at Z-5.
    prog = (
        HEAD
        + "G0 X40 Z2\nG71 P10 Q20 D5 F0.2\n"
        + "N10 G0 X10 Z2\nG1 Z0\nG3 X20 Z-5 R5\nG1 Z-15\nX40\nN20 G0 Z2\n"
    )
    got = moves(run(prog), 4)
    assert got[:8] == [
        "G0 X30 Z2", "G1 X30 Z-15", "G1 X31 Z-14.5", "G0 X31 Z2",
        "G0 X20 Z2", "G1 X20 Z-5", "G1 X21 Z-4.5", "G0 X21 Z2",
    ]  # fmt: skip
    assert got[8:] == [
        "G0 X10 Z2",
        "G1 X10 Z0",
        "G3 X20 Z-5",
        "G1 X20 Z-15",
        "G1 X40 Z-15",
        "G0 X40 Z2",
    ]


def test_g72_facing_passes() -> None:
    # A = X52 Z2 (radius 26). Contour: A' = (26,-6) (Z only: type I), (15,-6), (15,-2),
    # (0,-2). Levels in Z from 2 by 2 above -6: 0, -2, -4. Level 0 is above the whole
    # shape: cut to X0. Levels -2 and -4 meet the shoulder at X30 (dia).
    # Each pass: G0 Z level, G1 X end, pull off at 45 degrees (Z +0.5, X dia +1), G0 X52.
    prog = HEAD + "G0 X52 Z2\nG72 W2 R0.5\nG72 P10 Q20 F0.2\n" + "N10 G0 Z-6\nG1 X30\nZ-2\nN20 X0\n"
    assert moves(run(prog), 5) == [
        "G0 X52 Z0", "G1 X0 Z0", "G1 X1 Z0.5", "G0 X52 Z0.5",
        "G0 X52 Z-2", "G1 X30 Z-2", "G1 X31 Z-1.5", "G0 X52 Z-1.5",
        "G0 X52 Z-4", "G1 X30 Z-4", "G1 X31 Z-3.5", "G0 X52 Z-3.5",
        "G0 X52 Z-6", "G1 X30 Z-6", "G1 X30 Z-2", "G1 X0 Z-2", "G0 X0 Z2", "G0 X52 Z2",
    ]  # fmt: skip


def test_g70_runs_the_contour_with_its_own_feed_and_returns_to_the_start() -> None:
    prog = G71_TYPE1 + "G0 X50 Z2\nG70 P10 Q20 F0.1\nG0 X100\n"
    cmds = run(prog)
    assert moves(cmds, 13) == ["G0 X50 Z2"]  # line 13: G70 returns to its start point
    # the contour's own lines carry its moves, at G70's F0.1 = 100 mm/min
    fin = [c for c in cmds if c.line in range(6, 11) and isinstance(c, StraightFeed)]
    assert [f"X{c.end[0] * 2:g} Z{c.end[2]:g}" for c in fin] == [
        "X20 Z-20",
        "X30 Z-30",
        "X30 Z-40",
        "X50 Z-40",
    ]
    assert {c.feed for c in fin} == {100.0}


# --- G73 ----------------------------------------------------------------------------------


def test_g73_pattern_repeating() -> None:
    # A = X50 Z5. Relief Δi 4 (radius), Δk 2, 3 divisions; allowance U0.5 (0.25 radius)
    # W0.1. Contour (radius) from A' (10,0): (10,-10), (20,-20).
    # Pass k shifts by (4 (3-k)/2 + 0.25, 2 (3-k)/2 + 0.1): (4.25, 2.1), (2.25, 1.1), (0.25, 0.1).
    prog = (
        HEAD
        + "G0 X50 Z5\nG73 U4 W2 R3\nG73 P10 Q20 U0.5 W0.1 F0.2\n"
        + "N10 G0 X20 Z0\nG1 Z-10\nN20 X40 Z-20\n"
    )
    assert moves(run(prog), 5) == [
        "G0 X28.5 Z2.1", "G1 X28.5 Z-7.9", "G1 X48.5 Z-17.9", "G0 X50 Z-17.9", "G0 X50 Z5",
        "G0 X24.5 Z1.1", "G1 X24.5 Z-8.9", "G1 X44.5 Z-18.9", "G0 X50 Z-18.9", "G0 X50 Z5",
        "G0 X20.5 Z0.1", "G1 X20.5 Z-9.9", "G1 X40.5 Z-19.9", "G0 X50 Z-19.9", "G0 X50 Z5",
    ]  # fmt: skip


# --- G74 / G75 ------------------------------------------------------------------------------


def test_g75_od_grooving_fanuc_two_blocks() -> None:
    # A = X30 Z-10; retract 0.5; X20 (radius 10) in pecks of 3 mm (P3000 = 3000 µm):
    # 15 -> 12 -> 10; grooves at Z-10 and Z-14 (Q4000: shift 4).
    prog = HEAD + "G0 X30 Z-10\nG75 R0.5\nG75 X20 Z-14 P3000 Q4000 F0.1\n"
    assert moves(run(prog), 5) == [
        "G1 X24 Z-10", "G0 X25 Z-10", "G1 X20 Z-10", "G0 X30 Z-10",
        "G0 X30 Z-14", "G1 X24 Z-14", "G0 X25 Z-14", "G1 X20 Z-14", "G0 X30 Z-14",
        "G0 X30 Z-10",
    ]  # fmt: skip


def test_g75_haas_one_block_parting_with_pecks() -> None:
    # Haas: I is the peck (radius). X10 -> X0 in pecks of 2: 5 -> 3 -> 1 -> 0 (radius);
    # retract 0.254 mm (Haas setting 22: 0.010 in).
    prog = HEAD + "G0 X10 Z-5\nG75 X0 I2 F0.05\n"
    assert moves(run(prog), 4) == [
        "G1 X6 Z-5",
        "G0 X6.508 Z-5",
        "G1 X2 Z-5",
        "G0 X2.508 Z-5",
        "G1 X0 Z-5",
        "G0 X10 Z-5",
    ]


def test_g74_peck_drilling_on_the_axis() -> None:
    # A = X0 Z5; retract 1; Z-20 in pecks of 8 (Q8000): -3, -11, -19, -20, then back to Z5.
    prog = HEAD + "G0 X0 Z5\nG74 R1\nG74 Z-20 Q8000 F0.1\n"
    assert moves(run(prog), 5) == [
        "G1 X0 Z-3",
        "G0 X0 Z-2",
        "G1 X0 Z-11",
        "G0 X0 Z-10",
        "G1 X0 Z-19",
        "G0 X0 Z-18",
        "G1 X0 Z-20",
        "G0 X0 Z5",
    ]


# --- G76 ------------------------------------------------------------------------------------


def test_g76_fanuc_two_block_depths_and_flank_infeed() -> None:
    # P010060: 1 finishing pass, no chamfer, 60-degree tool; Q100: minimum cut 0.1;
    # R0.05 finishing allowance. X18.2 = root (radius 9.1), P900 = height 0.9, Q400 =
    # first cut 0.4, lead 1.5 at 500 rpm (750 mm/min).
    # Depths 0.4 sqrt(n): 0.4, 0.5657, 0.6928, 0.8, then 0.8944 > 0.85 = 0.9 - 0.05 -> 0.85;
    # the allowance pass at 0.9. Diameter = 2 (9.1 + 0.9 - d) = 20 - 2d; each pass starts
    # (0.9 - d) tan 30 back from Z5 (flank infeed), on the thread at full depth.
    prog = "G97 S500 M3\nG0 X25 Z5\nG76 P010060 Q100 R0.05\nG76 X18.2 Z-20 P900 Q400 F1.5\n"
    cmds = run(prog)
    got = moves(cmds, 4)
    depths = [0.4, 0.4 * math.sqrt(2), 0.4 * math.sqrt(3), 0.8, 0.85, 0.9]
    want = []
    for d in depths:
        dia = round(20 - 2 * d, 3)
        zs = round(5 + (0.9 - d) * math.tan(math.radians(30)), 3)
        if abs(zs - 5) > 1e-9:
            want.append(f"G0 X25 Z{zs:g}")
        want += [f"G0 X{dia:g} Z{zs:g}", f"G1 X{dia:g} Z-20", "G0 X25 Z-20", "G0 X25 Z5"]
    assert got == want
    assert {round(f, 6) for f in feeds(cmds, 4)} == {750.0}


def test_g76_haas_one_block() -> None:
    # Haas X Z K D F: height K 0.9, first cut D 0.4, radial infeed, passes 0.4 sqrt(n)
    # up to K: 0.4, 0.5657, 0.6928, 0.8, 0.8944, then 0.9798 > 0.9 -> 0.9.
    prog = "G97 S500 M3\nG0 X25 Z5\nG76 X18.2 Z-20 K0.9 D0.4 F1.5\n"
    got = moves(run(prog), 3)
    dias = [round(20 - 2 * d, 3) for d in [0.4 * math.sqrt(n) for n in range(1, 6)] + [0.9]]
    want = []
    for dia in dias:
        want += [f"G0 X{dia:g} Z5", f"G1 X{dia:g} Z-20", "G0 X25 Z-20", "G0 X25 Z5"]
    assert got == want


def test_thread_depth_sequence_honours_the_minimum_cut() -> None:
    # first 0.1, minimum 0.05: sqrt steps 0.1, 0.1414 (step 0.041 < 0.05 -> 0.15), ...
    d = lg.thread_depths(0.3, 0.1, 0.05, 0.0, 1)
    assert d[0] == 0.1
    assert d[1] == pytest.approx(0.15)
    assert all(b - a >= 0.05 - 1e-12 for a, b in zip(d, d[1:-1], strict=False))
    assert d[-1] == 0.3


# --- machine words: G80, G28 U0 W0, G96 with the G50 clamp -------------------------------------


def test_g80_on_a_lathe_is_accepted_and_g28_u0_w0_goes_home() -> None:
    cmds = run("G00 G18 G20 G40 G80 G99\nG0 X2 Z1\nG28 U0 W0\n")
    assert moves(cmds, 3)[-1] == "G0 X0 Z0"


def test_g96_surface_speed_is_clamped_by_g50_s() -> None:
    # 100 m/min at X10 (radius 5): 1000 x 100 / (pi x 10) = 3183 rpm, clamped to 1000.
    cmds = run("G0 X10 Z2\nG50 S1000\nG96 S100 M3\n")
    sp = [c for c in cmds if isinstance(c, Spindle)][-1]
    assert sp.rpm == pytest.approx(1000.0)
    cmds = run("G0 X100 Z2\nG50 S4000\nG96 S100 M3\n")  # radius 50: 318.3 rpm
    sp = [c for c in cmds if isinstance(c, Spindle)][-1]
    assert sp.rpm == pytest.approx(1000 * 100 / (math.pi * 100))


# --- bad input --------------------------------------------------------------------------------


def err(prog: str, **kw) -> NcError:
    with pytest.raises(NcError) as ei:
        run(prog, file="p.nc", **kw)
    assert ei.value.file == "p.nc"
    return ei.value


def test_type1_contour_not_monotonic_names_the_block_and_ps0064() -> None:
    # the 4th contour block turns back in X (30 -> 25): type I refuses it (line 8)
    prog = (
        HEAD + "G0 X50 Z2\nG71 P10 Q20 D2 F0.2\nN10 G0 X20\nG1 Z-10\nX30 Z-20\nX25 Z-25\nN20 X50\n"
    )
    e = err(prog)
    assert (e.line, e.col) == (8, 1)
    assert "PS0064" in e.message and "not monotonic in X" in e.message


def test_contour_turning_back_in_z_is_ps0329_even_for_type2() -> None:
    prog = HEAD + "G0 X50 Z2\nG71 P10 Q20 D2 F0.2\nN10 G0 X20 Z2\nG1 Z-10\nX30 Z-5\nN20 X50\n"
    e = err(prog)
    assert e.line == 7 and "PS0329" in e.message and "in Z" in e.message


@pytest.mark.parametrize(
    ("prog", "line", "col", "fragment"),
    [
        ("G0 X50 Z2\nG71 Q20 D2 F0.2\n", 2, 1, "PS0061 G71 needs P and Q"),
        ("G0 X50 Z2\nG70 F0.1\n", 2, 1, "PS0061 G70 needs P and Q"),
        ("G0 X50 Z2\nG71 P10 Q20 D2 F0.2\nN11 G0 X20\nN20 X50\n", 2, 5, "PS0063"),
        ("G0 X50 Z2\nG71 P10 Q21 D2 F0.2\nN10 G0 X20\nN20 X50\n", 2, 9, "N21 (Q)"),
        ("G0 X50 Z2\nG71 P10 Q20 F0.2\nN10 G0 X20\nN20 X50\n", 2, 1, "PS0062 G71 needs the depth"),
        ("G0 X50 Z2\nG71 P10 Q20 D2 F0.2\nN10 G2 X20 R5\nN20 X50\n", 3, 1, "PS0065"),
        ("G0 X50 Z2\nG71 P10 Q20 D2 F0.2\nN10 G0 X20\nG28 U0\nN20 X50\n", 4, 1, "PS0066"),
        ("G0 X50 Z2\nG71 P10 Q20 D0 F0.2\nN10 G0 X20\nN20 X50\n", 2, 13, "PS0062"),
        ("G0 X30 Z2\nG76 X20 Z-20 K1 F1.5\n", 2, 1, "needs K (thread height) and D"),
        ("G0 X30 Z2\nG76 X20 P900 Q300 F1.5\n", 2, 1, "G76 needs X (U) and Z (W)"),
        ("G0 X30 Z2\nG75 X20 Z-10 I1 F0.1\n", 2, 1, "needs the shift per groove"),
        ("G0 X30 Z2\nG90 X20 Z-10\n", 2, 1, "feed move without F"),
        ("G0 X30 Z2\nG90 X20 F0.2\n", 2, 1, "G90 needs X (U) and Z (W) in its first block"),
    ],
)
def test_bad_cycle_words(prog, line, col, fragment) -> None:
    e = err(HEAD + prog)
    assert fragment in e.message
    assert (e.line - 2, e.col) == (line, col)


def test_thread_lead_beyond_the_z_axis_speed_is_refused_at_f() -> None:
    # 3000 rpm x lead 10 = 30000 mm/min > Z max 24000 mm/min (the machine feeds 40000)
    fast = MachineParams(kind="lathe", axes=LATHE.axes, max_feed=40000.0)
    e = err("G97 S3000 M3\nG0 X20 Z2\nG32 Z-20 F10\n", params=fast)
    assert e.line == 3 and e.col == 10
    assert "needs 30000 mm/min on Z" in e.message and "Z axis maximum 24000" in e.message
    e = err("G97 S3000 M3\nG0 X30 Z2\nG76 X20 Z-20 K1 D0.3 F10\n", params=fast)
    assert e.line == 3 and "Z axis maximum 24000 mm/min" in e.message
    # the machine's maximum feed binds first on the default machine data (15000 mm/min)
    e = err("G97 S2000 M3\nG0 X20 Z2\nG32 Z-20 F10\n")
    assert "machine maximum feed 15000 mm/min" in e.message


def test_streamed_program_cannot_reach_a_contour_behind() -> None:
    prog = HEAD + "G0 X30 Z2\nN10 G0 X20\nG1 Z-10 F0.2\nN20 X30\nG0 Z2\nG71 P10 Q20 D3\n"
    with pytest.raises(NcError, match="streamed"):
        list(Interpreter(LATHE).run(iter(prog.splitlines())))
    # the same text as a list (re-readable) runs
    run(prog.splitlines())


def test_check_reports_the_cycle_error_and_carries_on() -> None:
    from cnc.interp.interpreter import check

    prog = (
        HEAD
        + "G0 X50 Z2\nG71 P10 Q20 D2 F0.2\nN10 G0 X20\nG1 X30 Z-20\nX25 Z-25\nN20 X50\nG0 X1 Y1\n"
    )
    errs = check(prog, LATHE, file="p.nc")
    assert [e.line for e in errs] == [7, 9]
    assert "PS0064" in errs[0].message and "no Y axis" in errs[1].message


# --- geometry properties --------------------------------------------------------------------


def test_rough_turning_never_cuts_below_the_translated_contour() -> None:
    # every feed move's end point of a type I roughing lies on or outside the contour
    contour = (
        lg.Seg(lg.FEED, (5.0, 2.0), (5.0, -10.0)),
        lg.Seg(lg.CCW, (5.0, -10.0), (10.0, -15.0), (5.0, -15.0)),
        lg.Seg(lg.FEED, (10.0, -15.0), (20.0, -30.0)),
    )
    mv = lg.rough_turning((25.0, 2.0), contour, 1.3, 0.3, (0.2, 0.1), False)

    def x_at(z: float) -> float:  # the translated contour's radius at z
        if z >= -9.9:
            return 5.2
        if z >= -14.9:
            dz = z - (-14.9)
            return 5.2 + math.sqrt(max(25 - dz * dz, 0.0))
        return 10.2 + (-14.9 - z) * 10 / 15

    for k, x, z, _, _ in mv:
        if k == lg.FEED and z > -29.9:
            assert x >= x_at(z) - 1e-6, (x, z)


# --- G-code systems B and C ------------------------------------------------------------------


def _system(letter: str) -> MachineParams:
    return MachineParams(kind="lathe", axes=LATHE.axes, lathe_gcode_system=letter)


def test_system_b_renames_the_cycles_and_frees_g90_g91_g92_g94() -> None:
    # B: G77 is A's G90; G90/G91 absolute/incremental; G92 S the speed clamp; G95 per rev
    b = _system("B")
    prog = "G95 G97 S1000 M3\nG0 X50 Z2\nG77 X40 Z-20 F0.2\nG0 X60\nG91 G0 X-4 Z-1\n"
    cmds = run(prog, params=b)
    assert moves(cmds, 3) == ["G0 X40 Z2", "G1 X40 Z-20", "G1 X50 Z-20", "G0 X50 Z2"]
    assert moves(cmds, 5) == ["G0 X56 Z1"]  # incremental under G91
    cmds = run("G0 X10 Z2\nG92 S1000\nG96 S100 M3\n", params=b)
    assert [c for c in cmds if isinstance(c, Spindle)][-1].rpm == pytest.approx(1000.0)
    with pytest.raises(NcError, match="unsupported G code G50"):
        run("G50 S1000\n", params=b)
    assert moves(run(G71_TYPE1.replace("G99", "G95"), params=b), 5) == moves(run(G71_TYPE1), 5)


def test_system_b_and_c_thread_with_g33() -> None:
    # Fanuc T: thread cutting is G32 in system A, G33 in B and C (gcw-tokarka-o1200)
    a = run("G97 S500 M3\nG99\nG0 X16 Z2\nG32 Z-17 F1.5\nG0 X18\n")
    for letter in ("B", "C"):
        other = run("G97 S500 M3\nG95\nG0 X16 Z2\nG33 Z-17 F1.5\nG0 X18\n", params=_system(letter))
        assert moves(other, 4) == moves(a, 4) == ["G1 X16 Z-17"]
    with pytest.raises(NcError, match="unsupported G code G33"):
        run("G33 Z-17 F1.5\n")


def test_system_c_moves_the_multiple_cycles_to_g72_g78_and_units_to_g70_g71() -> None:
    c = _system("C")
    prog = (
        G71_TYPE1.replace("G21", "G71")
        .replace("G99", "G95")
        .replace("G71 U2", "G73 U2")
        .replace("G71 P10", "G73 P10")
    )
    assert moves(run(prog, params=c), 5) == moves(run(G71_TYPE1), 5)
    cmds = run("G70\nG0 X1 Z1\n", params=c)  # G70: inch
    assert moves(cmds, 2) == ["G0 X25.4 Z25.4"]
    cmds = run("G95 G97 S1000 M3\nG0 X50 Z2\nG20 X40 Z-20 F0.2\n", params=c)  # G20: turning
    assert moves(cmds, 3) == ["G0 X40 Z2", "G1 X40 Z-20", "G1 X50 Z-20", "G0 X50 Z2"]


# --- the generated path in `nc plan` traces ------------------------------------------------------


def test_nc_plan_trace_carries_the_cycle_path(tmp_path) -> None:
    import csv

    import yaml
    from typer.testing import CliRunner

    import cnc.cli_plan  # noqa: F401  (registers the command)
    from cnc.cli import nc_app
    from cnc.machines import __file__ as machines_init

    # the shipped lathe with room for this part in + X and Z (machine zero = part zero)
    shipped = Path(machines_init).with_name("lathe2.yaml")
    cfg = yaml.safe_load(shipped.read_text(encoding="utf-8"))
    cfg["axes"]["X"].update(min_mm=-500.0, max_mm=500.0)
    cfg["axes"]["Z"].update(min_mm=-900.0, max_mm=500.0)
    mcfg = tmp_path / "lathe.yaml"
    mcfg.write_text(yaml.safe_dump(cfg))
    prog = tmp_path / "g71.nc"
    prog.write_text(G71_TYPE1)
    trace = tmp_path / "t.csv"
    res = CliRunner().invoke(
        nc_app, ["plan", str(prog), "--config", str(mcfg), "--trace", str(trace), "--json"]
    )
    assert res.exit_code == 0, res.output
    rows = [r for r in csv.DictReader(trace.open()) if r["line"] == "5"]
    # the cycle block's samples run every roughing level (radius 23 .. 11) and the contour;
    # machine coordinates differ from the program's by the machine's work/tool offsets, so
    # compare relative to the cycle's outermost point B' (radius 25.25, Z-39.9)
    ox = max(float(r["X"]) for r in rows) - 25.25
    oz = min(float(r["Z"]) for r in rows) + 39.9
    levels = {round(float(r["X"]) - ox, 3) for r in rows}
    assert {23.0, 21.0, 19.0, 17.0, 15.0, 13.0, 11.0, 10.25} <= levels
    assert max(float(r["Z"]) - oz for r in rows) == pytest.approx(2.1)  # A' translated by W


@pytest.mark.parametrize(
    "cycle",
    [
        "G71 P10 Q20 D0.000001 F0.2\nN10 G0 X20\nG1 Z-10\nN20 X50\n",
        "G73 U1 W1 R99999999\nG73 P10 Q20 F0.2\nN10 G0 X20\nG1 Z-10\nN20 X50\n",
        "G75 X20 Z-900 I0.0001 K0.0000001 F0.1\n",
        "G74 Z-900 K0.00001 F0.1\n",
        "G76 X40 Z-20 K5 D0.0000001 F1\n",
    ],
)
def test_a_cycle_that_would_explode_is_refused_quickly(cycle: str) -> None:
    e = err(HEAD + "G0 X50 Z2\n" + cycle)
    assert "PS0062" in e.message and e.line == 4


# --- fuzz and properties ------------------------------------------------------------------------

_num = st.one_of(
    st.integers(-60, 60).map(str),
    st.floats(-60, 60, allow_nan=False).map(lambda v: f"{v:.3f}"),
    st.sampled_from(["0", "0.0001", "1000000", "-0.5", "1"]),
)
_cycle_word = st.builds(lambda a, n: a + n, st.sampled_from("XZUWPQRIKDF"), _num)
_cycle_block = st.builds(
    lambda g, ws: " ".join([g, *ws]),
    st.sampled_from(["G70", "G71", "G72", "G73", "G74", "G75", "G76", "G90", "G92", "G94", "G32"]),
    st.lists(_cycle_word, max_size=6),
)
_contour_block = st.builds(
    lambda n, g, x, z: f"{n}{g} X{x} Z{z}",
    st.sampled_from(["", "", "N10 ", "N20 "]),
    st.sampled_from(["G0", "G1", "G2 R20", "G3 R20", "G1"]),
    st.integers(0, 80),
    st.integers(-60, 5),
)
_lathe_program = st.lists(st.one_of(_cycle_block, _contour_block), min_size=1, max_size=12).map(
    lambda bl: "G97 S800 M3\nG0 X60 Z5\n" + "\n".join(bl) + "\n"
)


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(_lathe_program)
def test_fuzz_lathe_cycles_give_moves_or_nc_errors(text: str) -> None:
    from cnc.interp.interpreter import check

    try:
        for _ in Interpreter(LATHE, max_blocks=20_000).run(text):
            pass
    except NcError as e:
        assert e.line >= 1 and e.col >= 1 and e.message
    assert all(isinstance(e, NcError) for e in check(text, LATHE, max_blocks=20_000))


@settings(max_examples=100, deadline=None)
@given(
    st.lists(
        st.tuples(st.floats(0.0, 8.0), st.floats(0.5, 15.0)), min_size=1, max_size=12
    ),  # (radius rise, length) per element: monotonic
    st.floats(0.3, 4.0),
    st.booleans(),
)
def test_type1_roughing_stays_outside_the_contour_and_returns_to_a(steps, depth, type2) -> None:
    pts = [(5.0, 0.0)]
    for rise, length in steps:
        x, z = pts[-1]
        pts.append((x + rise, z - length))
    segs = tuple(lg.Seg(lg.FEED, a, b) for a, b in zip(pts, pts[1:], strict=False))
    x0 = pts[-1][0] + 2.0
    mv = lg.rough_turning((x0, 2.0), segs, depth, 0.5, (0.2, 0.1), type2)

    def x_at(z: float) -> float:  # the translated contour's radius at z (monotonic)
        z -= 0.1
        for a, b in zip(pts, pts[1:], strict=False):
            if b[1] - 1e-9 <= z <= a[1] + 1e-9:
                t = 0.0 if a[1] == b[1] else (a[1] - z) / (a[1] - b[1])
                return a[0] + t * (b[0] - a[0]) + 0.2
        return pts[0][0] + 0.2 if z > 0 else pts[-1][0] + 0.2

    for k, x, z, _, _ in mv:
        if k == lg.FEED and pts[-1][1] + 0.1 < z < 0.1:
            assert x >= x_at(z) - 1e-6, (x, z)
    assert mv[-1][1:3] == (x0, 2.0)
    # the depth of every roughing level step is at most the depth of cut
    levels = sorted({round(x, 9) for k, x, z, _, _ in mv if k == lg.RAPID and z == 2.0})
    assert all(b - a <= depth + 1e-6 for a, b in zip(levels, levels[1:], strict=False))


def test_contour_behind_the_cycle_in_a_subprogram_and_in_a_file(tmp_path) -> None:
    # the contour N10..N20 runs first (as ordinary blocks), the G71 after it reads it again:
    # from the called program O100, and from the file on disk
    body = "G0 X30 Z2\nN10 G0 X20\nG1 Z-10 F0.2\nN20 X30\nG0 Z2\nG71 P10 Q20 D3\n"
    want = [
        "G0 X24 Z2", "G1 X24 Z-10", "G1 X25 Z-9.5", "G0 X25 Z2",
        "G0 X20 Z2", "G1 X20 Z-10", "G1 X30 Z-10", "G0 X30 Z2",
    ]  # fmt: skip
    cmds = run(HEAD + "M98 P100\n", programs={100: "O100\n" + body + "M99\n"})
    assert moves([c for c in cmds if c.line == 7]) == want  # line 7 of O100
    path = tmp_path / "part.nc"
    path.write_text(HEAD + body + "M30\n")
    with path.open() as fh:
        cmds = list(Interpreter(LATHE, file=str(path)).run(fh))
    assert moves(cmds, 8) == want


def test_contour_arc_with_mismatched_radii_is_refused_in_roughing() -> None:
    prog = (
        HEAD + "G0 X40 Z2\nG71 P10 Q20 D2 F0.2\nN10 G0 X10\nG1 Z0\nG3 X20 Z-5 I0 K-4\nN20 G1 X40\n"
    )
    e = err(prog)
    assert e.line == 7 and "end radius" in e.message


def test_block_delete_lines_leave_the_contour_when_the_switch_is_on() -> None:
    prog = HEAD + "G0 X30 Z2\nG71 P10 Q20 D3 F0.2\nN10 G0 X20\nG1 Z-10\n/X25 Z-15\nN20 X30\n"
    on = moves(run(prog, block_delete=True), 4)
    off = moves(run(prog, block_delete=False), 4)
    assert "G1 X25 Z-15" in off and "G1 X25 Z-15" not in on


def test_g76_haas_angle_and_cutting_methods() -> None:
    # A60, P3: constant depth 0.3 per pass up to K0.9: 0.3, 0.6, 0.9; each pass starts
    # (0.9 - d) tan 30 back from Z5; P4 alternates the flank (the second pass shifts forward)
    t = math.tan(math.radians(30))
    base = "G97 S500 M3\nG0 X25 Z5\nG76 X18.2 Z-20 K0.9 D0.3 A60 {} F1.5\n"
    got = moves(run(base.format("P3")), 3)
    want = []
    for d in (0.3, 0.6, 0.9):
        dia, zs = round(20 - 2 * d, 3), round(5 + (0.9 - d) * t, 3)
        if d < 0.9:
            want.append(f"G0 X25 Z{zs:g}")
        want += [f"G0 X{dia:g} Z{zs:g}", f"G1 X{dia:g} Z-20", "G0 X25 Z-20", "G0 X25 Z5"]
    assert got == want
    alt = moves(run(base.format("P4")), 3)
    assert alt[0] == want[0] and alt[5] == f"G0 X25 Z{round(5 - 0.3 * t, 3):g}"
    e = err(base.format("P5"))
    assert "PS0062" in e.message and "cutting method" in e.message
    e = err("G0 X20 A5\n")  # A is the G76 angle only
    assert "A word with no code" in e.message


def test_a_pass_waits_for_the_index_once_and_continuous_g32_blocks_do_not() -> None:
    from cnc.canon import SpindleSync, ThreadFeed

    # two G32 blocks in a row (a thread running into a taper): one index wait, at the start
    cmds = run("G97 S400 M3\nG0 X20 Z2\nG32 Z-20 F2\nX24 Z-30\nG0 X40\nZ2\nX20\nG32 Z-20\n")
    kinds = [type(c).__name__ for c in cmds if isinstance(c, SpindleSync | ThreadFeed)]
    assert kinds == ["SpindleSync", "ThreadFeed", "ThreadFeed", "SpindleSync", "ThreadFeed"]
    # G76: one wait per pass
    cmds = run("G97 S500 M3\nG0 X25 Z5\nG76 X18.2 Z-20 K0.9 D0.4 F1.5\n")
    assert sum(isinstance(c, SpindleSync) for c in cmds) == 6
    assert all(c.lead == 1.5 and c.rpm == 500.0 for c in cmds if isinstance(c, ThreadFeed))


def test_thread_with_the_spindle_stopped_is_refused() -> None:
    e = err("G97 S400\nG0 X20 Z2\nG32 Z-20 F2\n")
    assert e.line == 3 and "spindle stopped" in e.message
