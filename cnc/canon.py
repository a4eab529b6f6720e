"""Canonical machine commands: what the interpreter hands to the planner and the machine.

The interpreter resolves everything program-specific (units, work offsets, tool length,
incremental moves, polar/mirror/scale/rotation transforms, cutter compensation, canned
cycles, subprograms) so that every command below is in **machine coordinates, mm, mm/min,
seconds and rpm**. Each command carries `line`, the 1-based source line that produced it
(for subprograms: the line in the file the block came from), so status and errors can point
back at the program.

Positions are `Pose` tuples: X, Y, Z, then the machine's rotary axes in configured order
(`MachineParams.pose_axes`: mill4 X Y Z A, mill5 X Y Z B C; rotary angles in degrees).
A machine without rotary axes has 3-component poses; a lathe keeps Y at 0 and its
kinematics drops it. An arc's centre has the same length as its end (its rotary part is
the unchanged angles: a rotary axis does not turn in a circle).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

Pose = tuple[float, ...]


class Plane(Enum):
    """Arc plane selection; the value is the index of the plane's normal axis in a Pose."""

    XY = 2  # G17, normal Z
    ZX = 1  # G18, normal Y
    YZ = 0  # G19, normal X


class PathMode(Enum):
    EXACT_STOP = "G61"  # stop at every block end
    CONTINUOUS = "G64"  # blend corners within a path tolerance


@dataclass(frozen=True, slots=True)
class StraightTraverse:
    """G0 rapid to `end`; the planner uses the axes' rapid velocities."""

    line: int
    end: Pose
    exact_stop: bool = False  # G9 on this block


@dataclass(frozen=True, slots=True)
class StraightFeed:
    """G1 linear interpolation to `end` at path feed `feed` mm/min."""

    line: int
    end: Pose
    feed: float
    exact_stop: bool = False


@dataclass(frozen=True, slots=True)
class ThreadFeed(StraightFeed):
    """G32 (and the G76/G92 cycles' passes): a thread move, `feed` = `lead` x `rpm`.

    The controller holds the lead while the spindle runs at another speed than `rpm` (an
    override): the move's feed follows the spindle speed, and the feed override and the
    adaptive feed are out of effect during it (Fanuc: fixed at 100 %).
    """

    lead: float = 0.0  # mm per spindle revolution, along the thread's long axis
    rpm: float = 0.0  # the spindle speed `feed` is computed for


@dataclass(frozen=True, slots=True)
class SkipFeed(StraightFeed):
    """G31: a linear feed move to `end` that stops at the skip signal; the rest of the move
    is dropped and the program goes on from where the machine stopped.

    `signal`: the skip input it waits for (G31 P1..P4: the multi-step skip's steps; 0 for
    G31 without P); `tool_length`: the length of the tool in the spindle as the control
    knows it (the tool tip is the gauge line minus this along Z) and `tool_radius` its
    radius (the tool's end is a disc of it), for the tool setter;
    `expected`: where the interpreter expects the skip (X Y Z: the machine's tool setter
    met on the programmed path), None when it expects none: a planner without a machine
    (`nc plan`) stops there. The machine stops taking blocks after it until the move has
    ended and hands the interpreter the latched position (`Interpreter.skipped`).
    """

    signal: int = 0
    tool_length: float = 0.0
    tool_radius: float = 0.0
    expected: Pose | None = None

    def planned(self) -> StraightFeed:
        """The move as a planner without a skip signal runs it: to the expected skip."""
        if self.expected is None:
            return StraightFeed(self.line, self.end, self.feed, True)
        return StraightFeed(self.line, (*self.expected[:3], *self.end[3:]), self.feed, True)


@dataclass(frozen=True, slots=True)
class SpindleSync:
    """Before a thread pass: wait for the spindle's one-revolution signal, so every pass of
    a thread starts at the same spindle angle and cuts the same helix (a sync point: the
    motion stops at the end of the move before it)."""

    line: int


@dataclass(frozen=True, slots=True)
class ArcFeed:
    """G2/G3 circular or helical interpolation.

    `center` is the arc centre in machine coordinates (its normal-axis component equals the
    start's). The helix rises linearly along the plane's normal axis from the start to
    `end`. `turns` counts extra full turns (0 for an ordinary arc; a full circle is start ==
    end in the plane with turns=0 and is taken as 360 degrees).
    """

    line: int
    end: Pose
    center: Pose
    plane: Plane
    clockwise: bool
    feed: float
    turns: int = 0
    exact_stop: bool = False


@dataclass(frozen=True, slots=True)
class SetPathMode:
    """G61 / G64 [P tolerance mm], Haas G187 (accuracy) and G103 (look-ahead limit).

    Each one carries the whole path control state for the blocks that follow: the mode, the
    path tolerance and the look-ahead limit (`lookahead` motion blocks, 0 = the machine's
    own look-ahead; G103 P1..P15).
    """

    line: int
    mode: PathMode
    tolerance: float = 0.0  # mm; 0 means "as fast as the limits allow"
    lookahead: int = 0


@dataclass(frozen=True, slots=True)
class Dwell:
    line: int
    seconds: float


class SpindleDirection(Enum):
    CW = "M3"
    CCW = "M4"
    STOP = "M5"
    ORIENT = "M19"


@dataclass(frozen=True, slots=True)
class Spindle:
    """Spindle command. `rpm` is the commanded speed (for G96 the speed at the current X).

    `surface_speed` (m/min) and `max_rpm` are set under G96 constant surface speed so that a
    lathe's machine can follow X; otherwise None.
    """

    line: int
    direction: SpindleDirection
    rpm: float
    surface_speed: float | None = None
    max_rpm: float | None = None


@dataclass(frozen=True, slots=True)
class Coolant:
    """M7 mist / M8 flood / M9 off, as the resulting state."""

    line: int
    mist: bool
    flood: bool


@dataclass(frozen=True, slots=True)
class ToolSelect:
    """T word: prepare the tool (a changer may pre-position its magazine)."""

    line: int
    tool: int


@dataclass(frozen=True, slots=True)
class ToolChange:
    """M6: change to the selected tool. Handed to the PLC with wait-for-finish."""

    line: int
    tool: int


@dataclass(frozen=True, slots=True)
class AuxFunction:
    """An M-function the NC does not handle itself: strobe code to the PLC, wait for finish."""

    line: int
    code: int
    wait: bool = True


class StopKind(Enum):
    PROGRAM_STOP = "M0"
    OPTIONAL_STOP = "M1"
    PROGRAM_END = "M2"
    PROGRAM_END_REWIND = "M30"


@dataclass(frozen=True, slots=True)
class ProgramStop:
    line: int
    kind: StopKind


CanonCommand = (
    StraightTraverse
    | StraightFeed
    | ArcFeed
    | SetPathMode
    | Dwell
    | Spindle
    | Coolant
    | ToolSelect
    | ToolChange
    | AuxFunction
    | ProgramStop
)

MOTION_TYPES = (StraightTraverse, StraightFeed, ArcFeed)
