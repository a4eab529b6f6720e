"""Haas G103 (look-ahead limit) and G187 (accuracy): their effect on the planner.

The interpreter turns both into `SetPathMode` commands carrying the whole path control
state (mode, tolerance, look-ahead limit); the planner (`Motion`) takes fewer blocks ahead
under G103 P and blends corners within the G187 tolerance.
"""

from __future__ import annotations

import pytest

from cnc.canon import MOTION_TYPES, PathMode, SetPathMode
from cnc.errors import NcError
from cnc.interp import Interpreter
from cnc.interpolator import Motion
from cnc.params import AxisParams, MachineParams
from tests.cnc.test_planner_helpers import run as run_motion

AXES = tuple(AxisParams(a, -1000, 1000, 30000, 3000, 5e4) for a in "XYZ")
MILL = MachineParams(axes=AXES, lookahead=200, default_path_tolerance=0.01)
START = (0.0, 0.0, 0.0)


def interp(text: str) -> list:
    return list(Interpreter(MILL, start=START).run(text))


def modes(text: str) -> list[tuple[PathMode, float, int]]:
    return [(c.mode, c.tolerance, c.lookahead) for c in interp(text) if isinstance(c, SetPathMode)]


def zigzag(n: int, x0: float = 0.0) -> str:
    """n short feed moves with 90 degree corners (blocks the look-ahead can see)."""
    return "".join(f"X{x0 + (i + 1) * 2} Y{2 * ((i + 1) % 2)}\n" for i in range(n))


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("G103 P5\n", [(PathMode.CONTINUOUS, 0.01, 5)]),
        ("G103 P0\n", [(PathMode.CONTINUOUS, 0.01, 0)]),
        ("G103\n", [(PathMode.CONTINUOUS, 0.01, 0)]),
        ("G187 E0.05\n", [(PathMode.CONTINUOUS, 0.05, 0)]),
        ("G20 G187 E0.002\n", [(PathMode.CONTINUOUS, pytest.approx(0.0508), 0)]),
        ("G187 P1\n", [(PathMode.CONTINUOUS, 0.04, 0)]),
        ("G187 P3\n", [(PathMode.CONTINUOUS, 0.0025, 0)]),
        ("G187 P1 E0.2\n", [(PathMode.CONTINUOUS, 0.2, 0)]),
        ("G187 E0.2\nG187\n", [(PathMode.CONTINUOUS, 0.2, 0), (PathMode.CONTINUOUS, 0.01, 0)]),
        # each command carries the whole state: G103 keeps the G187 tolerance and back
        (
            "G187 E0.2\nG103 P2\nG64\n",
            [
                (PathMode.CONTINUOUS, 0.2, 0),
                (PathMode.CONTINUOUS, 0.2, 2),
                (PathMode.CONTINUOUS, 0.01, 2),
            ],
        ),
        ("G103 P3\nG61\n", [(PathMode.CONTINUOUS, 0.01, 3), (PathMode.EXACT_STOP, 0.0, 3)]),
    ],
)
def test_interpreter_path_control_state(text: str, expected: list) -> None:
    assert modes(text) == expected


@pytest.mark.parametrize(
    ("text", "col", "message"),
    [
        ("G103 P16\n", 6, "G103 P .* 0..15"),
        ("G103 P1.5\n", 6, "G103 P"),
        ("G187 P4\n", 6, "P must be 1 .rough., 2 .medium. or 3 .finish."),
        ("G187 E0\n", 6, "E .corner rounding tolerance. must be > 0"),
        ("G1 X1 E2 F100\n", 7, "E word with no code"),
    ],
)
def test_bad_path_control_words(text: str, col: int, message: str) -> None:
    with pytest.raises(NcError, match=message) as exc:
        interp(text)
    assert (exc.value.line, exc.value.col) == (1, col)


def test_g103_limits_the_blocks_the_planner_takes_ahead() -> None:
    cmds = interp("G1 F3000\nG103 P2\n" + zigzag(6) + "G103 P0\n" + zigzag(6, 12.0))
    m = Motion(MILL, start=START)
    pushed_before_refusal = []
    queue = list(cmds)
    # feed without stepping: the window fills to the limit and then refuses
    n = 0
    while queue and m.push(queue[0]):
        if isinstance(queue[0], MOTION_TYPES):
            n += 1
        queue.pop(0)
    pushed_before_refusal.append(n)
    assert pushed_before_refusal == [2]
    assert m.space() == 0
    # run the whole program: every G103 P2 block still runs, the limit then lifts
    samples, _ = run_motion(MILL, cmds, start=START)
    assert samples[-1].pose[:2] == pytest.approx((24.0, 0.0))


def _stops_between_blocks(text: str) -> int:
    """Motion samples at rest strictly inside the program's path (block ends it stops at)."""
    samples, _ = run_motion(MILL, interp(text), start=START)
    moving = [i for i, s in enumerate(samples) if s.velocity > 0.0]
    first, last = moving[0], moving[-1]
    return sum(1 for s in samples[first:last] if s.velocity == 0.0)


def test_g103_p1_stops_at_every_block_end_and_p0_blends() -> None:
    # P1: the planner never sees the next block, so each one ends at rest
    assert _stops_between_blocks("G1 F3000\nG103 P1\n" + zigzag(5)) >= 4
    assert _stops_between_blocks("G1 F3000\nG103 P0\n" + zigzag(5)) == 0


def test_g187_tolerance_bounds_the_corner_blends() -> None:
    def deviation(text: str) -> float:
        m = Motion(MILL, start=START)
        run_motion(MILL, interp(text), start=START, motion=m)
        return m.path.max_blend_deviation

    rough = deviation("G1 F3000\nG187 E0.2\n" + zigzag(4))
    fine = deviation("G1 F3000\nG187 E0.002\n" + zigzag(4))
    assert 0.0 < fine <= 0.002 + 1e-12
    assert 0.002 < rough <= 0.2 + 1e-12
