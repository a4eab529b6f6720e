"""Property tests: random paths never exceed the axis limits and stay within G64 P."""

from __future__ import annotations

import math

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cnc.canon import (
    ArcFeed,
    PathMode,
    Plane,
    SetPathMode,
    StraightFeed,
    StraightTraverse,
)
from cnc.params import MachineParams
from tests.cnc.test_planner_helpers import (
    assert_within_limits,
    max_deviation,
    programmed_pieces,
    run,
)

coord = st.floats(min_value=-25.0, max_value=25.0, allow_nan=False).map(lambda x: round(x, 3))
feed = st.sampled_from([1200.0, 4000.0, 9000.0, 15000.0])


@st.composite
def programs(draw):
    n = draw(st.integers(min_value=2, max_value=7))
    tol = draw(st.sampled_from([0.001, 0.01, 0.05, 0.5]))
    cmds = [SetPathMode(1, PathMode.CONTINUOUS, tol)]
    pos = (0.0, 0.0, 0.0)
    exact_ends = []
    for i in range(n):
        line = i + 2
        kind = draw(st.sampled_from(["g0", "g1", "g1", "g1", "arc", "g61", "short"]))
        g9 = draw(st.booleans()) and draw(st.booleans())
        if kind == "g61":
            cmds.append(SetPathMode(line, PathMode.EXACT_STOP))
            cmds.append(SetPathMode(line, PathMode.CONTINUOUS, tol))
            continue
        if kind == "arc":
            plane = draw(st.sampled_from(list(Plane)))
            k = plane.value
            radius = draw(st.floats(min_value=0.5, max_value=15.0))
            ang0 = draw(st.floats(min_value=0.0, max_value=2 * math.pi))
            sweep = draw(st.floats(min_value=0.2, max_value=6.0))
            cw = draw(st.booleans())
            rise = draw(st.sampled_from([0.0, 0.0, 1.5, -3.0]))
            axes = [a for a in range(3) if a != k]
            # choose the centre so that the arc starts at pos; build the end on the circle,
            # turning the right way round for G2/G3 in this plane
            c = list(pos)
            c[axes[0]] = pos[axes[0]] - radius * math.cos(ang0)
            c[axes[1]] = pos[axes[1]] - radius * math.sin(ang0)
            e1 = [0.0, 0.0, 0.0]
            e1[axes[0]] = math.cos(ang0)
            e1[axes[1]] = math.sin(ang0)
            w = [0.0, 0.0, 0.0]
            w[k] = 1.0
            e2 = [
                w[1] * e1[2] - w[2] * e1[1],
                w[2] * e1[0] - w[0] * e1[2],
                w[0] * e1[1] - w[1] * e1[0],
            ]
            if cw:
                e2 = [-x for x in e2]
            end = [
                c[i] + radius * (math.cos(sweep) * e1[i] + math.sin(sweep) * e2[i])
                for i in range(3)
            ]
            end[k] = pos[k] + rise
            end = tuple(end)
            cmds.append(ArcFeed(line, end, tuple(c), plane, cw, draw(feed), 0, g9))
            pos = end
            continue
        if kind == "short":
            end = tuple(round(p + draw(st.floats(min_value=-0.05, max_value=0.05)), 4) for p in pos)
        else:
            end = (draw(coord), draw(coord), draw(coord))
        if kind == "g0":
            cmds.append(StraightTraverse(line, end, g9))
        else:
            cmds.append(StraightFeed(line, end, draw(feed), g9))
        if g9 and end != pos:  # G9 on a move that goes nowhere is a no-op
            exact_ends.append(end)
        pos = end
    return cmds, tol, exact_ends, pos


@settings(
    max_examples=int(__import__("os").environ.get("PLANNER_EXAMPLES", "25")),
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
    derandomize=not __import__("os").environ.get("PLANNER_RANDOM"),
)
@given(programs(), st.sampled_from([0.001, 0.002, 0.004, 0.008]))
def test_random_paths_respect_limits_tolerance_and_exact_stops(prog, ipo):
    cmds, tol, exact_ends, final = prog
    params = MachineParams(ipo_cycle_s=ipo)
    start = (0.0, 0.0, 0.0)
    samples, _ = run(params, cmds, start)
    assert_within_limits(params, samples, start, ipo)
    assert max_deviation(samples, programmed_pieces(cmds, start)) <= tol + 1e-9
    poses = [s.pose for s in samples]
    for e in exact_ends:
        assert e in poses, "exact stop point not sampled"
    assert samples[-1].pose == final


