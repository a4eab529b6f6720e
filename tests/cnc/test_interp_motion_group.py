"""The motion step (cnc/interp/motion.py): which codes may share a block with a motion or
cycle code, what the modal motion becomes, and when a canned cycle ends.

The moves are worked out by hand (a mill with its reference point at the origin, G54 = 0);
they are the table `make mutation` holds cnc/interp/motion.py against (tests/mutation.py).
"""

from cnc.canon import StraightFeed as F
from cnc.canon import StraightTraverse as T
from cnc.interp import Interpreter
from cnc.params import AxisParams, MachineParams
from tests.cnc.interp_tables import cases, refused

BIG = tuple(AxisParams(a, -1000, 1000, 30000, 3000, 5e4) for a in "XYZ")
MILL = MachineParams(axes=BIG)
# a G81 drill at X0 Y0 from Z10: R2, bottom Z-5, F100; each hole: over it at the initial Z,
# down to R, feed to the bottom, back to the initial Z10 (G98); all exact stop
DRILL = "G0 Z10\nG81 X0 Y0 Z-5 R2 F100\n"


def interp(text: str) -> tuple[Interpreter, list]:
    it = Interpreter(MILL)
    return it, list(it.run(text))


# (name, program, the last commands, modal motion after, cycle after)
# fmt: off
MODES = [
    # with G10/G28/G30/G92 the motion code only sets the mode: the axis words are theirs
    ("G0 beside G28 sets G0", "G1 X1 F100\nG0 G28 Z5\nX3",
     [T(2, (1.0, 0.0, 5.0)), T(2, (1.0, 0.0, 0.0)), T(3, (3.0, 0.0, 0.0))], "G0", "G80"),
    ("G1 beside G92 sets G1", "G0 X1\nG1 G92 X0 F100\nX2",
     [T(1, (1.0, 0.0, 0.0)), F(3, (3.0, 0.0, 0.0), 100.0)], "G1", "G80"),
    ("G1 beside G10 sets G1", "G1 G10 L2 P1 X5 F100\nX1", [F(2, (6.0, 0.0, 0.0), 100.0)], "G1", "G80"),
    ("G53 moves with its G1", "G0 X1\nG53 G1 X5 F100", [T(1, (1.0, 0.0, 0.0)), F(2, (5.0, 0.0, 0.0), 100.0)],
     "G1", "G80"),
    # G80 beside G28 ends the cycle: the next X is a plain move in the motion before it
    ("G80 beside G28 ends the cycle", DRILL + "G80 G28 Z10\nX5",
     [T(3, (0.0, 0.0, 10.0)), T(3, (0.0, 0.0, 0.0)), T(4, (5.0, 0.0, 0.0))], "G0", "G80"),
    # a motion code ends the cycle too
    ("G0 ends the cycle", DRILL + "G0 X10", [T(2, (0.0, 0.0, 10.0), True), T(3, (10.0, 0.0, 10.0))],
     "G0", "G80"),
    ("G1 ends the cycle", DRILL + "G1 X10",
     [T(2, (0.0, 0.0, 10.0), True), F(3, (10.0, 0.0, 10.0), 100.0)], "G1", "G80"),
    ("G9 G80: the move after the cycle is exact stop", DRILL + "G9 G80 X5",
     [T(2, (0.0, 0.0, 10.0), True), T(3, (5.0, 0.0, 10.0), True)], "G0", "G80"),
    # the cycle is modal: a block of axis words alone drills again there
    ("a cycle repeats at the next X", DRILL + "X10",
     [T(3, (10.0, 0.0, 10.0), True), T(3, (10.0, 0.0, 2.0), True),
      F(3, (10.0, 0.0, -5.0), 100.0, True), T(3, (10.0, 0.0, 10.0), True)], "G0", "G81"),
    ("G9 marks a plain move", "G9 G1 X1 F100", [F(1, (1.0, 0.0, 0.0), 100.0, True)], "G1", "G80"),
    # a modal G2 with no words is no move; G2 named with none is refused (below)
    ("a modal arc with no words", "G2 X10 Y0 R5 F100\nM8", None, "G2", "G80"),
]
# fmt: on


@cases("prog,last,motion,cycle", MODES)
def test_motion_and_cycle_modes(prog, last, motion, cycle) -> None:
    it, out = interp(prog + "\n")
    if last is not None:
        assert out[-len(last) :] == last
    else:
        assert not any(isinstance(c, T | F) for c in out if c.line > 1)
    assert (it.state.gcodes["motion"], it.state.gcodes["cycle"]) == (motion, cycle)


SHARE = "a motion G code cannot share a block with this G code"
# (name, program, message, line, column): the column is the motion or cycle code's
# fmt: off
REFUSALS = [
    ("G1 beside G4", "N10 G4 P100 G1 X1 F10", SHARE, 1, 13),
    ("G81 beside G28", "G0 Z10\nG81 G28 Z10 R2 F100", SHARE, 2, 1),
    ("G81 beside G28, G28 first", "G0 Z10\nG28 G81 Z10 R2 F100", SHARE, 2, 5),
    # (was a silent G0 to X1 Z-5: the drill cycle dropped)
    ("G81 beside G53", "G53 G81 X1 Z-5 R2 F100", SHARE, 1, 5),
    ("G2 with no end point or centre", "M8 G2", "arc without end point or centre", 1, 4),
]
# fmt: on


@cases("prog,message,line,col", REFUSALS)
def test_refusals(prog, message, line, col) -> None:
    assert refused(lambda: interp(prog + "\n")) == (message, line, col)
