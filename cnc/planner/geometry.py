"""Path pieces in machine coordinates, evaluated in closed form from the path length s.

A `Line` and an `Arc` (circle, helix, or the interpreter's tolerance spiral) are the only
pieces; G64 corner blends are `Arc`s too. `point(s)` is exact at both ends (it returns the
stored end points), so consecutive pieces join without rounding drift and the programmed
end point of a block is reached bit for bit.
"""

from __future__ import annotations

from math import atan2, cos, pi, sin, sqrt, tan

Vec = tuple[float, ...]


def _sub(a: Vec, b: Vec) -> Vec:
    return tuple(x - y for x, y in zip(a, b, strict=True))


def _dot(a: Vec, b: Vec) -> float:
    return sum(x * y for x, y in zip(a, b, strict=True))


def _norm(a: Vec) -> float:
    return sqrt(_dot(a, a))


def _cross3(a: Vec, b: Vec) -> Vec:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


class Line:
    """Straight piece from `start` to `end`."""

    __slots__ = ("start", "end", "u", "length")
    kind = "line"

    def __init__(self, start: Vec, end: Vec) -> None:
        self.start = start
        self.end = end
        d = _sub(end, start)
        n = _norm(d)
        self.length = n
        self.u = tuple(x / n for x in d) if n > 0.0 else tuple(0.0 for _ in d)

    def point(self, s: float) -> Vec:
        if s <= 0.0:
            return self.start
        if s >= self.length:
            return self.end
        return tuple(p + u * s for p, u in zip(self.start, self.u, strict=True))

    def tangent(self, s: float) -> Vec:
        return self.u

    def curvature(self, s: float) -> Vec:
        """Curvature vector d^2P/ds^2 (kappa * normal)."""
        return tuple(0.0 for _ in self.u)

    def with_ends(self, start: Vec, end: Vec) -> Line:
        """The same line shortened (direction kept exactly, so trimming never bends it)."""
        ln = Line.__new__(Line)
        ln.start = start
        ln.end = end
        ln.u = self.u
        ln.length = _norm(_sub(end, start))
        return ln


class Arc:
    """Circle/helix: P(phi) = O + r(phi) (cos phi e1 + sin phi e2) + w * rise * phi / sweep.

    `phi` runs linearly with s from 0 to `sweep`; r(phi) is linear from r0 to r1 (r0 == r1
    for a true circle). The rise is along `w`, the plane's normal axis.
    """

    __slots__ = (
        "start",
        "end",
        "center",
        "e1",
        "e2",
        "w",
        "r0",
        "r1",
        "sweep",
        "rise",
        "length",
    )
    kind = "arc"

    def __init__(
        self,
        start: Vec,
        end: Vec,
        center: Vec,
        e1: Vec,
        e2: Vec,
        w: Vec,
        r0: float,
        r1: float,
        sweep: float,
        rise: float,
    ) -> None:
        self.start = start
        self.end = end
        self.center = center
        self.e1 = e1
        self.e2 = e2
        self.w = w
        self.r0 = r0
        self.r1 = r1
        self.sweep = sweep
        self.rise = rise
        rm = 0.5 * (r0 + r1)
        self.length = sqrt((rm * sweep) ** 2 + rise * rise)

    def point(self, s: float) -> Vec:
        if s <= 0.0:
            return self.start
        if s >= self.length:
            return self.end
        f = s / self.length
        phi = self.sweep * f
        r = self.r0 + (self.r1 - self.r0) * f
        c = r * cos(phi)
        sn = r * sin(phi)
        h = self.rise * f
        return tuple(
            o + c * a + sn * b + h * z
            for o, a, b, z in zip(self.center, self.e1, self.e2, self.w, strict=True)
        )

    def tangent(self, s: float) -> Vec:
        f = s / self.length
        phi = self.sweep * f
        k = self.sweep / self.length
        r = self.r0 + (self.r1 - self.r0) * f
        dr = (self.r1 - self.r0) / self.length
        cp, sp = cos(phi), sin(phi)
        h = self.rise / self.length
        return tuple(
            r * k * (-sp * a + cp * b) + dr * (cp * a + sp * b) + h * z
            for a, b, z in zip(self.e1, self.e2, self.w, strict=True)
        )

    def curvature(self, s: float) -> Vec:
        phi = self.sweep * s / self.length
        k = self.sweep / self.length
        r = self.r0 + (self.r1 - self.r0) * s / self.length
        cp, sp = cos(phi), sin(phi)
        return tuple(-r * k * k * (cp * a + sp * b) for a, b in zip(self.e1, self.e2, strict=True))

    @property
    def plane_fraction(self) -> float:
        """cos of the helix angle: the share of path speed that runs in the arc plane."""
        rm = 0.5 * (self.r0 + self.r1)
        return rm * self.sweep / self.length

    @property
    def rise_fraction(self) -> float:
        return abs(self.rise) / self.length