events = st.lists(
    st.tuples(
        st.integers(min_value=1, max_value=1500),
        st.sampled_from(["feed", "rapid", "hold", "single"]),
        st.sampled_from([0.0, 0.3, 1.0, 1.6, 2.0]),
    ),
    max_size=5,
)


@settings(
    max_examples=int(__import__("os").environ.get("PLANNER_EXAMPLES", "25")),
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
    derandomize=not __import__("os").environ.get("PLANNER_RANDOM"),
)
@given(programs(), events)
def test_operator_events_never_break_the_limits(prog, evs):
    """Overrides, feed hold and single block at random cycles: limits, P and the end hold."""
    from cnc.interpolator import Motion

    cmds, tol, _exact, final = prog
    params = MachineParams()
    start = (0.0, 0.0, 0.0)
    m = Motion(params, start=start)
    for c in cmds:
        m.push(c)
    m.end_of_program()
    at = {}
    for cyc, kind, val in evs:
        at.setdefault(cyc, []).append((kind, val))
    samples = []
    for cyc in range(400_000):
        for kind, val in at.get(cyc, ()):
            if kind == "feed":
                m.set_feed_override(val)
            elif kind == "rapid":
                m.set_rapid_override(min(val, 1.0))
            elif kind == "hold":
                m.feed_hold()
            else:
                m.set_single_block(val > 0.5)
        if cyc > 1600:  # after the events: everything back to normal, let it finish
            m.set_feed_override(1.0)
            m.set_rapid_override(1.0)
            m.set_single_block(False)
            if m.holding:
                m.resume()
        s = m.step()
        samples.append(s)
        if s.sync is not None:
            m.acknowledge()
        if cyc > 1600 and m.idle:
            break
    assert_within_limits(params, samples, start)
    assert max_deviation(samples, programmed_pieces(cmds, start)) <= tol + 1e-9
    assert samples[-1].pose == final


@st.composite
def polylines(draw):
    """CAM-like chains of short lines (rounded to 0.1 um), bending at random."""
    n = draw(st.integers(min_value=3, max_value=40))
    tol = draw(st.sampled_from([0.001, 0.005, 0.02]))
    step = draw(st.sampled_from([0.01, 0.05, 0.2, 1.0]))
    pos = (0.0, 0.0, 0.0)
    ang = draw(st.floats(min_value=0.0, max_value=6.28))
    cmds = [SetPathMode(1, PathMode.CONTINUOUS, tol)]
    for i in range(n):
        ang += draw(st.floats(min_value=-0.6, max_value=0.6))
        ln = step * draw(st.floats(min_value=0.3, max_value=1.7))
        dz = draw(st.sampled_from([0.0, 0.0, -0.2 * step]))
        end = tuple(
            round(v, 4)
            for v in (pos[0] + ln * math.cos(ang), pos[1] + ln * math.sin(ang), pos[2] + dz)
        )
        if end == pos:
            continue
        cmds.append(StraightFeed(i + 2, end, draw(feed)))
        pos = end
    return cmds, tol, pos


@settings(
    max_examples=int(__import__("os").environ.get("PLANNER_EXAMPLES", "25")),
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
    derandomize=not __import__("os").environ.get("PLANNER_RANDOM"),
)
@given(polylines(), st.sampled_from([0.0005, 0.002, 0.008]))
def test_short_segment_chains_respect_limits_and_tolerance(prog, ipo):
    cmds, tol, final = prog
    params = MachineParams(ipo_cycle_s=ipo)
    start = (0.0, 0.0, 0.0)
    samples, _ = run(params, cmds, start)
    assert_within_limits(params, samples, start, ipo)
    assert max_deviation(samples, programmed_pieces(cmds, start)) <= tol + 1e-9
    assert samples[-1].pose == final
