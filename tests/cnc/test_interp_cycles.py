"""Canned cycles G73 G74 G76 G80-G89 with G98/G99 and K repeats, expanded to moves."""

import pytest

from cnc.canon import Dwell, ProgramStop, Spindle, SpindleDirection, StraightFeed, StraightTraverse
from cnc.errors import NcError
from cnc.interp import Interpreter
from cnc.params import AxisParams, MachineParams

BIG = tuple(AxisParams(a, -1000, 1000, 30000, 3000, 5e4) for a in "XYZ")
MILL = MachineParams(axes=BIG)
T, F = StraightTraverse, StraightFeed
CW, CCW = SpindleDirection.CW, SpindleDirection.CCW


def run(text: str, **kw) -> list:
    return list(Interpreter(MILL, **kw).run(text))


def path(cmds: list) -> list:
    """Compact form: ('T'|'F', z) for moves at the hole, other commands by type name."""
    out = []
    for c in cmds:
        if isinstance(c, T | F):
            out.append(("T" if isinstance(c, T) else "F", c.end[0], c.end[1], c.end[2]))
        elif isinstance(c, Spindle):
            out.append(("S", c.direction.value))
        elif isinstance(c, Dwell):
            out.append(("D", c.seconds))
        else:
            out.append((type(c).__name__,))
    return out


START = "G0 X0 Y0 Z10\nS600 M3\n"


@pytest.mark.parametrize(
    ("block", "expected"),
    [
        ("G98 G81 X5 Y5 Z-4 R2 F100",
         [("T", 5, 5, 10), ("T", 5, 5, 2), ("F", 5, 5, -4), ("T", 5, 5, 10)]),
        ("G99 G81 X5 Y5 Z-4 R2 F100",
         [("T", 5, 5, 10), ("T", 5, 5, 2), ("F", 5, 5, -4), ("T", 5, 5, 2)]),
        ("G99 G82 X5 Y5 Z-4 R2 P500 F100",
         [("T", 5, 5, 10), ("T", 5, 5, 2), ("F", 5, 5, -4), ("D", 0.5), ("T", 5, 5, 2)]),
        ("G99 G85 X5 Y5 Z-4 R2 F100",
         [("T", 5, 5, 10), ("T", 5, 5, 2), ("F", 5, 5, -4), ("F", 5, 5, 2)]),
        ("G98 G89 X5 Y5 Z-4 R2 P200 F100",
         [("T", 5, 5, 10), ("T", 5, 5, 2), ("F", 5, 5, -4), ("D", 0.2), ("F", 5, 5, 2),
          ("T", 5, 5, 10)]),
        ("G99 G86 X5 Y5 Z-4 R2 F100",
         [("T", 5, 5, 10), ("T", 5, 5, 2), ("F", 5, 5, -4), ("S", "M5"), ("T", 5, 5, 2),
          ("S", "M3")]),
        ("G99 G88 X5 Y5 Z-4 R2 P100 F100",
         [("T", 5, 5, 10), ("T", 5, 5, 2), ("F", 5, 5, -4), ("D", 0.1), ("S", "M5"),
          ("ProgramStop",), ("T", 5, 5, 2), ("S", "M3")]),
        ("G99 G84 X5 Y5 Z-4 R2 F100",
         [("T", 5, 5, 10), ("T", 5, 5, 2), ("S", "M3"), ("F", 5, 5, -4), ("S", "M4"),
          ("F", 5, 5, 2), ("S", "M3")]),
        ("G98 G74 X5 Y5 Z-4 R2 P300 F100",
         [("T", 5, 5, 10), ("T", 5, 5, 2), ("S", "M4"), ("F", 5, 5, -4), ("D", 0.3),
          ("S", "M3"), ("F", 5, 5, 2), ("S", "M4"), ("T", 5, 5, 10)]),
        ("G99 G76 X5 Y5 Z-4 R2 Q0.5 F100",
         [("T", 5, 5, 10), ("T", 5, 5, 2), ("F", 5, 5, -4), ("S", "M19"), ("T", 5.5, 5, -4),
          ("T", 5.5, 5, 2), ("T", 5, 5, 2), ("S", "M3")]),
        ("G99 G83 X5 Y5 Z-4 R2 Q3 F100",
         [("T", 5, 5, 10), ("T", 5, 5, 2), ("F", 5, 5, -1), ("T", 5, 5, 2), ("T", 5, 5, -0.5),
          ("F", 5, 5, -4), ("T", 5, 5, 2)]),
        ("G99 G73 X5 Y5 Z-4 R2 Q3 F100",
         [("T", 5, 5, 10), ("T", 5, 5, 2), ("F", 5, 5, -1), ("T", 5, 5, -0.5),
          ("F", 5, 5, -4), ("T", 5, 5, 2)]),
        ("G87 X5 Y5 Z-4 R-10 Q0.5 F100",
         [("T", 5, 5, 10), ("S", "M19"), ("T", 5.5, 5, 10), ("T", 5.5, 5, -10),
          ("T", 5, 5, -10), ("S", "M3"), ("F", 5, 5, -4), ("S", "M19"), ("T", 5.5, 5, -4),
          ("T", 5.5, 5, 10), ("T", 5, 5, 10), ("S", "M3")]),
    ],
)  # fmt: skip
def test_cycle_expansion(block: str, expected: list) -> None:
    cmds = run(START + block + "\n")[2:]
    assert path(cmds) == [tuple(e) for e in expected]
    assert all(c.exact_stop for c in cmds if isinstance(c, T | F))


