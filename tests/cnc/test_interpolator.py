"""Interpolator: closed-form sampling of lines, arcs and helices; determinism; IPO cycle."""

from __future__ import annotations

import hashlib
import math

import pytest

from cnc.canon import ArcFeed, PathMode, Plane, SetPathMode, StraightFeed, StraightTraverse
from cnc.interpolator import Motion
from cnc.params import MachineParams
from tests.cnc.test_planner_helpers import assert_within_limits, run

P = MachineParams()


@pytest.mark.parametrize("plane", list(Plane))
@pytest.mark.parametrize("cw", [True, False])
def test_arc_samples_lie_on_the_circle_to_rounding(plane, cw):
    k = plane.value
    axes = [i for i in range(3) if i != k]
    start = [-20.0, -20.0, -20.0]
    center = list(start)
    center[axes[0]] -= 12.5  # start is at angle 0 around the centre
    end = list(center)
    end[axes[1]] += 12.5  # a quarter (or three quarters) away
    cmd = ArcFeed(1, tuple(end), tuple(center), plane, cw, 6000.0)
    samples, _ = run(P, [cmd], tuple(start))
    for s in samples:
        r = math.hypot(s.pose[axes[0]] - center[axes[0]], s.pose[axes[1]] - center[axes[1]])
        assert abs(r - 12.5) <= 1e-12 * 12.5
        assert s.pose[k] == start[k]
    assert samples[-1].pose == tuple(end)
    n = [0.0, 0.0, 0.0]
    n[k] = 1.0

    def turn(p, q):
        u = [p[i] - center[i] for i in range(3)]
        v = [q[i] - center[i] for i in range(3)]
        cr = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]
        return math.atan2(
            sum(c * m for c, m in zip(cr, n, strict=True)),
            sum(x * y for x, y in zip(u, v, strict=True)),
        )

    poses = [tuple(start)] + [x.pose for x in samples]
    swept = sum(turn(a, b) for a, b in zip(poses, poses[1:], strict=False))
    positive = turn(start, end) % (2 * math.pi)  # G3 turns positively about the normal axis
    expected = -(2 * math.pi - positive) if cw else positive
    assert swept == pytest.approx(expected, rel=1e-12)
    assert_within_limits(P, samples, tuple(start))


def test_helix_rises_linearly_with_the_angle():
    start = (-10.0, -20.0, -5.0)
    center = (-20.0, -20.0, -5.0)
    end = (-10.0, -20.0, -8.0)  # two full turns plus one, falling 3 mm
    cmd = ArcFeed(1, end, center, Plane.XY, False, 3000.0, turns=2)
    samples, _ = run(P, [cmd], start)
    total = 0.0
    prev = start
    for s in samples:
        da = math.remainder(
            math.atan2(s.pose[1] - center[1], s.pose[0] - center[0])
            - math.atan2(prev[1] - center[1], prev[0] - center[0]),
            2 * math.pi,
        )
        total += da
        prev = s.pose
        assert abs(math.hypot(s.pose[0] - center[0], s.pose[1] - center[1]) - 10.0) < 1e-12
        assert s.pose[2] - start[2] == pytest.approx(-3.0 * total / (6 * math.pi), abs=1e-12)
    assert total == pytest.approx(6 * math.pi, rel=1e-12)
    assert samples[-1].pose == end
    assert_within_limits(P, samples, start)


def test_line_samples_are_on_the_line():
    samples, _ = run(P, [StraightFeed(1, (-30.0, -40.0, -12.0), 5000.0)])
    n = math.sqrt(30.0**2 + 40.0**2 + 12.0**2)
    u = (-30.0 / n, -40.0 / n, -12.0 / n)
    for s in samples:
        t = sum(a * b for a, b in zip(s.pose, u, strict=True))
        off = [p - t * c for p, c in zip(s.pose, u, strict=True)]
        assert max(abs(x) for x in off) < 1e-13


def trace_bytes(samples) -> bytes:
    return "\n".join(f"{s.t!r},{s.pose!r},{s.velocity!r},{s.line}" for s in samples).encode()


def program():
    cmds = [SetPathMode(1, PathMode.CONTINUOUS, 0.02), StraightTraverse(2, (-5.0, -5.0, 0.0))]
    for i in range(60):
        a = 0.1 * i
        cmds.append(
            StraightFeed(
                3 + i, (-20.0 + 8 * math.cos(a), -20.0 + 8 * math.sin(a), -0.01 * i), 4000.0
            )
        )
    cmds.append(ArcFeed(70, (-30.0, -20.0, -1.0), (-25.0, -20.0, -0.6), Plane.XY, True, 4000.0))
    return cmds


def run_with_events():
    m = Motion(MachineParams(lookahead=25))
    samples = []
    cmds = iter(program())
    pending = next(cmds)
    for k in range(100_000):
        while pending is not None and m.push(pending):
            pending = next(cmds, None)
        if pending is None:
            m.end_of_program()
        if k == 150:
            m.set_feed_override(1.7)
        if k == 400:
            m.feed_hold()
        if k == 700:
            m.resume()
        samples.append(m.step())
        if pending is None and m.idle:
            break
    return samples


def test_same_commands_give_byte_identical_traces():
    a = trace_bytes(run_with_events())
    b = trace_bytes(run_with_events())
    assert a == b
    assert hashlib.sha256(a).hexdigest() == hashlib.sha256(b).hexdigest()


def test_sample_time_is_cycle_count_times_ipo():
    samples = run_with_events()
    assert all(s.t == (i + 1) * 0.002 for i, s in enumerate(samples))


@pytest.mark.parametrize("ipo", [0.0005, 0.001, 0.004, 0.008])
def test_ipo_cycles_from_half_to_eight_ms(ipo):
    params = MachineParams(ipo_cycle_s=ipo)
    samples, _ = run(params, program())
    assert samples[-1].pose == (-30.0, -20.0, -1.0)
    assert_within_limits(params, samples, (0.0, 0.0, 0.0), ipo)
