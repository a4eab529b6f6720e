"""Kernel bugs real part programs hit (issue 13): each from its corpus file plus a hand test.

- a plane change after G40 was refused: the compensator object was tested for existence,
  not for being active (Fusion 360 / Haas posts: enier-1003, -1006, -1031);
- `G0 G91 G28 Z0` was refused although G28 (group 0) owns the axis words and G0 only sets
  the modal motion (versa-o8000-tablewash);
- G40 with no in-plane move left compensation waiting for a cancel move, so G53, G28 or a
  plane change after it was refused (lcnc-comp, the enier lathe programs).
"""

from __future__ import annotations

from dataclasses import replace

import pytest

from cnc.canon import StraightFeed, StraightTraverse
from cnc.errors import NcError
from cnc.interp import Interpreter, ToolOffset, check
from cnc.params import AxisParams, MachineParams
from tests import reference

BIG = tuple(AxisParams(a, -1000, 1000, 30000, 3000, 5e4) for a in "XYZ")
MILL = MachineParams(axes=BIG)
TOOLS = {1: ToolOffset(radius=1.0)}


def run(text: str) -> list:
    return list(Interpreter(MILL, tools=TOOLS).run(text))


def corpus_errors(name: str, kind: str = "mill") -> list[NcError]:
    path = reference.GCODE_CORPUS / name
    if not path.exists():
        pytest.skip(reference.MISSING)
    params = MachineParams(kind=kind)
    if kind == "lathe":
        x, _, z = params.axes
        params = MachineParams(kind="lathe", axes=(x, z))
    big = 1e9  # these programs have no setup for the default machine: no soft limits
    params = replace(params, axes=tuple(replace(a, min_mm=-big, max_mm=big) for a in params.axes))
    with open(path, encoding="latin-1") as fh:
        return check(fh, params, file=name)


# --- a plane change after G40 -----------------------------------------------------------


@pytest.mark.parametrize(
    "name",
    [
        "enier-1003-inspection-plate.nc",
        "enier-1006-motor-bracket.nc",
        "enier-1031-slot-assembly.nc",
    ],
)
def test_fusion_programs_change_plane_after_g40(name: str) -> None:
    # `G1 G40 X.. Y..` ends a profile, later `G19 G3 ...` ramps: was "plane change while
    # cutter compensation is active".
    assert [str(e) for e in corpus_errors(name)] == []


def test_plane_change_after_a_cancel_move() -> None:
    cmds = run("G0 X0 Y0 Z0\nG41 D1 G1 X10 F100\nX20\nG40 G1 X30 Y0\nG18\nG2 X40 Z0 R5\nM30\n")
    assert cmds[-2].plane.name == "ZX"


def test_plane_change_with_compensation_on_is_still_refused() -> None:
    with pytest.raises(NcError, match="plane change while cutter compensation is active"):
        run("G0 X0 Y0\nG41 D1 G1 X10 F100\nX20\nG18\n")


# --- G0 G91 G28 Z0 ----------------------------------------------------------------------


def test_haas_program_returns_home_with_g0_g91_g28() -> None:
    errors = corpus_errors("versa-o8000-tablewash.nc")
    assert not [e for e in errors if e.line == 5], [str(e) for e in errors]


def test_g0_g91_g28_z0_moves_z_home_only_and_sets_the_modes() -> None:
    interp = Interpreter(MILL)
    cmds = list(interp.run("G90 G1 X10 Y20 Z30 F500\nG0 G91 G28 Z0\n"))
    assert [type(c) for c in cmds] == [StraightFeed, StraightTraverse, StraightTraverse]
    assert cmds[1].end == (10.0, 20.0, 30.0)  # the intermediate point: Z0 incremental
    assert cmds[2].end == (10.0, 20.0, 0.0)  # only Z goes to its reference point
    assert interp.state.gcodes["motion"] == "G0"
    assert interp.state.gcodes["distance"] == "G91"


def test_g80_beside_g28_cancels_the_cycle_and_a_cycle_beside_it_is_refused() -> None:
    interp = Interpreter(MILL)
    list(interp.run("G0 X0 Y0 Z10\nG81 X5 Z-1 R2 F100\nG80 G28 Z10\n"))
    assert interp.state.gcodes["cycle"] == "G80"
    with pytest.raises(NcError, match="cannot share a block"):
        run("G0 X0 Y0 Z10\nG81 G28 Z10 R2 F100\n")


# --- G40 with no in-plane move ----------------------------------------------------------


def test_lcnc_comp_changes_plane_after_a_lone_g40() -> None:
    # `g40`, blank line, `g20 g64 g18`: the plane change was refused.
    assert [str(e) for e in corpus_errors("lcnc-comp.nc")] == []