def test_g83_fixed_peck_depths() -> None:
    # TV-INT-15's shrinking pecks (75, 50, 25, 25, 5) are Philips parameter programming;
    # Fanuc G83 pecks a fixed Q from the R plane (+5) down to the bottom
    cmds = run("G0 X0 Y0 Z5\nG99 G83 Z-180 R5 Q75 F100 X0\n")
    feeds = [c.end[2] for c in cmds if isinstance(c, F)]
    assert feeds == [-70.0, -145.0, -180.0]  # Fanuc G83 with a fixed Q
    assert all(isinstance(c, T | F) for c in cmds)


def test_tv_int_11_modal_cycle_holes() -> None:
    cmds = run("G0 Z10\nG81 X10 Y10 Z-15 R2 F200 S1000 M3\nX60\nY30\nX10\nG80\nG0 X0\n")
    holes = [c.end[:2] for c in cmds if isinstance(c, F)]
    assert holes == [(10, 10), (60, 10), (60, 30), (10, 30)]
    assert cmds[-1] == T(7, (0.0, 30.0, 10.0))  # after G80: plain G0 again


def test_k_repeat_incremental_and_k0() -> None:
    cmds = run("G0 X0 Y0 Z10\nG91 G99 G81 X10 Z-5 R-8 K3 F100\n")
    holes = [c.end for c in cmds if isinstance(c, F)]
    assert holes == [(10.0, 0.0, -3.0), (20.0, 0.0, -3.0), (30.0, 0.0, -3.0)]
    assert run("G0 X0 Y0 Z10\nG81 X10 Z-5 R2 K0 F100\n")[1:] == []


def test_tv_int_12_subprogram_holes_three_tools() -> None:
    sub = "O9001\nX-40 Y0\nX0 Y40\nX40 Y0\nX0 Y-40\nM99\n"
    prog = (
        "G0 Z10\nG81 Z-2 R2 F100 K0\nM98 P9001\nG83 Z-20 Q5 K0\nM98 P9001\n"
        "G84 Z-15 K0\nM98 P9001\nG80\nM30\n"
    )
    cmds = run(prog, programs={9001: sub})
    bottoms = [c for c in cmds if isinstance(c, F) and c.end[2] in (-2.0, -20.0, -15.0)]
    assert len(bottoms) == 12


def test_cycle_errors() -> None:
    with pytest.raises(NcError, match="hole bottom"):
        run("G81 X1 R2 F100\n")
    with pytest.raises(NcError, match="G87 back boring needs R below"):
        run("G0 Z10\nG87 X1 Z-2 Q1 F100\n")  # R omitted: the initial level, above the bore
    with pytest.raises(NcError, match="Q > 0"):
        run("G0 Z10\nG83 X1 Z-2 R2 F100\n")
    with pytest.raises(NcError, match="pecks"):
        run("G0 Z10\nG83 X1 Z-200 R2 Q0.001 F100\n")
    with pytest.raises(NcError, match="feed move without F"):
        run("G0 Z10\nG81 X1 Z-2 R2\n")
    with pytest.raises(NcError, match="holes x pecks"):
        run("G0 Z10\nG91 G83 X0.1 Z-100 R-8 Q0.01 K9999 F100\n")


