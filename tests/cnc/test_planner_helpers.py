"""Shared helpers for the planner/interpolator tests: run a Motion, check the samples.

The limits are checked under the discrete definition of docs/motion.md: per axis
v_k = (p_k - p_{k-1})/T, a_k = (v_k - v_{k-1})/T, j_k = (a_k - a_{k-1})/T over the IPO
samples, with the samples before the first one equal to the start pose (rest).
"""

from __future__ import annotations

import math
import sys

from cnc.canon import MOTION_TYPES, ArcFeed, StraightFeed, StraightTraverse
from cnc.interpolator import Motion
from cnc.params import MachineParams
from cnc.planner.geometry import Line, arc_from_canon, distance_to_piece
from cnc.planner.limits import AxisLimits

EPS = sys.float_info.epsilon
REL = 1e-9


def run(params: MachineParams, cmds, start=(0.0, 0.0, 0.0), max_cycles=400_000, motion=None):
    """Push everything (respecting space), step to idle, ack syncs. Returns (samples, syncs)."""
    m = motion or Motion(params, start=start)
    samples = []
    syncs = []
    it = iter(cmds)
    pending = next(it, None)
    done_feeding = pending is None
    if done_feeding:
        m.end_of_program()
    for _ in range(max_cycles):
        while pending is not None and m.push(pending):
            pending = next(it, None)
        if pending is None and not done_feeding:
            m.end_of_program()
            done_feeding = True
        s = m.step()
        samples.append(s)
        if s.sync is not None:
            syncs.append((len(samples) - 1, s.sync))
            m.acknowledge()
        if done_feeding and m.idle:
            return samples, syncs
    raise AssertionError("motion did not finish")


def derivatives(samples, start, ipo):
    """Per-axis discrete velocity, acceleration and jerk maxima (abs) and the pose scale."""
    n = len(start)
    p1 = tuple(start)
    v1 = [0.0] * n
    a1 = [0.0] * n
    vmax = [0.0] * n
    amax = [0.0] * n
    jmax = [0.0] * n
    scale = max(abs(x) for x in start) if start else 0.0
    for s in samples:
        p = s.pose
        for i in range(n):
            v = (p[i] - p1[i]) / ipo
            a = (v - v1[i]) / ipo
            j = (a - a1[i]) / ipo
            vmax[i] = max(vmax[i], abs(v))
            amax[i] = max(amax[i], abs(a))
            jmax[i] = max(jmax[i], abs(j))
            v1[i] = v
            a1[i] = a
            scale = max(scale, abs(p[i]))
        p1 = p
    return vmax, amax, jmax, scale


def assert_within_limits(params, samples, start, ipo=None):
    ipo = ipo or params.ipo_cycle_s
    lim = AxisLimits.from_params(params, ipo)
    vmax, amax, jmax, scale = derivatives(samples, start, ipo)
    # rounding floor of the k-th difference of positions of size `scale`
    floor = [2 * EPS * scale / ipo, 4 * EPS * scale / ipo**2, 8 * EPS * scale / ipo**3]
    for i in range(len(start)):
        assert vmax[i] <= lim.vel[i] * (1 + REL) + floor[0], ("vel", i, vmax[i], lim.vel[i])
        assert amax[i] <= lim.acc[i] * (1 + REL) + floor[1], ("acc", i, amax[i], lim.acc[i])
        assert jmax[i] <= lim.jerk[i] * (1 + REL) + floor[2], ("jerk", i, jmax[i], lim.jerk[i])
    return vmax, amax, jmax


def programmed_pieces(cmds, start):
    """The programmed geometry (no blends) of a command list, for deviation checks."""
    pieces = []
    pos = tuple(start)
    for c in cmds:
        if isinstance(c, StraightTraverse | StraightFeed):
            end = tuple(float(x) for x in c.end)
            if end != pos:
                pieces.append(Line(pos, end))
            pos = end
        elif isinstance(c, ArcFeed):
            end = tuple(float(x) for x in c.end)
            pieces.append(arc_from_canon(pos, end, c.center, c.plane.value, c.clockwise, c.turns))
            pos = end
    return pieces


def max_deviation(samples, pieces):
    worst = 0.0
    for s in samples:
        d = min(distance_to_piece(s.pose, g) for g in pieces) if pieces else 0.0
        worst = max(worst, d)
    return worst


def motion_count(cmds):
    return sum(1 for c in cmds if isinstance(c, MOTION_TYPES))


def circle_allowed(params, radius, feed):
    lim = AxisLimits.from_params(params)
    a = min(lim.acc[0], lim.acc[1])
    j = min(lim.jerk[0], lim.jerk[1])
    return min(feed / 60.0, math.sqrt(a * radius), (j * radius * radius) ** (1.0 / 3.0))
