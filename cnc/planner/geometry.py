"""Path pieces in machine coordinates, evaluated in closed form from the path length s.

A `Line` and an `Arc` (circle, helix, or the interpreter's tolerance spiral) are the only
pieces; G64 corner blends are `Arc`s too. `point(s)` is exact at both ends (it returns the
stored end points), so consecutive pieces join without rounding drift and the programmed
end point of a block is reached bit for bit. Poses are (X, Y, Z); the hot path is written
out for three axes with plain floats.

This module is compiled with mypyc (cnc/planner/mypyc.list): the fixed-size
`tuple[float, float, float]` and the typed attributes of the `Piece` classes become native
C values. The source is the reference and must give the same floats when run as Python.
"""

from __future__ import annotations

from collections.abc import Sequence
from math import atan2, cos, pi, sin, sqrt, tan
from math import pow as fpow

from cnc.planner.native import mypyc_attr

Vec3 = tuple[float, float, float]
Vec = tuple[float, ...]
ZERO: Vec3 = (0.0, 0.0, 0.0)  # (a Final tuple of floats is not set up by mypyc)


@mypyc_attr(acyclic=True)
class Piece:
    """What every piece has: end points, length, unit tangents and curvature vectors at both
    ends (t0/t1, k0/k1)."""

    __slots__ = ("start", "end", "length", "t0", "t1", "k0", "k1")

    start: Vec3
    end: Vec3
    length: float
    t0: Vec3
    t1: Vec3
    k0: Vec3
    k1: Vec3

    def __init__(self, start: Vec3, end: Vec3) -> None:
        # Every attribute is set here, in the base class's own __init__: mypyc then knows
        # them always defined. Otherwise it keeps a tuple of floats unboxed with no
        # "defined" flag and takes a first item equal to its float error value (-113.0) for
        # "never set": a line from or to X-113 raised "attribute 'end' of 'Piece'
        # undefined" in the compiled planner.
        self.start = start
        self.end = end
        self.length = 0.0
        self.t0 = self.t1 = self.k0 = self.k1 = ZERO

    def point(self, s: float) -> Vec3:
        raise NotImplementedError

    def tangent(self, s: float) -> Vec3:
        raise NotImplementedError

    def curvature(self, s: float) -> Vec3:
        """Curvature vector d^2P/ds^2 (kappa * normal)."""
        raise NotImplementedError


@mypyc_attr(acyclic=True)
class Line(Piece):
    """Straight piece from `start` to `end` (`u`: the unit direction, given when the line is
    a shortened copy of another, so that trimming never bends it)."""

    __slots__ = ("u",)

    u: Vec3

    def __init__(self, start: Vec3, end: Vec3, u: Vec3 | None = None) -> None:
        Piece.__init__(self, start, end)
        dx = end[0] - start[0]
        dy = end[1] - start[1]
        dz = end[2] - start[2]
        n = sqrt(dx * dx + dy * dy + dz * dz)
        self.length = n
        if u is None:
            u = (dx / n, dy / n, dz / n) if n > 0.0 else (0.0, 0.0, 0.0)
        self.u = self.t0 = self.t1 = u
        self.k0 = self.k1 = (0.0, 0.0, 0.0)

    def point(self, s: float) -> Vec3:
        if s <= 0.0:
            return self.start
        if s >= self.length:
            return self.end
        p0, p1, p2 = self.start
        u0, u1, u2 = self.u
        return (p0 + u0 * s, p1 + u1 * s, p2 + u2 * s)

    def tangent(self, s: float) -> Vec3:
        return self.u

    def curvature(self, s: float) -> Vec3:
        return (0.0, 0.0, 0.0)

    def with_ends(self, start: Vec3, end: Vec3) -> Line:
        """The same line shortened (direction kept exactly, so trimming never bends it)."""
        return Line(start, end, self.u)

    def move_start(self, start: Vec3) -> None:
        """Shorten this line in place to begin at `start` (as `with_ends(start, end)`)."""
        self.start = start
        end = self.end
        dx = end[0] - start[0]
        dy = end[1] - start[1]
        dz = end[2] - start[2]
        self.length = sqrt(dx * dx + dy * dy + dz * dz)