def test_lathe_g53_after_g40_with_a_z_move() -> None:
    # `N20 G00 G40 Z0.1` (no X change) then `G53 G00 X0.0`: was "G53 with cutter
    # compensation active" (the file has other, unrelated errors: G71 is part 2's).
    errors = corpus_errors("enier-lathe-hp1.nc", "lathe")
    assert not [e for e in errors if "compensation" in e.message], [str(e) for e in errors]


def test_g40_then_a_z_move_then_g28_leaves_from_the_offset_point() -> None:
    cmds = run("G0 X0 Y0 Z5\nG41 D1 G1 X10 F100\nX20\nG40\nG0 Z50\nG28\nM30\n")
    moves = [(type(c).__name__, c.end) for c in cmds if hasattr(c, "end")]
    assert moves == [
        ("StraightTraverse", (0.0, 0.0, 5.0)),
        ("StraightFeed", (10.0, 1.0, 5.0)),  # start-up
        ("StraightFeed", (20.0, 1.0, 5.0)),  # the element ends at its perpendicular offset
        ("StraightTraverse", (20.0, 1.0, 50.0)),  # Z up there
        ("StraightTraverse", (0.0, 0.0, 0.0)),  # G28: uncompensated, all axes home
    ]


@pytest.mark.parametrize("after", ["G53 G0 Z0", "G18", "G81 X30 Y0 Z-1 R2", "G68 X0 Y0 R10"])
def test_a_lone_g40_is_completed_by_codes_that_need_compensation_off(after: str) -> None:
    run(f"G0 X0 Y0 Z5\nG41 D1 G1 X10 F100\nX20\nG40\n{after}\nM30\n")


def test_g40_then_an_in_plane_move_is_still_the_cancel_move() -> None:
    cmds = run("G0 X0 Y0 Z5\nG41 D1 G1 X10 F100\nX20\nG40\nG0 Z50\nX30 Y0\nM30\n")
    assert [c.end for c in cmds if hasattr(c, "end")][-1] == (30.0, 0.0, 50.0)


# --- the interference check looks forward, as a control's read-ahead ---------------------

# Two laps of a 75 x 45 rectangle entered along the extension of its first side (X5 from
# Y-25): on the second lap the compensated path at the (5, 5) corner comes back onto that
# first side's line, whose part below Y5 is the lead-in through air.
TWO_LAPS = """G17 G21 G90
G0 X-25 Y-25
G1 Z-5 F500
G41 D1 X5
Y50
X80
Y5
X5
Y50
X70
G2 X80 Y40 R10
G1 Y5
X20
G40 X-25
M30
"""


def test_a_second_lap_is_not_a_gouge_against_the_lead_in() -> None:
    tools = {1: ToolOffset(radius=5.0)}
    assert list(Interpreter(MILL, tools=tools).run(TWO_LAPS))


@pytest.mark.parametrize("name", ["enier-mill-hp1.nc", "enier-nims-mill.nc"])
def test_haas_training_programs_lap_twice_with_a_real_cutter(name: str) -> None:
    # with the shipped 5 mm radius these were refused against their own lead-in
    path = reference.GCODE_CORPUS / name
    if not path.exists():
        pytest.skip(reference.MISSING)
    params = replace(MILL, axes=BIG)
    with open(path, encoding="latin-1") as fh:
        errors = check(fh, params, file=name, tools={1: ToolOffset(radius=5.0)})
    assert [str(e) for e in errors if "gouge" in str(e)] == []


def test_a_neck_ahead_is_still_a_gouge() -> None:
    # inside a slot 6 wide with a 10 mm cutter (G42: the tool between the walls)
    slot = "G17 G21 G90\nG0 X-20 Y-20\nG1 Z-5 F500\nG42 D1 X0\nY40\nX6\nY-20\nG40 X30\nM30\n"
    with pytest.raises(NcError, match="gouge"):
        list(Interpreter(MILL, tools={1: ToolOffset(radius=5.0)}).run(slot))


# --- a reference return does not fix the program's unit -----------------------------------


def test_g20_after_a_bare_g28_is_taken() -> None:
    # Haas lathe programs (enier-lathe-nims1001) start `G28`, then `G20` with the tool call
    moves = [c for c in run("G28\nG20 G90\nG0 X1 Z1\nM30\n") if isinstance(c, StraightTraverse)]
    assert moves[-1].end[0] == pytest.approx(25.4)
    with pytest.raises(NcError, match="unit change after motion"):
        run("G28 X0\nG20\nG0 X1\nM30\n")  # an intermediate point is a programmed position
