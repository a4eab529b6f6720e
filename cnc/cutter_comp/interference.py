"""Exact minimum distance between lines and arcs, for the interference (gouge) check.

A compensated element gouges the part when some point of it comes closer than the tool
radius to the programmed contour. The minimum distance between two elements is reached at
an end point of one of them, at a pair of interior points whose connecting line is normal
to both (for a circle: on a line through its centre), or is zero where they cross; each
function below enumerates exactly those candidates.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from cnc.cutter_comp.geometry import Point, dist, dot, left_normal, sub

_TWO_PI = 2.0 * math.pi
_ANG_EPS = 1e-12


@dataclass(frozen=True, slots=True)
class Arc:
    """An arc as centre, radius, start angle and signed sweep (full circle: |sweep| = 2 pi)."""

    center: Point
    radius: float
    a0: float
    sweep: float  # signed: > 0 counter-clockwise
    start: Point
    end: Point

    @staticmethod
    def of(start: Point, end: Point, center: Point, ccw: bool, full: bool) -> Arc:
        radius = dist(start, center)
        a0 = math.atan2(start[1] - center[1], start[0] - center[0])
        if full:
            mag = _TWO_PI
        else:
            a1 = math.atan2(end[1] - center[1], end[0] - center[0])
            mag = ((a1 - a0) if ccw else (a0 - a1)) % _TWO_PI
            if mag == 0.0:
                mag = _TWO_PI
        return Arc(center, radius, a0, mag if ccw else -mag, start, end)

    def contains_angle(self, theta: float) -> bool:
        if abs(self.sweep) >= _TWO_PI - _ANG_EPS:
            return True
        rel = ((theta - self.a0) if self.sweep > 0 else (self.a0 - theta)) % _TWO_PI
        return rel <= abs(self.sweep) + _ANG_EPS or rel >= _TWO_PI - _ANG_EPS

    def contains(self, p: Point) -> bool:
        return self.contains_angle(math.atan2(p[1] - self.center[1], p[0] - self.center[0]))


Element = tuple[Point, Point] | Arc  # a line segment (start, end) or an arc


Box = tuple[float, float, float, float]  # u_min, v_min, u_max, v_max


def bbox(e: Element) -> Box:
    """A box around the element (for arcs: around the whole circle; cheap and safe)."""
    if isinstance(e, Arc):
        (cu, cv), r = e.center, e.radius
        return (cu - r, cv - r, cu + r, cv + r)
    (au, av), (bu, bv) = e
    return (min(au, bu), min(av, bv), max(au, bu), max(av, bv))


def box_gap(p: Box, q: Box) -> float:
    """A lower bound of the distance between anything inside box p and inside box q."""
    gu = max(0.0, p[0] - q[2], q[0] - p[2])
    gv = max(0.0, p[1] - q[3], q[1] - p[3])
    return math.hypot(gu, gv)


def point_segment(p: Point, a: Point, b: Point) -> float:
    ab = sub(b, a)
    den = dot(ab, ab)
    if den == 0.0:
        return dist(p, a)
    t = max(0.0, min(1.0, dot(sub(p, a), ab) / den))
    return math.hypot(p[0] - a[0] - t * ab[0], p[1] - a[1] - t * ab[1])


def point_arc(p: Point, arc: Arc) -> float:
    d = dist(p, arc.center)
    if d > 0.0 and arc.contains(p):
        return abs(d - arc.radius)
    if d == 0.0:
        return arc.radius
    return min(dist(p, arc.start), dist(p, arc.end))


def segment_segment(a: Point, b: Point, c: Point, d: Point) -> float:
    if _segments_cross(a, b, c, d):
        return 0.0
    return min(
        point_segment(a, c, d),
        point_segment(b, c, d),
        point_segment(c, a, b),
        point_segment(d, a, b),
    )


def _orient(a: Point, b: Point, c: Point) -> float:
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])


def _segments_cross(a: Point, b: Point, c: Point, d: Point) -> bool:
    d1, d2 = _orient(c, d, a), _orient(c, d, b)
    d3, d4 = _orient(a, b, c), _orient(a, b, d)
    return ((d1 > 0 > d2) or (d1 < 0 < d2)) and ((d3 > 0 > d4) or (d3 < 0 < d4))


def segment_arc(a: Point, b: Point, arc: Arc) -> float:
    cands = [
        point_arc(a, arc),
        point_arc(b, arc),
        point_segment(arc.start, a, b),
        point_segment(arc.end, a, b),
    ]
    ab = sub(b, a)
    length = math.hypot(*ab)
    if length == 0.0:
        return min(cands)
    u = (ab[0] / length, ab[1] / length)
    n = left_normal(u)
    ca = sub(arc.center, a)
    t = dot(ca, u)  # foot of the centre on the line, from a
    h = dot(ca, n)  # signed distance of the centre from the line
    if 0.0 <= t <= length:
        for sgn in (1.0, -1.0):  # circle points on the normal through the centre
            q = (arc.center[0] + sgn * arc.radius * n[0], arc.center[1] + sgn * arc.radius * n[1])
            if arc.contains(q):
                cands.append(abs(h + sgn * arc.radius))
    if abs(h) <= arc.radius:
        s = math.sqrt(arc.radius * arc.radius - h * h)
        for tt in (t - s, t + s):
            if 0.0 <= tt <= length and arc.contains((a[0] + u[0] * tt, a[1] + u[1] * tt)):
                return 0.0
    return min(cands)


def arc_arc(p: Arc, q: Arc) -> float:
    cands = [
        point_arc(p.start, q),
        point_arc(p.end, q),
        point_arc(q.start, p),
        point_arc(q.end, p),
    ]
    v = sub(q.center, p.center)
    d = math.hypot(*v)
    if d == 0.0:
        if p.contains(q.start) or p.contains(q.end) or q.contains(p.start) or q.contains(p.end):
            cands.append(abs(p.radius - q.radius))
        return min(cands)
    u = (v[0] / d, v[1] / d)
    for sp in (1.0, -1.0):  # pairs of points on the line through both centres
        pp = (p.center[0] + sp * p.radius * u[0], p.center[1] + sp * p.radius * u[1])
        if not p.contains(pp):
            continue
        for sq in (1.0, -1.0):
            qq = (q.center[0] + sq * q.radius * u[0], q.center[1] + sq * q.radius * u[1])
            if q.contains(qq):
                cands.append(dist(pp, qq))
    a = (p.radius * p.radius - q.radius * q.radius + d * d) / (2.0 * d)
    h2 = p.radius * p.radius - a * a
    if h2 >= 0.0:
        h = math.sqrt(h2)
        base = (p.center[0] + u[0] * a, p.center[1] + u[1] * a)
        n = left_normal(u)
        for sgn in (1.0, -1.0):
            x = (base[0] + sgn * h * n[0], base[1] + sgn * h * n[1])
            if p.contains(x) and q.contains(x):
                return 0.0
    return min(cands)


def distance(e: Element, f: Element) -> float:
    """Minimum distance between two elements (line segments or arcs)."""
    if isinstance(e, Arc):
        if isinstance(f, Arc):
            return arc_arc(e, f)
        return segment_arc(f[0], f[1], e)
    if isinstance(f, Arc):
        return segment_arc(e[0], e[1], f)
    return segment_segment(e[0], e[1], f[0], f[1])