@mypyc_attr(acyclic=True)
class Arc(Piece):
    """Circle/helix: P(phi) = O + r(phi) (cos phi e1 + sin phi e2) + w * rise * phi / sweep.

    `phi` runs linearly with s from 0 to `sweep`; r(phi) is linear from r0 to r1 (r0 == r1
    for a true circle). The rise is along `w`, the plane's normal axis. `t0/t1` and
    `k0/k1` are the unit tangent and the curvature vector at both ends.
    """

    __slots__ = (
        "center",
        "e1",
        "e2",
        "w",
        "r0",
        "r1",
        "sweep",
        "rise",
        "cent",
        "trim",
    )

    center: Vec3
    e1: Vec3
    e2: Vec3
    w: Vec3
    r0: float
    r1: float
    sweep: float
    rise: float
    # per-axis centripetal coefficients (planner.limits.centripetal), once computed
    cent: tuple[Vec3, Vec3] | None
    trim: float  # of a G64 blend: the length trimmed from each of the two lines

    def __init__(
        self,
        start: Vec3,
        end: Vec3,
        center: Vec3,
        e1: Vec3,
        e2: Vec3,
        w: Vec3,
        r0: float,
        r1: float,
        sweep: float,
        rise: float,
    ) -> None:
        Piece.__init__(self, start, end)
        self.center = center
        self.e1 = e1
        self.e2 = e2
        self.w = w
        self.r0 = r0
        self.r1 = r1
        self.sweep = sweep
        self.rise = rise
        self.cent = None
        self.trim = 0.0
        rm = 0.5 * (r0 + r1)
        length = sqrt(fpow(rm * sweep, 2.0) + rise * rise)
        self.length = length
        k = sweep / length
        h = rise / length
        dr = (r1 - r0) / length
        # ends: phi = 0 and phi = sweep
        cp, sp = cos(sweep), sin(sweep)
        a0, a1, a2 = e1
        b0, b1, b2 = e2
        w0, w1, w2 = w
        rk = r0 * k
        self.t0 = (
            rk * b0 + dr * a0 + h * w0,
            rk * b1 + dr * a1 + h * w1,
            rk * b2 + dr * a2 + h * w2,
        )
        rk = r1 * k
        c0, c1, c2 = cp * a0 + sp * b0, cp * a1 + sp * b1, cp * a2 + sp * b2
        d0, d1, d2 = -sp * a0 + cp * b0, -sp * a1 + cp * b1, -sp * a2 + cp * b2
        self.t1 = (
            rk * d0 + dr * c0 + h * w0,
            rk * d1 + dr * c1 + h * w1,
            rk * d2 + dr * c2 + h * w2,
        )
        q = -r0 * k * k
        self.k0 = (q * a0, q * a1, q * a2)
        q = -r1 * k * k
        self.k1 = (q * c0, q * c1, q * c2)

    def point(self, s: float) -> Vec3:
        if s <= 0.0:
            return self.start
        length = self.length
        if s >= length:
            return self.end
        f = s / length
        phi = self.sweep * f
        r = self.r0 + (self.r1 - self.r0) * f
        c = r * cos(phi)
        sn = r * sin(phi)
        h = self.rise * f
        o0, o1, o2 = self.center
        a0, a1, a2 = self.e1
        b0, b1, b2 = self.e2
        z0, z1, z2 = self.w
        return (
            o0 + c * a0 + sn * b0 + h * z0,
            o1 + c * a1 + sn * b1 + h * z1,
            o2 + c * a2 + sn * b2 + h * z2,
        )

    def tangent(self, s: float) -> Vec3:
        f = s / self.length
        phi = self.sweep * f
        k = self.sweep / self.length
        r = self.r0 + (self.r1 - self.r0) * f
        dr = (self.r1 - self.r0) / self.length
        cp, sp = cos(phi), sin(phi)
        h = self.rise / self.length
        a, b, z = self.e1, self.e2, self.w
        return (
            r * k * (-sp * a[0] + cp * b[0]) + dr * (cp * a[0] + sp * b[0]) + h * z[0],
            r * k * (-sp * a[1] + cp * b[1]) + dr * (cp * a[1] + sp * b[1]) + h * z[1],
            r * k * (-sp * a[2] + cp * b[2]) + dr * (cp * a[2] + sp * b[2]) + h * z[2],
        )

    def curvature(self, s: float) -> Vec3:
        phi = self.sweep * s / self.length
        k = self.sweep / self.length
        r = self.r0 + (self.r1 - self.r0) * s / self.length
        cp, sp = cos(phi), sin(phi)
        a, b = self.e1, self.e2
        return (
            -r * k * k * (cp * a[0] + sp * b[0]),
            -r * k * k * (cp * a[1] + sp * b[1]),
            -r * k * k * (cp * a[2] + sp * b[2]),
        )

    @property
    def plane_fraction(self) -> float:
        """cos of the helix angle: the share of path speed that runs in the arc plane."""
        rm = 0.5 * (self.r0 + self.r1)
        return rm * self.sweep / self.length

    @property
    def rise_fraction(self) -> float:
        return abs(self.rise) / self.length