def test_cycle_in_other_planes() -> None:
    cmds = run("G18 G0 X0 Y10 Z0\nG99 G81 X5 Z5 Y-4 R2 F100\n")
    assert [c.end for c in cmds[1:]] == [
        (5.0, 10.0, 5.0), (5.0, 2.0, 5.0), (5.0, -4.0, 5.0), (5.0, 2.0, 5.0)
    ]  # fmt: skip
    cmds = run("G19 G0 X10 Y0 Z0\nG99 G81 Y5 Z5 X-4 R2 F100\n")
    assert cmds[-2].end == (-4.0, 5.0, 5.0)


def test_g88_manual_stop_is_a_program_stop() -> None:
    cmds = run(START + "G88 X1 Y1 Z-1 R1 F10\n")
    assert any(isinstance(c, ProgramStop) for c in cmds)


@pytest.mark.parametrize(
    ("prog", "expected"),
    [
        # R never given: the R level is the initial level Z10 (the feed starts there)
        ("G98 G81 X5 Y5 Z-4 F100\n", [("T", 5, 5, 10), ("F", 5, 5, -4), ("T", 5, 5, 10)]),
        (
            "G99 G81 X5 Y5 Z-4 F100\nX7\n",
            [
                ("T", 5, 5, 10),
                ("F", 5, 5, -4),
                ("T", 5, 5, 10),
                ("T", 7, 5, 10),
                ("F", 7, 5, -4),
                ("T", 7, 5, 10),
            ],
        ),
        # incremental: Z is measured from the R level = the initial level
        ("G91 G99 G81 X5 Y5 Z-14 F100\n", [("T", 5, 5, 10), ("F", 5, 5, -4), ("T", 5, 5, 10)]),
        # an R of an earlier cycle stays modal (the last R)
        (
            "G99 G81 X1 Y1 Z-4 R2 F100\nG80\nG0 Z20\nG81 X5 Y5 Z-4\n",
            [
                ("T", 1, 1, 10),
                ("T", 1, 1, 2),
                ("F", 1, 1, -4),
                ("T", 1, 1, 2),
                ("T", 1, 1, 20),
                ("T", 5, 5, 20),
                ("T", 5, 5, 2),
                ("F", 5, 5, -4),
                ("T", 5, 5, 2),
            ],
        ),
    ],
)
def test_r_omitted_is_the_initial_level(prog: str, expected: list) -> None:
    assert path(run(START + prog))[2:] == expected


@pytest.mark.parametrize(
    ("prog", "expected"),
    [
        # the hole bottom above R: a Fanuc feeds from R up to Z (no P/S alarm relates them);
        # z64-stdbc-o0010.nc's tap sub: G0 Z.1 / G98 G84 Z.5 R.1 (Z#5 for the tap depth J)
        (
            "G0 X0 Y0 Z.1\nS100 M3\nG98 G84 Z.5 R.1 F10\n",
            [("S", "M3"), ("S", "M3"), ("F", 0, 0, 0.5), ("S", "M4"), ("F", 0, 0, 0.1),
             ("S", "M3")],
        ),
        ("G0 X0 Y0 Z10\nG99 G81 X1 Z2 R-2 F100\n", [("T", 1, 0, 10), ("T", 1, 0, -2),
                                                   ("F", 1, 0, 2), ("T", 1, 0, -2)]),
        # pecks go from R towards Z: up (G83 Q1 from R0 to Z2.5: 1, 2, 2.5)
        (
            "G0 X0 Y0 Z0\nG99 G83 Z2.5 R0 Q1 F100\n",
            [("F", 0, 0, 1), ("T", 0, 0, 0), ("T", 0, 0, 0.5), ("F", 0, 0, 2), ("T", 0, 0, 0),
             ("T", 0, 0, 1.5), ("F", 0, 0, 2.5), ("T", 0, 0, 0)],
        ),
    ],
)  # fmt: skip
def test_a_hole_bottom_above_r_feeds_upward_and_is_noted(prog: str, expected: list) -> None:
    ip = Interpreter(MILL, file="up.nc")
    cmds = list(ip.run(prog))
    assert path(cmds[1:]) == expected  # after the G0 to the start point
    assert list(ip.upward_holes) == [("up.nc", prog.count("\n"))]


def test_a_hole_bottom_below_r_is_not_noted() -> None:
    ip = Interpreter(MILL)
    list(ip.run("G0 X0 Y0 Z10\nG81 X1 Z-2 R2 F100\nX2\n"))
    assert ip.upward_holes == {}
