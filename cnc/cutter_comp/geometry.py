"""Plane geometry of cutter radius compensation: offset elements, corners, intersections.

Everything here is pure 2-D arithmetic in the active plane's (u, v) coordinates. The
state machine in `cnc.cutter_comp.compensator` decides *when* a corner is resolved; this
module decides *how*.

Sign convention: `side` is +1 when the tool runs on the left of the programmed contour
(G41 with a positive radius) and -1 on the right. The offset point of a contour point p
with unit tangent t is p + side * r * left_normal(t), left_normal(t) = (-t.v, t.u).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

Point = tuple[float, float]

# --- tolerances (see docs/cutter_comp.md, "Tolerances") --------------------------------
#: Lengths below LEN_TOL_REL * scale count as zero. `scale` is max(1, |radius|, the largest
#: coordinate seen), so the tolerance follows the program's magnitude and units.
LEN_TOL_REL = 1e-9
#: Consecutive programmed segments must join within this relative distance while
#: compensation is on (the interpreter's own arithmetic leaves ~1e-15 gaps; a real gap means
#: a work offset changed under compensation).
CONTINUITY_TOL_REL = 1e-7
#: The interference check refuses a compensated point closer to the programmed contour
#: than r - INTERFERENCE_TOL_REL * scale. Exact contacts (inside-corner trim points, corner
#: arcs, the element's own offset) sit at exactly r up to rounding, far inside this margin.
INTERFERENCE_TOL_REL = 1e-8
#: A lead-out arc (the last element before the cancel move, curving to the tool side) joins
#: the contour tangentially when the tangents differ by less than this (radians): CAM output
#: rounded to 4 decimals of an inch leaves ~4e-4 rad at a small arc.
LEAD_OUT_TANGENT = 1e-2
#: Outside line/line corners turning by less than this (radians) are joined at the
#: intersection of the extended offset lines instead of with a micro-arc. The tool centre
#: then stands off by r*(1/cos(a/2) - 1) <= 1.25e-9 * r beyond the radius.
SHALLOW_ANGLE = 1e-4


def sub(a: Point, b: Point) -> Point:
    return (a[0] - b[0], a[1] - b[1])


def add(a: Point, b: Point) -> Point:
    return (a[0] + b[0], a[1] + b[1])


def mul(a: Point, k: float) -> Point:
    return (a[0] * k, a[1] * k)


def dot(a: Point, b: Point) -> float:
    return a[0] * b[0] + a[1] * b[1]


def cross(a: Point, b: Point) -> float:
    return a[0] * b[1] - a[1] * b[0]


def norm(a: Point) -> float:
    return math.hypot(a[0], a[1])


def dist(a: Point, b: Point) -> float:
    return math.hypot(a[0] - b[0], a[1] - b[1])


def left_normal(t: Point) -> Point:
    return (-t[1], t[0])


@dataclass(slots=True)
class OffsetElement:
    """One programmed line or arc together with its equidistant (offset) curve.

    For a line the offset is the parallel line; for an arc the concentric circle of radius
    `off_radius`. `off_start`/`off_end` are the perpendicular offset points of the programmed
    end points; `ts` is the position (length along the offset curve, from `off_start`) where
    the compensated element begins once its start corner is resolved, `ps` that point.
    """

    kind: str
    p0: Point
    p1: Point
    side: float
    r: float
    # line
    d: Point = (0.0, 0.0)
    length: float = 0.0
    # arc
    center: Point = (0.0, 0.0)
    ccw: bool = True
    radius: float = 0.0
    off_radius: float = 0.0
    a0: float = 0.0
    sweep: float = 0.0  # > 0, radians, in the arc's own direction
    # offset curve
    off_start: Point = (0.0, 0.0)
    off_end: Point = (0.0, 0.0)
    ps: Point = (0.0, 0.0)
    ts: float = 0.0

    @property
    def sigma(self) -> float:
        return 1.0 if self.ccw else -1.0

    @property
    def off_length(self) -> float:
        """Length of the untrimmed offset curve."""
        if self.kind == "line":
            return self.length
        return self.off_radius * self.sweep

    def tangent_start(self) -> Point:
        return self.d if self.kind == "line" else self._arc_tangent(self.p0)

    def tangent_end(self) -> Point:
        return self.d if self.kind == "line" else self._arc_tangent(self.p1)

    def _arc_tangent(self, p: Point) -> Point:
        rv = sub(p, self.center)
        n = norm(rv)
        t = left_normal((rv[0] / n, rv[1] / n))
        return t if self.ccw else (-t[0], -t[1])

    def param(self, x: Point, near_end: bool, tol: float) -> float:
        """Position of `x` (a point on the offset curve) measured along it from off_start.

        On a line the position may fall outside [0, off_length] (an extended or reversed
        element). On an arc a trim point is read as lying *inside* the element: walking
        backwards from the end (near_end) or forwards from the start by 0..2 pi, so a trim
        of more than the sweep shows as a reversed element instead of wrapping round the
        circle. Within `tol` of the end point itself counts as no trim at all.
        """
        if self.kind == "line":
            return dot(sub(x, self.off_start), self.d)
        ang = math.atan2(x[1] - self.center[1], x[0] - self.center[0])
        two_pi = 2.0 * math.pi
        if near_end:
            a1 = self.a0 + self.sigma * self.sweep
            back = (self.sigma * (a1 - ang)) % two_pi
            if (two_pi - back) * self.off_radius <= tol:
                back = 0.0
            return self.off_radius * (self.sweep - back)
        fwd = (self.sigma * (ang - self.a0)) % two_pi
        if (two_pi - fwd) * self.off_radius <= tol:
            fwd = 0.0
        return self.off_radius * fwd


def make_line(p0: Point, p1: Point, side: float, r: float) -> OffsetElement:
    v = sub(p1, p0)
    length = norm(v)
    d = (v[0] / length, v[1] / length)
    n = mul(left_normal(d), side * r)
    e = OffsetElement("line", p0, p1, side, r, d=d, length=length)
    e.off_start = add(p0, n)
    e.off_end = add(p1, n)
    e.ps = e.off_start
    return e


def make_arc(
    p0: Point, p1: Point, center: Point, ccw: bool, side: float, r: float, full: bool
) -> OffsetElement:
    """Offset arc; the caller has checked that the offset radius stays positive."""
    r0 = dist(p0, center)
    r1 = dist(p1, center)
    radius = 0.5 * (r0 + r1)
    sigma = 1.0 if ccw else -1.0
    a0 = math.atan2(p0[1] - center[1], p0[0] - center[0])
    a1 = math.atan2(p1[1] - center[1], p1[0] - center[0])
    if full:
        sweep = 2.0 * math.pi
    else:
        sweep = (sigma * (a1 - a0)) % (2.0 * math.pi)
        if sweep <= 0.0:
            sweep = 2.0 * math.pi
    # The left normal of a ccw arc points at the centre: left side of ccw = inside.
    off_radius = radius - side * sigma * r
    e = OffsetElement(
        "arc",
        p0,
        p1,
        side,
        r,
        center=center,
        ccw=ccw,
        radius=radius,
        off_radius=off_radius,
        a0=a0,
        sweep=sweep,
    )
    e.off_start = on_circle(center, off_radius, p0)
    e.off_end = e.off_start if full else on_circle(center, off_radius, p1)
    e.ps = e.off_start
    return e


def on_circle(center: Point, radius: float, towards: Point) -> Point:
    """The point of the circle (center, radius) on the ray from the centre through `towards`."""
    v = sub(towards, center)
    n = norm(v)
    return (center[0] + v[0] * radius / n, center[1] + v[1] * radius / n)


def intersect_offsets(a: OffsetElement, b: OffsetElement, near: Point) -> Point | None:
    """Intersection of the two (unbounded) offset curves closest to `near`, or None."""
    if a.kind == "line" and b.kind == "line":
        pts = _line_line(a.off_start, a.d, b.off_start, b.d)
    elif a.kind == "line":
        pts = _line_circle(a.off_start, a.d, b.center, b.off_radius)
    elif b.kind == "line":
        pts = _line_circle(b.off_start, b.d, a.center, a.off_radius)
    else:
        pts = _circle_circle(a.center, a.off_radius, b.center, b.off_radius)
    if not pts:
        return None
    return min(pts, key=lambda p: dist(p, near))


def _line_line(p: Point, d1: Point, q: Point, d2: Point) -> list[Point]:
    c = cross(d1, d2)
    if c == 0.0:
        return []
    t = cross(sub(q, p), d2) / c
    return [add(p, mul(d1, t))]


def _line_circle(p: Point, d: Point, c: Point, radius: float) -> list[Point]:
    w = sub(p, c)
    b = dot(w, d)
    foot = sub(p, mul(d, b))  # closest point of the line to the centre
    h2 = radius * radius - dot(sub(foot, c), sub(foot, c))
    if h2 < 0.0:
        # Grazing within rounding: treat as touching so near-tangent corners still resolve.
        if h2 < -2.0 * radius * LEN_TOL_REL * max(1.0, radius):
            return []
        h2 = 0.0
    h = math.sqrt(h2)
    return [add(foot, mul(d, h)), sub(foot, mul(d, h))]


def _circle_circle(c1: Point, r1: float, c2: Point, r2: float) -> list[Point]:
    v = sub(c2, c1)
    d = norm(v)
    if d == 0.0:
        return []
    a = (r1 * r1 - r2 * r2 + d * d) / (2.0 * d)
    h2 = r1 * r1 - a * a
    if h2 < 0.0:
        if h2 < -2.0 * max(r1, r2) * LEN_TOL_REL * max(1.0, r1, r2):
            return []
        h2 = 0.0
    h = math.sqrt(h2)
    u = (v[0] / d, v[1] / d)
    base = add(c1, mul(u, a))
    off = mul(left_normal(u), h)
    return [add(base, off), sub(base, off)]


def turn_angle(t_in: Point, t_out: Point) -> float:
    """Unsigned angle (0..pi) the direction turns through at a junction."""
    return math.atan2(abs(cross(t_in, t_out)), dot(t_in, t_out))
