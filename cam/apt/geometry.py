"""APT canonical geometry and the closed-form constructions of the 2D forms.

APT lines and circles live in the XY plane (a circle is a cylinder along Z, a line a
plane parallel to Z); planes are 3D. Every construction here is closed form (no
iteration) and raises `GeometryError` with the reason when it has no solution; the
evaluator adds file, line and column.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from cam.errors import CamError

EPS = 1e-9  # lengths; APT programs are in inch or mm, both far above this


class GeometryError(CamError, ValueError):
    """A construction without a (unique) solution: the message says why (no position: the
    evaluator says where, as a CamError of its own)."""

    def __init__(self, message: str) -> None:
        super().__init__(message)

    def __str__(self) -> str:
        return self.message


@dataclass(frozen=True, slots=True)
class Point:
    x: float
    y: float
    z: float = 0.0


@dataclass(frozen=True, slots=True)
class Vector:
    i: float
    j: float
    k: float


@dataclass(frozen=True, slots=True)
class Line:
    """A line in XY through (px, py) with unit direction (ux, uy)."""

    px: float
    py: float
    ux: float
    uy: float

    @property
    def normal(self) -> tuple[float, float]:
        """The unit left normal of the direction."""
        return (-self.uy, self.ux)

    def signed_distance(self, x: float, y: float) -> float:
        """Positive on the left of the direction."""
        nx, ny = self.normal
        return (x - self.px) * nx + (y - self.py) * ny

    def foot(self, x: float, y: float) -> tuple[float, float]:
        t = (x - self.px) * self.ux + (y - self.py) * self.uy
        return (self.px + t * self.ux, self.py + t * self.uy)

    def offset(self, d: float) -> Line:
        """The parallel line at signed distance d (positive to the left)."""
        nx, ny = self.normal
        return Line(self.px + d * nx, self.py + d * ny, self.ux, self.uy)

    def same_as(self, other: Line, tol: float = 1e-6) -> bool:
        cross = self.ux * other.uy - self.uy * other.ux
        return abs(cross) < tol and abs(self.signed_distance(other.px, other.py)) < tol


@dataclass(frozen=True, slots=True)
class Circle:
    cx: float
    cy: float
    r: float
    cz: float = 0.0


@dataclass(frozen=True, slots=True)
class Plane:
    """a x + b y + c z = d with (a, b, c) a unit normal."""

    a: float
    b: float
    c: float
    d: float


@dataclass(frozen=True, slots=True)
class Conic:
    """A x^2 + B xy + C y^2 + D x + E y + F = 0 (ELLIPS, HYPERB): a geometric entity for
    definitions; it cannot be a drive or check surface here."""

    kind: str
    coefficients: tuple[float, float, float, float, float, float]


# --- lines -----------------------------------------------------------------------------------


def line_through(x1: float, y1: float, x2: float, y2: float) -> Line:
    dx, dy = x2 - x1, y2 - y1
    n = math.hypot(dx, dy)
    if n < EPS:
        raise GeometryError("the two points of the line coincide (in XY)")
    return Line(x1, y1, dx / n, dy / n)


def line_at_angle(x: float, y: float, deg: float) -> Line:
    a = math.radians(deg)
    return Line(x, y, math.cos(a), math.sin(a))


def intersect_lines(l1: Line, l2: Line) -> tuple[float, float]:
    cross = l1.ux * l2.uy - l1.uy * l2.ux
    if abs(cross) < 1e-12:
        raise GeometryError("the lines are parallel: no intersection")
    dx, dy = l2.px - l1.px, l2.py - l1.py
    t = (dx * l2.uy - dy * l2.ux) / cross
    return (l1.px + t * l1.ux, l1.py + t * l1.uy)


def intersect_line_circle(ln: Line, c: Circle) -> list[tuple[float, float]]:
    fx, fy = ln.foot(c.cx, c.cy)
    h2 = c.r * c.r - ((fx - c.cx) ** 2 + (fy - c.cy) ** 2)
    if h2 < -EPS * max(1.0, c.r):
        return []
    if h2 <= EPS * EPS:
        return [(fx, fy)]
    h = math.sqrt(h2)
    return [(fx - h * ln.ux, fy - h * ln.uy), (fx + h * ln.ux, fy + h * ln.uy)]


def intersect_circles(c1: Circle, c2: Circle) -> list[tuple[float, float]]:
    dx, dy = c2.cx - c1.cx, c2.cy - c1.cy
    d = math.hypot(dx, dy)
    if d < EPS:
        return []
    if d > c1.r + c2.r + EPS or d < abs(c1.r - c2.r) - EPS:
        return []
    a = (c1.r * c1.r - c2.r * c2.r + d * d) / (2 * d)
    h2 = c1.r * c1.r - a * a
    mx, my = c1.cx + a * dx / d, c1.cy + a * dy / d
    if h2 <= EPS * EPS:
        return [(mx, my)]
    h = math.sqrt(h2)
    return [(mx + h * dy / d, my - h * dx / d), (mx - h * dy / d, my + h * dx / d)]


def tangent_lines_two_circles(c1: Circle, c2: Circle, s1: int, s2: int) -> Line:
    """The line touching c1 on side s1 and c2 on side s2 (+1 = LEFT, -1 = RIGHT, as seen
    looking from c1's centre towards c2's), directed from c1 towards c2.

    With n the line's unit left normal and n . p = q the line, a circle touched on its
    LEFT has its centre on the line's right: n . c_i - q = -s_i r_i. Subtracting gives
    n . (c2 - c1) = s1 r1 - s2 r2, so n = cos(a) e + sin(a) e_perp with e the unit
    centre-to-centre vector; sin(a) >= 0 makes the line run from c1 towards c2."""
    dx, dy = c2.cx - c1.cx, c2.cy - c1.cy
    d = math.hypot(dx, dy)
    if d < EPS:
        raise GeometryError("the circles are concentric (or the same circle): no tangent line")
    ex, ey = dx / d, dy / d
    cos_a = (s1 * c1.r - s2 * c2.r) / d
    if abs(cos_a) > 1 + 1e-12:
        raise GeometryError("the circles overlap: this tangent line does not exist")
    cos_a = max(-1.0, min(1.0, cos_a))
    sin_a = math.sqrt(1 - cos_a * cos_a)
    nx, ny = cos_a * ex - sin_a * ey, cos_a * ey + sin_a * ex
    q = nx * c1.cx + ny * c1.cy + s1 * c1.r
    return Line(q * nx, q * ny, ny, -nx)


# --- circles ---------------------------------------------------------------------------------


def circle_three_points(p1: Point, p2: Point, p3: Point) -> Circle:
    ax, ay, bx, by, cx, cy = p1.x, p1.y, p2.x, p2.y, p3.x, p3.y
    d = 2 * (ax * (by - cy) + bx * (cy - ay) + cx * (ay - by))
    scale = max(1.0, abs(ax), abs(ay), abs(bx), abs(by), abs(cx), abs(cy))
    if abs(d) < 1e-12 * scale * scale:
        raise GeometryError("the three points are collinear (or two coincide): no circle")
    a2, b2, c2 = ax * ax + ay * ay, bx * bx + by * by, cx * cx + cy * cy
    ux = (a2 * (by - cy) + b2 * (cy - ay) + c2 * (ay - by)) / d
    uy = (a2 * (cx - bx) + b2 * (ax - cx) + c2 * (bx - ax)) / d
    return Circle(ux, uy, math.hypot(ax - ux, ay - uy))


def circle_centres_through(p1: Point, p2: Point, r: float) -> list[tuple[float, float]]:
    """Both centres of the circles of radius r through p1 and p2."""
    dx, dy = p2.x - p1.x, p2.y - p1.y
    d = math.hypot(dx, dy)
    if d < EPS:
        raise GeometryError("the two points coincide: the circle is not defined")
    if d > 2 * r + EPS:
        raise GeometryError(f"the points are {d:g} apart, more than the diameter {2 * r:g}")
    h = math.sqrt(max(r * r - d * d / 4, 0.0))
    mx, my = (p1.x + p2.x) / 2, (p1.y + p2.y) / 2
    return [(mx - h * dy / d, my + h * dx / d), (mx + h * dy / d, my - h * dx / d)]


def circles_tangent_three_lines(l1: Line, l2: Line, l3: Line) -> list[Circle]:
    """Inscribed and escribed circles of three pairwise non-parallel lines (up to 4)."""
    for a, b in ((l1, l2), (l1, l3), (l2, l3)):
        if abs(a.ux * b.uy - a.uy * b.ux) < 1e-12:
            raise GeometryError("two of the three lines are parallel")
    out: list[Circle] = []
    for s1 in (1, -1):
        for s2 in (1, -1):
            for s3 in (1, -1):
                # n_i . c - s_i r = n_i . p_i  (signed distance of the centre = s_i r)
                rows = []
                for ln, s in ((l1, s1), (l2, s2), (l3, s3)):
                    nx, ny = ln.normal
                    rows.append((nx, ny, -s, nx * ln.px + ny * ln.py))
                sol = _solve3(rows)
                if sol is None or sol[2] <= EPS:
                    continue
                c = Circle(sol[0], sol[1], sol[2])
                if not any(abs(c.cx - o.cx) < 1e-9 and abs(c.cy - o.cy) < 1e-9 for o in out):
                    out.append(c)
    return out


def _solve3(rows: list[tuple[float, float, float, float]]) -> tuple[float, float, float] | None:
    (a1, b1, c1, d1), (a2, b2, c2, d2), (a3, b3, c3, d3) = rows
    det = a1 * (b2 * c3 - b3 * c2) - b1 * (a2 * c3 - a3 * c2) + c1 * (a2 * b3 - a3 * b2)
    if abs(det) < 1e-12:
        return None
    x = (d1 * (b2 * c3 - b3 * c2) - b1 * (d2 * c3 - d3 * c2) + c1 * (d2 * b3 - d3 * b2)) / det
    y = (a1 * (d2 * c3 - d3 * c2) - d1 * (a2 * c3 - a3 * c2) + c1 * (a2 * d3 - a3 * d2)) / det
    z = (a1 * (b2 * d3 - b3 * d2) - b1 * (a2 * d3 - a3 * d2) + d1 * (a2 * b3 - a3 * b2)) / det
    return (x, y, z)


# --- planes ----------------------------------------------------------------------------------


def plane_from_normal(a: float, b: float, c: float, d: float) -> tuple[Plane, float]:
    """The plane a x + b y + c z = d normalised, and |(a, b, c)|."""
    n = math.sqrt(a * a + b * b + c * c)
    if n < EPS:
        raise GeometryError("the plane's normal (A, B, C) is zero")
    return Plane(a / n, b / n, c / n, d / n), n


def plane_three_points(p1: Point, p2: Point, p3: Point) -> Plane:
    ux, uy, uz = p2.x - p1.x, p2.y - p1.y, p2.z - p1.z
    vx, vy, vz = p3.x - p1.x, p3.y - p1.y, p3.z - p1.z
    nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
    n = math.sqrt(nx * nx + ny * ny + nz * nz)
    scale = max(
        1.0, math.sqrt(ux * ux + uy * uy + uz * uz) * math.sqrt(vx * vx + vy * vy + vz * vz)
    )
    if n < 1e-12 * scale:
        raise GeometryError("the three points are collinear (or two coincide): no plane")
    nx, ny, nz = nx / n, ny / n, nz / n
    return Plane(nx, ny, nz, nx * p1.x + ny * p1.y + nz * p1.z)


def plane_z(pl: Plane, x: float, y: float) -> float:
    if abs(pl.c) < 1e-12:
        raise GeometryError("the part surface is vertical: the tool tip cannot rest on it")
    return (pl.d - pl.a * x - pl.b * y) / pl.c


# --- conics ----------------------------------------------------------------------------------


def conic(kind: str, m: float, n: float, a: float, b: float, angle_deg: float) -> Conic:
    """ELLIPS (x'^2/a^2 + y'^2/b^2 = 1) or HYPERB (x'^2/a^2 - y'^2/b^2 = 1) centred at
    (m, n), the x' axis at angle_deg from X. Coefficients scaled so that, unrotated, they
    are the seed's b^2 x^2 +- a^2 y^2 - ... form."""
    if a <= 0 or b <= 0:
        raise GeometryError("the semi-axes of a conic must be > 0")
    sign = 1.0 if kind == "ELLIPS" else -1.0
    # b^2 x'^2 + sign a^2 y'^2 = a^2 b^2, with x' = (x-m)cos + (y-n)sin, y' = -(x-m)sin + (y-n)cos
    t = math.radians(angle_deg)
    ct, st = math.cos(t), math.sin(t)
    p, q = b * b, sign * a * a
    A = p * ct * ct + q * st * st
    B = 2 * (p - q) * ct * st
    C = p * st * st + q * ct * ct
    D = -2 * A * m - B * n
    E = -2 * C * n - B * m
    F = A * m * m + B * m * n + C * n * n - a * a * b * b
    return Conic(kind, tuple(0.0 if abs(v) < 1e-15 else v for v in (A, B, C, D, E, F)))  # type: ignore[arg-type]
