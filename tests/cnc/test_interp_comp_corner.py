"""The arc inserted at an outside corner under G41/G42 is cut at the corner's height: it does
not take the next block's helical Z move (nor its turns) with it."""

from cnc.canon import ArcFeed, StraightFeed
from cnc.interp import Interpreter, ToolOffset
from cnc.params import MachineParams

PROGRAM = """G21 G90 G17 G54
G0 X0 Y-5 Z0
G42 D1 G1 X10 Y0 F300
G1 X20 Y0
G2 X30 Y10 Z-3 I10 J0
G40 G1 X40 Y10
M30
"""


def test_corner_arc_before_a_helix_is_flat():
    interp = Interpreter(
        MachineParams(),
        tools={1: ToolOffset(radius=2.0)},
        work_offsets={1: (-300.0, -200.0, -100.0)},
        file="t.nc",
    )
    out = [c for c in interp.run(PROGRAM) if isinstance(c, ArcFeed | StraightFeed)]
    helix = [c for c in out if isinstance(c, ArcFeed) and c.line == 5]
    assert len(helix) == 2  # the left turn into the arc is an outside corner for G42
    corner, body = helix
    before = out[out.index(corner) - 1]
    assert corner.turns == 0
    assert corner.end[2] == before.end[2]  # flat: cut at the current Z
    assert body.end[2] == before.end[2] - 3.0  # the helix itself still descends 3 mm