def arc_from_canon(
    start: Vec, end: Vec, center: Vec, normal_axis: int, clockwise: bool, turns: int
) -> Arc:
    """Build the closed-form arc of a G2/G3 block (plane given by its normal axis index)."""
    n = len(start)
    w = tuple(1.0 if i == normal_axis else 0.0 for i in range(n))
    rel0 = tuple(0.0 if i == normal_axis else start[i] - center[i] for i in range(n))
    rel1 = tuple(0.0 if i == normal_axis else end[i] - center[i] for i in range(n))
    r0 = _norm(rel0)
    r1 = _norm(rel1)
    e1 = tuple(x / r0 for x in rel0)
    e2 = _cross3(w, e1)
    if clockwise:
        e2 = tuple(-x for x in e2)
    ang = atan2(_dot(rel1, e2), _dot(rel1, e1))
    if ang <= 1e-12:
        ang += 2.0 * pi
    sweep = ang + 2.0 * pi * turns
    rise = end[normal_axis] - start[normal_axis]
    c = tuple(center[i] if i != normal_axis else start[i] for i in range(n))
    return Arc(start, end, c, e1, e2, w, r0, r1, sweep, rise)


def blend(
    corner: Vec, u1: Vec, u2: Vec, tolerance: float, avail1: float, avail2: float
) -> tuple[Arc, float] | None:
    """Circular blend of the corner between two lines, deviating at most `tolerance`.

    Returns (arc, d) where d is the length trimmed from each line, or None when the lines
    are collinear (no blend needed) or reverse (no blend possible).
    """
    c = _dot(u1, u2)
    if c > 1.0:
        c = 1.0
    elif c < -1.0:
        c = -1.0
    # turning angle from a well-conditioned formula (acos loses digits near 0)
    diff = _norm(_sub(u2, u1))
    summ = _norm(tuple(a + b for a, b in zip(u1, u2, strict=True)))
    theta = 2.0 * atan2(diff, summ)
    if theta < 1e-12 or theta > pi - 1e-6:
        return None
    d = tolerance / tan(0.25 * theta)
    if d > avail1:
        d = avail1
    if d > avail2:
        d = avail2
    if d <= 1e-12:
        return None
    r = d / tan(0.5 * theta)
    perp = tuple(b - c * a for a, b in zip(u1, u2, strict=True))
    pn = _norm(perp)
    n1 = tuple(x / pn for x in perp)
    start = tuple(p - d * a for p, a in zip(corner, u1, strict=True))
    end = tuple(p + d * b for p, b in zip(corner, u2, strict=True))
    center = tuple(p + r * m for p, m in zip(start, n1, strict=True))
    e1 = tuple(-x for x in n1)
    zero = tuple(0.0 for _ in u1)
    return Arc(start, end, center, e1, u1, zero, r, r, theta, 0.0), d


def distance_to_piece(p: Vec, piece: Line | Arc) -> float:
    """Distance from p to a programmed piece (used by tests and the plan report)."""
    if isinstance(piece, Line):
        d = _sub(p, piece.start)
        t = _dot(d, piece.u)
        t = 0.0 if t < 0.0 else (piece.length if t > piece.length else t)
        q = piece.point(t)
        return _norm(_sub(p, q))
    # arc: project onto the plane, find the angle, compare with the helix at that angle
    rel = _sub(p, piece.center)
    x = _dot(rel, piece.e1)
    y = _dot(rel, piece.e2)
    ang = atan2(y, x)
    if ang < 0.0:
        ang += 2.0 * pi
    best = float("inf")
    sw = piece.sweep
    k = 0
    while True:
        phi = ang + 2.0 * pi * k
        if phi > sw + 2.0 * pi:
            break
        for cand in (phi, 0.0, sw):
            if 0.0 <= cand <= sw:
                q = piece.point(cand / sw * piece.length)
                dd = _norm(_sub(p, q))
                if dd < best:
                    best = dd
        k += 1
    return best