def arc_from_canon(
    start: Sequence[float],
    end: Sequence[float],
    center: Sequence[float],
    normal_axis: int,
    clockwise: bool,
    turns: int,
) -> Arc:
    """Build the closed-form arc of a G2/G3 block (plane given by its normal axis index)."""
    k = normal_axis
    s0, s1, s2 = start
    p0, p1, p2 = end
    m0, m1, m2 = center
    w = (1.0 if k == 0 else 0.0, 1.0 if k == 1 else 0.0, 1.0 if k == 2 else 0.0)
    rel0 = (0.0 if k == 0 else s0 - m0, 0.0 if k == 1 else s1 - m1, 0.0 if k == 2 else s2 - m2)
    rel1 = (0.0 if k == 0 else p0 - m0, 0.0 if k == 1 else p1 - m1, 0.0 if k == 2 else p2 - m2)
    r0 = sqrt(rel0[0] ** 2 + rel0[1] ** 2 + rel0[2] ** 2)
    r1 = sqrt(rel1[0] ** 2 + rel1[1] ** 2 + rel1[2] ** 2)
    e1 = (rel0[0] / r0, rel0[1] / r0, rel0[2] / r0)
    e2 = (w[1] * e1[2] - w[2] * e1[1], w[2] * e1[0] - w[0] * e1[2], w[0] * e1[1] - w[1] * e1[0])
    if clockwise:
        e2 = (-e2[0], -e2[1], -e2[2])
    ang = atan2(
        rel1[0] * e2[0] + rel1[1] * e2[1] + rel1[2] * e2[2],
        rel1[0] * e1[0] + rel1[1] * e1[1] + rel1[2] * e1[2],
    )
    if ang <= 1e-12:
        ang += 2.0 * pi
    sweep = ang + 2.0 * pi * turns
    rise = end[k] - start[k]
    c = (m0 if k != 0 else s0, m1 if k != 1 else s1, m2 if k != 2 else s2)
    return Arc((s0, s1, s2), (p0, p1, p2), c, e1, e2, w, r0, r1, sweep, rise)


def blend_arc(
    corner: Vec3, u1: Vec3, u2: Vec3, tolerance: float, avail1: float, avail2: float
) -> Arc | None:
    """`blend` with the trimmed length in `arc.trim` (no tuple: runs for every corner)."""
    a0, a1, a2 = u1
    b0, b1, b2 = u2
    c = a0 * b0 + a1 * b1 + a2 * b2
    # turning angle from a well-conditioned formula (acos loses digits near 0)
    dx, dy, dz = b0 - a0, b1 - a1, b2 - a2
    sx, sy, sz = b0 + a0, b1 + a1, b2 + a2
    theta = 2.0 * atan2(sqrt(dx * dx + dy * dy + dz * dz), sqrt(sx * sx + sy * sy + sz * sz))
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
    px, py, pz = b0 - c * a0, b1 - c * a1, b2 - c * a2
    pn = sqrt(px * px + py * py + pz * pz)
    n0, n1, n2 = px / pn, py / pn, pz / pn
    x, y, z = corner
    start = (x - d * a0, y - d * a1, z - d * a2)
    end = (x + d * b0, y + d * b1, z + d * b2)
    center = (start[0] + r * n0, start[1] + r * n1, start[2] + r * n2)
    # a planar arc of constant radius (rise 0, r0 == r1): the general formulas then give
    # what the folded-in ones would (x + 0.0 for the zero terms), so one constructor serves
    arc = Arc(start, end, center, (-n0, -n1, -n2), u1, (0.0, 0.0, 0.0), r, r, theta, 0.0)
    arc.trim = d
    return arc


def _dist(a: Vec3, b: Vec3) -> float:
    return sqrt((a[0] - b[0]) ** 2 + (a[1] - b[1]) ** 2 + (a[2] - b[2]) ** 2)


def distance_to_piece(pose: Sequence[float], piece: Piece) -> float:
    """Distance from p to a programmed piece (used by tests and the plan report)."""
    p = (float(pose[0]), float(pose[1]), float(pose[2]))
    if isinstance(piece, Line):
        u = piece.u
        st = piece.start
        t = (p[0] - st[0]) * u[0] + (p[1] - st[1]) * u[1] + (p[2] - st[2]) * u[2]
        t = 0.0 if t < 0.0 else (piece.length if t > piece.length else t)
        return _dist(p, piece.point(t))
    if not isinstance(piece, Arc):
        raise TypeError(f"not a path piece: {piece!r}")
    # arc: the angle of p in the arc plane, then the helix point at that angle (each turn)
    o = piece.center
    rel = (p[0] - o[0], p[1] - o[1], p[2] - o[2])
    e1, e2 = piece.e1, piece.e2
    ang = atan2(
        rel[0] * e2[0] + rel[1] * e2[1] + rel[2] * e2[2],
        rel[0] * e1[0] + rel[1] * e1[1] + rel[2] * e1[2],
    )
    if ang < 0.0:
        ang += 2.0 * pi
    sw = piece.sweep
    best = min(_dist(p, piece.start), _dist(p, piece.end))
    phi = ang
    while phi <= sw:
        d = _dist(p, piece.point(phi / sw * piece.length))
        if d < best:
            best = d
        phi += 2.0 * pi
    return best
