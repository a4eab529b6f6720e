"""The look-ahead window never makes the planner break its limits (issue 13, item 5).

A re-plan for new blocks starts from the state the executor has committed to. The new
blocks may ask for less speed than the old plan was heading for (a G64 blend eats the
last line, a junction into it gets its cap, coasts move); if the window did not keep a
stoppable tail the new plan could only meet them by demanding more than the limits
(real CAM programs showed X jerk 2.6x its limit at look-ahead 200, 50x at 5). Short
blocks and a shallow look-ahead provoke this most, so the paths here are chains of short
lines and arcs (CAM output rounded to 0.1 um) run at look-ahead 5, 50 and 200.

Tolerance: the discrete limits of docs/motion.md hold up to 1e-9 relative plus the float
rounding floor of the k-th backward difference of poses of size |p|, 2^k eps |p| / T^k
(`assert_within_limits`): the profile is planned in closed form and only rounding
separates a sample from its exact value.
"""

from __future__ import annotations

import math
import os

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cnc.canon import ArcFeed, PathMode, Plane, SetPathMode, StraightFeed, StraightTraverse
from cnc.params import MachineParams
from tests.cnc.test_planner_helpers import (
    assert_within_limits,
    max_deviation,
    programmed_pieces,
    run,
)

EXAMPLES = int(os.environ.get("PLANNER_EXAMPLES", "20"))


@st.composite
def short_blocks(draw):
    """A CAM-like chain of short lines and arcs (ends rounded to 0.1 um), some corners."""
    n = draw(st.integers(min_value=4, max_value=45))
    tol = draw(st.sampled_from([0.001, 0.005, 0.01, 0.05]))
    step = draw(st.sampled_from([0.003, 0.01, 0.03, 0.1, 0.4]))
    feed = draw(st.sampled_from([600.0, 2000.0, 6000.0, 15000.0]))
    cmds: list = [SetPathMode(1, PathMode.CONTINUOUS, tol)]
    pos = (0.0, 0.0, 0.0)
    heading = draw(st.floats(min_value=0.0, max_value=2 * math.pi))
    for i in range(n):
        line = i + 2
        kind = draw(st.sampled_from(["line", "line", "line", "arc", "corner", "plunge", "rapid"]))
        if kind == "corner":
            heading += draw(st.sampled_from([-2.5, -1.6, -0.8, 0.8, 1.6, 2.5]))
            kind = "line"
        else:
            heading += draw(st.floats(min_value=-0.35, max_value=0.35))
        length = step * draw(st.floats(min_value=0.2, max_value=2.5))
        if kind == "arc":
            radius = draw(st.floats(min_value=0.05, max_value=20.0))
            cw = draw(st.booleans())
            # the start radius points away from the centre, perpendicular to the heading
            side = -1.0 if cw else 1.0
            a0 = heading - side * 0.5 * math.pi
            c = (pos[0] - radius * math.cos(a0), pos[1] - radius * math.sin(a0), pos[2])
            sweep = min(length / radius, 3.0)
            a1 = a0 + side * sweep
            end = (
                round(c[0] + radius * math.cos(a1), 4),
                round(c[1] + radius * math.sin(a1), 4),
                pos[2],
            )
            if math.dist(end[:2], c[:2]) < 1e-3 or math.dist(pos[:2], c[:2]) < 1e-3:
                continue
            cmds.append(ArcFeed(line, end, c, Plane.XY, cw, feed))
            heading = a1 + side * 0.5 * math.pi
            pos = end
            continue
        dz = -0.3 * length if kind == "plunge" else 0.0
        end = (
            round(pos[0] + length * math.cos(heading), 4),
            round(pos[1] + length * math.sin(heading), 4),
            round(pos[2] + dz, 4),
        )
        if end == pos:
            continue
        if kind == "rapid":
            cmds.append(StraightTraverse(line, end))
        else:
            cmds.append(StraightFeed(line, end, feed))
        pos = end
    return cmds, tol, pos


@pytest.mark.parametrize("lookahead", [5, 50, 200])
def test_short_block_paths_never_break_the_limits_at_any_look_ahead(lookahead):
    @settings(
        max_examples=EXAMPLES,
        deadline=None,
        suppress_health_check=[HealthCheck.too_slow],
        derandomize=not os.environ.get("PLANNER_RANDOM"),
    )
    @given(short_blocks(), st.sampled_from([0.001, 0.002, 0.004]))
    def check(prog, ipo):
        cmds, tol, final = prog
        params = MachineParams(ipo_cycle_s=ipo, lookahead=lookahead)
        start = (0.0, 0.0, 0.0)
        samples, _ = run(params, cmds, start)
        assert_within_limits(params, samples, start, ipo)
        assert max_deviation(samples, programmed_pieces(cmds, start)) <= tol + 1e-9
        assert samples[-1].pose == final

    check()


def _zigzag(n: int, step: float) -> list:
    """Short lines turning 40 deg left and right: every junction a coast or a share."""
    cmds: list = [SetPathMode(1, PathMode.CONTINUOUS, 0.005)]
    x = y = 0.0
    for i in range(n):
        ang = 0.35 if i % 2 else -0.35
        x = round(x + step * math.cos(ang), 4)
        y = round(y + step * math.sin(ang), 4)
        cmds.append(StraightFeed(i + 2, (x, y, 0.0), 3000.0))
    return cmds


@pytest.mark.parametrize("lookahead", [2, 5, 50])
def test_a_zigzag_of_short_lines_stays_within_the_limits(lookahead):
    """Deterministic companion of the property: the shape that broke the jerk limit."""
    params = MachineParams(lookahead=lookahead)
    cmds = _zigzag(120, 0.02)
    samples, _ = run(params, cmds)
    assert_within_limits(params, samples, (0.0, 0.0, 0.0))
    assert samples[-1].pose == cmds[-1].end
