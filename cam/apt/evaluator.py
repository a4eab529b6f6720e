"""APT evaluator: statements -> CL records (the processor of 000_nc_book.md §11.3).

Geometry is evaluated when it is defined (a name must be defined before it is used);
motion statements produce tool-tip locations: point-to-point (FROM, GOTO, GODLTA) as
given, continuous path (GO, GOLFT, GORGT, GOFWD, GOBACK, GOUP, GODOWN) as the tool-centre
path offset from the drive surface by the cutter radius, with every tangent and
intersection point in closed form. Post-processor statements pass through as CL records.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

from cam.apt import geometry as g
from cam.apt.geometry import Circle, Conic, GeometryError, Line, Plane, Point, Vector
from cam.apt.lexer import Token
from cam.apt.parser import GEOMETRY, BinOp, Call, Definition, Minor, Neg, Num, Ref, Statement, parse
from cam.cl import ClRecord
from cam.errors import CamError, CamWarning, WarningSink, ignore_warning

MODS_XY = ("XLARGE", "XSMALL", "YLARGE", "YSMALL")
MODS_XYZ = (*MODS_XY, "ZLARGE", "ZSMALL")
TOOL_SIDES = ("TLLFT", "TLRGT", "TLON")
H_DEFAULT_INCH = 5.0
PLANE_COSINE_WARN = 0.01  # |n| this close to 1 but not 1: inexact direction cosines
ON_TOLERANCE = 1e-6  # relative: the tool is "on" its offset drive surface


def _scale(*v: float) -> float:
    return 1.0 + max(abs(x) for x in v)


@dataclass(slots=True)
class _Arg:
    value: object  # float | Point | Line | Circle | Plane | Vector | Conic | str (minor)
    tok: Token

    @property
    def sig(self) -> str:
        v = self.value
        if isinstance(v, str):
            return v
        return {
            float: "n",
            Point: "P",
            Line: "L",
            Circle: "C",
            Plane: "PL",
            Vector: "V",
            Conic: "K",
        }[type(v)]


def _kind_name(v: object) -> str:
    if isinstance(v, float):
        return "a number"
    return {Point: "a POINT", Line: "a LINE", Circle: "a CIRCLE", Plane: "a PLANE",
            Vector: "a VECTOR", Conic: "a conic"}.get(type(v), "a value")  # fmt: skip


class Processor:
    """Evaluate one APT program; `run()` yields its CL records."""

    def __init__(self, text: str, file: str = "<apt>", warn: WarningSink = ignore_warning):
        self.text = text
        self.file = file
        self.warn = warn
        self.env: dict[str, object] = {}
        self.zsurf = 0.0
        self.units = "INCHES"
        self.moved = False
        self.pos: tuple[float, float, float] | None = None
        self.direction: tuple[float, float] | None = None  # forward, XY, unit
        self.tool_axis = (0.0, 0.0, 1.0)
        self.multax = False
        self.cutter_radius: float | None = None
        self.tool_side = "TLON"
        self.part_surface: Plane | None = None
        self.finished = False

    # --- errors -----------------------------------------------------------------------------

    def err(self, msg: str, tok: Token) -> CamError:
        return CamError(msg, tok.line, tok.col, self.file)

    # --- values -----------------------------------------------------------------------------

    def value(self, node: object) -> object:
        if isinstance(node, Num):
            return node.value
        if isinstance(node, Ref):
            try:
                return self.env[node.name]
            except KeyError:
                raise self.err(
                    f"undefined name {node.name!r} (define it before use)", node.tok
                ) from None
        if isinstance(node, Neg):
            return -self.number(node.operand)
        if isinstance(node, BinOp):
            a, b = self.number(node.left), self.number(node.right)
            try:
                if node.op == "+":
                    return a + b
                if node.op == "-":
                    return a - b
                if node.op == "*":
                    return a * b
                if node.op == "/":
                    if b == 0:
                        raise self.err("division by zero", node.tok)
                    return a / b
                r = a**b
                if isinstance(r, complex) or not math.isfinite(r):
                    raise self.err(f"{a:g} ** {b:g} is not a real number", node.tok)
                return float(r)
            except OverflowError:
                raise self.err("number too large", node.tok) from None
        if isinstance(node, Call):
            return self.call(node)
        if isinstance(node, Definition):
            return self.define(node)
        if isinstance(node, Minor):
            raise self.err(f"{node.word} is a modifier, not a value", node.tok)
        raise AssertionError(node)

    def number(self, node: object) -> float:
        v = self.value(node)
        if not isinstance(v, float):
            raise self.err(f"expected a number, got {_kind_name(v)}", _tok_of(node))
        return v

    def call(self, node: Call) -> float:
        xs = [self.number(a) for a in node.args]
        f = node.func
        arity = {"ATAN2F": 2, "MAXF": 2, "MINF": 2}.get(f, 1)
        if f in ("DOTF", "DISTF"):
            raise self.err(f"{f} is not supported", node.tok)
        if len(xs) != arity:
            raise self.err(f"{f} takes {arity} argument(s), got {len(xs)}", node.tok)
        x = xs[0]
        try:
            r = {
                "SQRTF": lambda: math.sqrt(x),
                "SINF": lambda: math.sin(math.radians(x)),
                "COSF": lambda: math.cos(math.radians(x)),
                "TANF": lambda: math.tan(math.radians(x)),
                "ASINF": lambda: math.degrees(math.asin(x)),
                "ACOSF": lambda: math.degrees(math.acos(x)),
                "ATANF": lambda: math.degrees(math.atan(x)),
                "ATAN2F": lambda: math.degrees(math.atan2(xs[0], xs[1])),
                "ABSF": lambda: abs(x),
                "EXPF": lambda: math.exp(x),
                "LOGF": lambda: math.log(x),
                "INTF": lambda: float(math.trunc(x)),
                "SIGNF": lambda: math.copysign(1.0, x),
                "MAXF": lambda: max(xs),
                "MINF": lambda: min(xs),
            }[f]()
        except (ValueError, OverflowError) as e:
            raise self.err(f"{f}({', '.join(f'{v:g}' for v in xs)}): {e}", node.tok) from None
        return float(r)

    def args(self, nodes: list) -> list[_Arg]:
        out = []
        for n in nodes:
            if isinstance(n, Minor):
                out.append(_Arg(n.word, n.tok))
            else:
                v = self.value(n)
                out.append(_Arg(v, _tok_of(n)))
        return out

    # --- geometry definitions ---------------------------------------------------------------

    def define(self, d: Definition) -> object:
        if d.major == "MACRO":
            raise self.err("MACRO is not supported by this processor (no macros or loops)", d.tok)
        args = self.args(d.args)
        sig = tuple(a.sig for a in args)
        fn = {
            "POINT": self.point,
            "LINE": self.line,
            "CIRCLE": self.circle,
            "CIRCL": self.circle,
            "PLANE": self.plane,
            "VECTOR": self.vector,
            "ELLIPS": self.conic,
            "ELIPS": self.conic,
            "HYPERB": self.conic,
        }.get(d.major)
        if fn is None:
            raise self.err(f"{d.major} surfaces are not supported by this processor", d.tok)
        try:
            return fn(d, args, sig)
        except GeometryError as e:
            raise self.err(f"{d.major}: {e}", d.tok) from None

    def _no_form(self, d: Definition, sig: tuple[str, ...]) -> CamError:
        return self.err(
            f"{d.major}/{','.join(sig)}: not a {d.major} form this processor knows", d.tok
        )

    def _pick(self, cands: list[tuple[float, float]], mod: _Arg) -> tuple[float, float]:
        """Pick by XLARGE/XSMALL/YLARGE/YSMALL among candidate points."""
        if mod.value not in MODS_XY:
            raise self.err(f"expected XLARGE, XSMALL, YLARGE or YSMALL, not {mod.value}", mod.tok)
        if len(cands) == 1:
            return cands[0]
        axis = 0 if mod.value[0] == "X" else 1
        vals = [c[axis] for c in cands]
        if max(vals) - min(vals) < 1e-9 * _scale(*vals):
            raise self.err(
                f"ambiguous modifier {mod.value}: the candidates have the same {mod.value[0]}",
                mod.tok,
            )
        best = max if mod.value.endswith("LARGE") else min
        chosen = best(cands, key=lambda c: c[axis])
        if sum(1 for c in cands if abs(c[axis] - chosen[axis]) < 1e-9 * _scale(*vals)) > 1:
            raise self.err(f"ambiguous modifier {mod.value}: several candidates tie", mod.tok)
        return chosen

    def _side(self, ln: Line, mod: _Arg) -> int:
        """+1 when the modifier names the left side of the line's direction, -1 the right:
        XLARGE means the larger-X side (as the seed's fillet and PARLEL modifiers)."""
        if mod.value not in MODS_XY:
            raise self.err(f"expected XLARGE, XSMALL, YLARGE or YSMALL, not {mod.value}", mod.tok)
        nx, ny = ln.normal
        comp = nx if mod.value[0] == "X" else ny
        if abs(comp) < 1e-9:
            raise self.err(
                f"ambiguous modifier {mod.value}: the line is parallel to the"
                f" {mod.value[0]} axis, so both sides have the same {mod.value[0]}",
                mod.tok,
            )
        s = 1 if comp > 0 else -1
        return s if mod.value.endswith("LARGE") else -s

    def point(self, d: Definition, a: list[_Arg], sig: tuple[str, ...]) -> Point:
        v = [x.value for x in a]
        if sig in (("n", "n"), ("n", "n", "n")):
            return Point(v[0], v[1], v[2] if len(v) == 3 else self.zsurf)  # type: ignore[arg-type]
        if sig[:2] == ("P", "DELTA") and all(s == "n" for s in sig[2:]) and len(sig) in (4, 5):
            p = v[0]
            dz = v[4] if len(v) == 5 else 0.0
            return Point(p.x + v[2], p.y + v[3], p.z + dz)  # type: ignore[union-attr,operator]
        if sig[0] == "RTHETA":
            sig, v, a = sig[1:], v[1:], a[1:]
        if len(sig) == 3 and sig[0] in ("XYPLAN", "YZPLAN", "ZXPLAN") and sig[1:] == ("n", "n"):
            r, t = v[1], math.radians(v[2])  # type: ignore[arg-type]
            c, s = r * math.cos(t), r * math.sin(t)
            if sig[0] == "XYPLAN":
                return Point(c, s, self.zsurf)
            if sig[0] == "YZPLAN":  # the angle from Y+
                return Point(0.0, c, s)
            return Point(c, 0.0, s)  # ZXPLAN: the angle from X+
        if sig == ("P", "RADIUS", "n", "ATANGL", "n"):
            p, r, t = v[0], v[2], math.radians(v[4])  # type: ignore[arg-type]
            return Point(p.x + r * math.cos(t), p.y + r * math.sin(t), p.z)  # type: ignore[union-attr]
        if sig == ("CENTER", "C"):
            c = v[1]
            return Point(c.cx, c.cy, c.cz)  # type: ignore[union-attr]
        if sig == ("C", "ATANGL", "n"):
            c, t = v[0], math.radians(v[2])  # type: ignore[arg-type]
            return Point(c.cx + c.r * math.cos(t), c.cy + c.r * math.sin(t), c.cz)  # type: ignore[union-attr]
        if (
            len(sig) == 7
            and sig[:3] == ("P", "DELTA", sig[2])
            and sig[2] in ("CLW", "CCLW")
            and sig[3:6] == ("ON", "C", "ATANGL")
            and sig[6] == "n"
        ):
            p, c, t = v[0], v[4], v[6]
            start = math.atan2(p.y - c.cy, p.x - c.cx)  # type: ignore[union-attr]
            if math.hypot(p.x - c.cx, p.y - c.cy) < g.EPS:  # type: ignore[union-attr]
                raise GeometryError("the reference point is the circle's centre: no angle")
            ang = start + math.radians(t) * (1 if sig[2] == "CCLW" else -1)  # type: ignore[arg-type]
            return Point(c.cx + c.r * math.cos(ang), c.cy + c.r * math.sin(ang), p.z)  # type: ignore[union-attr]
        if sig == ("INTOF", "L", "L"):
            x, y = g.intersect_lines(v[1], v[2])  # type: ignore[arg-type]
            return Point(x, y, self.zsurf)
        mod = None
        if sig and sig[0] in MODS_XY:
            mod, sig, v = a[0], sig[1:], v[1:]
        if sig in (("INTOF", "L", "C"), ("INTOF", "C", "L"), ("INTOF", "C", "C")):
            if sig[1] == "C" and sig[2] == "C":
                cands = g.intersect_circles(v[1], v[2])  # type: ignore[arg-type]
            else:
                ln, c = (v[1], v[2]) if sig[1] == "L" else (v[2], v[1])
                cands = g.intersect_line_circle(ln, c)  # type: ignore[arg-type]
            if not cands:
                raise GeometryError("the curves do not intersect")
            if len(cands) == 2 and mod is None:
                raise self.err(
                    "two intersection points: give XLARGE, XSMALL, YLARGE or YSMALL", d.tok
                )
            x, y = cands[0] if mod is None else self._pick(cands, mod)
            return Point(x, y, self.zsurf)
        raise self._no_form(d, tuple(x.sig for x in a))

    def line(self, d: Definition, a: list[_Arg], sig: tuple[str, ...]) -> Line:
        v = [x.value for x in a]
        if sig == ("P", "P"):
            return g.line_through(v[0].x, v[0].y, v[1].x, v[1].y)  # type: ignore[union-attr]
        if sig == ("n",) * 4:
            return g.line_through(*v)  # type: ignore[arg-type]
        if sig == ("n",) * 6:
            return g.line_through(v[0], v[1], v[3], v[4])  # type: ignore[arg-type]
        if sig in (("XAXIS",), ("XAXIS", "n")):
            return Line(0.0, v[1] if len(v) == 2 else 0.0, 1.0, 0.0)  # type: ignore[arg-type]
        if sig in (("YAXIS",), ("YAXIS", "n")):
            return Line(v[1] if len(v) == 2 else 0.0, 0.0, 0.0, 1.0)  # type: ignore[arg-type]
        if sig in (("P", "ATANGL", "n"), ("P", "ATANGL", "n", "L"), ("P", "ATANGL", "n", "XAXIS")):
            base = 0.0
            if sig[-1] == "L":
                base = math.degrees(math.atan2(v[3].uy, v[3].ux))  # type: ignore[union-attr]
            return g.line_at_angle(v[0].x, v[0].y, base + v[2])  # type: ignore[union-attr,operator]
        if sig == ("P", "PARLEL", "L"):
            return Line(v[0].x, v[0].y, v[2].ux, v[2].uy)  # type: ignore[union-attr]
        if sig == ("P", "PERPTO", "L"):
            return Line(v[0].x, v[0].y, -v[2].uy, v[2].ux)  # type: ignore[union-attr]
        if sig[:2] == ("PARLEL", "L") and len(sig) == 4 and sig[3] == "n":
            ln = v[1]
            return ln.offset(self._side(ln, a[2]) * abs(v[3]))  # type: ignore[union-attr,arg-type]
        if len(sig) in (5, 6) and sig[0] == "ATANGL" and sig[1] == "n":
            rest = sig[2:]
            base = 0.0
            if rest[0] == "L":
                base = math.degrees(math.atan2(v[2].uy, v[2].ux))  # type: ignore[union-attr]
                rest, off = rest[1:], 3
            else:
                off = 2
            if rest[:2] == ("TANTO", "C") and len(rest) == 3 and rest[2] in MODS_XY:
                c = v[off + 1]
                t = math.radians(base + v[1])  # type: ignore[operator]
                ux, uy = math.cos(t), math.sin(t)
                nx, ny = -uy, ux
                cands = [(c.cx + s * c.r * nx, c.cy + s * c.r * ny) for s in (1, -1)]  # type: ignore[union-attr]
                tx, ty = self._pick(cands, a[off + 2])
                return Line(tx, ty, ux, uy)
        if (
            len(sig) == 6
            and sig[0] in ("LEFT", "RIGHT")
            and sig[3] in ("LEFT", "RIGHT")
            and sig[1:3] == ("TANTO", "C")
            and sig[4:] == ("TANTO", "C")
        ):
            s1 = 1 if sig[0] == "LEFT" else -1
            s2 = 1 if sig[3] == "LEFT" else -1
            return g.tangent_lines_two_circles(v[2], v[5], s1, s2)  # type: ignore[arg-type]
        if (
            len(sig) == 4
            and sig[0] == "P"
            and sig[1] in ("LEFT", "RIGHT")
            and sig[2:] == ("TANTO", "C")
        ):
            p, c = v[0], v[3]
            dx, dy = c.cx - p.x, c.cy - p.y  # type: ignore[union-attr]
            dist = math.hypot(dx, dy)
            if dist <= c.r + g.EPS:  # type: ignore[union-attr]
                raise GeometryError("the point is not outside the circle: no tangent through it")
            beta = math.asin(c.r / dist) * (1 if sig[1] == "LEFT" else -1)  # type: ignore[union-attr]
            base = math.atan2(dy, dx) + beta
            return Line(p.x, p.y, math.cos(base), math.sin(base))  # type: ignore[union-attr]
        raise self._no_form(d, sig)

    def circle(self, d: Definition, a: list[_Arg], sig: tuple[str, ...]) -> Circle:
        v = [x.value for x in a]
        z = self.zsurf

        def radius(r: float, at: _Arg) -> float:
            if not r > 0:
                raise self.err(f"the radius must be > 0, got {r:g}", at.tok)
            return r

        if sig == ("n", "n", "n"):
            return Circle(v[0], v[1], radius(v[2], a[2]), z)  # type: ignore[arg-type]
        if sig == ("n", "n", "n", "n"):
            return Circle(v[0], v[1], radius(v[3], a[3]), v[2])  # type: ignore[arg-type]
        if sig == ("CENTER", "P", "RADIUS", "n"):
            p = v[1]
            return Circle(p.x, p.y, radius(v[3], a[3]), p.z)  # type: ignore[union-attr,arg-type]
        if sig == ("P", "P", "P"):
            c = g.circle_three_points(v[0], v[1], v[2])  # type: ignore[arg-type]
            return Circle(c.cx, c.cy, c.r, v[0].z)  # type: ignore[union-attr]
        if sig == ("CENTER", "P", "P"):
            p, q = v[1], v[2]
            r = math.hypot(q.x - p.x, q.y - p.y)  # type: ignore[union-attr]
            if r < g.EPS:
                raise GeometryError("the point on the circle is its centre: radius 0")
            return Circle(p.x, p.y, r, p.z)  # type: ignore[union-attr]
        if sig == ("CENTER", "P", "TANTO", "L"):
            p, ln = v[1], v[3]
            r = abs(ln.signed_distance(p.x, p.y))  # type: ignore[union-attr]
            if r < g.EPS:
                raise GeometryError("the centre lies on the line: radius 0")
            return Circle(p.x, p.y, r, p.z)  # type: ignore[union-attr]
        if (
            len(sig) == 5
            and sig[:2] == ("CENTER", "P")
            and sig[2] in ("LARGE", "SMALL")
            and sig[3:] == ("TANTO", "C")
        ):
            p, c = v[1], v[4]
            dist = math.hypot(p.x - c.cx, p.y - c.cy)  # type: ignore[union-attr]
            r = dist + c.r if sig[2] == "LARGE" else abs(dist - c.r)  # type: ignore[union-attr]
            if r < g.EPS:
                raise GeometryError(
                    "the centre lies on the given circle: the SMALL circle has radius 0"
                )
            return Circle(p.x, p.y, r, p.z)  # type: ignore[union-attr]
        if len(sig) == 5 and sig[0] in MODS_XY and sig[1:] == ("P", "P", "RADIUS", "n"):
            r = radius(v[4], a[4])  # type: ignore[arg-type]
            cands = g.circle_centres_through(v[1], v[2], r)  # type: ignore[arg-type]
            x, y = self._pick(cands, a[0])
            return Circle(x, y, r, z)
        if (
            len(sig) == 6
            and sig[0] in MODS_XY
            and sig[2] in MODS_XY
            and sig[1] == "L"
            and sig[3] == "L"
            and sig[4:] == ("RADIUS", "n")
        ):
            l1, l2 = v[1], v[3]
            r = radius(v[5], a[5])  # type: ignore[arg-type]
            s1, s2 = self._side(l1, a[0]), self._side(l2, a[2])  # type: ignore[arg-type]
            x, y = g.intersect_lines(l1.offset(s1 * r), l2.offset(s2 * r))  # type: ignore[union-attr]
            return Circle(x, y, r, z)
        if (
            sig[-5:] == ("TANTO", "L", "THRU", "P", "RADIUS", "n")[-5:]
            and len(sig) in (6, 7)
            and sig[-6:] == ("TANTO", "L", "THRU", "P", "RADIUS", "n")
        ):
            mod = a[0] if len(sig) == 7 else None
            if mod is not None and mod.value not in MODS_XY:
                raise self._no_form(d, sig)
            off = 1 if mod is None else 2
            ln, p = v[off], v[off + 2]
            r = radius(v[off + 4], a[off + 4])  # type: ignore[arg-type]
            sd = ln.signed_distance(p.x, p.y)  # type: ignore[union-attr]
            if abs(sd) > 2 * r + g.EPS:
                raise GeometryError(
                    f"the point is {abs(sd):g} from the line, more than the diameter {2 * r:g}"
                )
            sides = (1, -1) if abs(sd) < g.EPS else ((1,) if sd > 0 else (-1,))
            cands: list[tuple[float, float]] = []
            for s in sides:
                cands += g.intersect_line_circle(ln.offset(s * r), Circle(p.x, p.y, r))  # type: ignore[union-attr]
            if not cands:
                raise GeometryError(
                    "no circle of that radius is tangent to the line through the point"
                )
            if len(cands) > 1 and mod is None:
                raise self.err("two circles fit: give XLARGE, XSMALL, YLARGE or YSMALL", d.tok)
            x, y = cands[0] if mod is None else self._pick(cands, mod)
            return Circle(x, y, r, z)
        if (
            len(sig) == 6
            and all(sig[i] in MODS_XY for i in (0, 2, 4))
            and all(sig[i] == "L" for i in (1, 3, 5))
        ):
            lines = [v[1], v[3], v[5]]
            sides = [self._side(ln, a[i]) for ln, i in zip(lines, (0, 2, 4), strict=True)]  # type: ignore[arg-type]
            for c in g.circles_tangent_three_lines(*lines):  # type: ignore[arg-type]
                if all(
                    (ln.signed_distance(c.cx, c.cy) > 0) == (s > 0)  # type: ignore[union-attr]
                    for ln, s in zip(lines, sides, strict=True)
                ):
                    return Circle(c.cx, c.cy, c.r, z)
            raise GeometryError(
                "no circle tangent to the three lines on the sides the modifiers give"
            )
        if (
            len(sig) == 7
            and sig[0] in MODS_XY
            and sig[1] == "L"
            and sig[2] in MODS_XY
            and sig[3] in ("IN", "OUT")
            and sig[4:] == ("C", "RADIUS", "n")
        ):
            ln, c = v[1], v[4]
            r = radius(v[6], a[6])  # type: ignore[arg-type]
            s = self._side(ln, a[0])  # type: ignore[arg-type]
            rr = c.r - r if sig[3] == "IN" else c.r + r  # type: ignore[union-attr]
            if rr <= g.EPS:
                raise GeometryError(f"radius {r:g} does not fit IN a circle of radius {c.r:g}")  # type: ignore[union-attr]
            cands = g.intersect_line_circle(ln.offset(s * r), Circle(c.cx, c.cy, rr))  # type: ignore[union-attr]
            if not cands:
                raise GeometryError(
                    "no circle of that radius touches the line and the circle on those sides"
                )
            x, y = self._pick(cands, a[2])
            return Circle(x, y, r, z)
        raise self._no_form(d, sig)

    def plane(self, d: Definition, a: list[_Arg], sig: tuple[str, ...]) -> Plane:
        v = [x.value for x in a]
        if sig == ("n",) * 4:
            pl, n = g.plane_from_normal(*v)  # type: ignore[arg-type]
            if 1e-6 < abs(n - 1.0) <= PLANE_COSINE_WARN:
                self.warn(
                    CamWarning(
                        f"PLANE: the direction cosines are not a unit vector (|n| = {n:.6g});"
                        f" normalised: the plane is {pl.a:.6g} x + {pl.b:.6g} y + {pl.c:.6g} z"
                        f" = {pl.d:.6g}",
                        d.tok.line,
                        d.tok.col,
                        self.file,
                    )
                )
            return pl
        if sig == ("P", "P", "P"):
            return g.plane_three_points(*v)  # type: ignore[arg-type]
        if sig == ("P", "PARLEL", "PL") or sig in (
            ("P", "PARLEL", p) for p in ("XYPLAN", "YZPLAN", "ZXPLAN")
        ):
            pl = self._as_plane(a[2])
            p = v[0]
            return Plane(pl.a, pl.b, pl.c, pl.a * p.x + pl.b * p.y + pl.c * p.z)  # type: ignore[union-attr]
        if len(sig) == 4 and sig[0] == "PARLEL" and sig[2] in MODS_XYZ and sig[3] == "n":
            pl = self._as_plane(a[1])
            comp = {"X": pl.a, "Y": pl.b, "Z": pl.c}[sig[2][0]]
            if abs(comp) < 1e-9:
                raise self.err(
                    f"ambiguous modifier {sig[2]}: the plane is parallel to the {sig[2][0]} axis",
                    a[2].tok,
                )
            s = (1 if comp > 0 else -1) * (1 if sig[2].endswith("LARGE") else -1)
            return Plane(pl.a, pl.b, pl.c, pl.d + s * abs(v[3]))  # type: ignore[arg-type]
        if sig == ("P", "PERPTO", "V"):
            p, vec = v[0], v[2]
            pl, _ = g.plane_from_normal(vec.i, vec.j, vec.k, 0.0)  # type: ignore[union-attr]
            return Plane(pl.a, pl.b, pl.c, pl.a * p.x + pl.b * p.y + pl.c * p.z)  # type: ignore[union-attr]
        if sig in (("PERPTO", "PL", "P", "P"), ("P", "P", "PERPTO", "PL")):
            p1, p2, pl = (v[2], v[3], v[1]) if sig[0] == "PERPTO" else (v[0], v[1], v[3])
            ux, uy, uz = p2.x - p1.x, p2.y - p1.y, p2.z - p1.z  # type: ignore[union-attr]
            n = (uy * pl.c - uz * pl.b, uz * pl.a - ux * pl.c, ux * pl.b - uy * pl.a)  # type: ignore[union-attr]
            if math.sqrt(sum(x * x for x in n)) < 1e-12:
                raise GeometryError("the two points lie along the plane's normal: no unique plane")
            out, _ = g.plane_from_normal(*n, 0.0)
            return Plane(out.a, out.b, out.c, out.a * p1.x + out.b * p1.y + out.c * p1.z)  # type: ignore[union-attr]
        if sig == ("P", "PERPTO", "PL", "PL"):
            p, p1, p2 = v[0], v[2], v[3]
            n = (p1.b * p2.c - p1.c * p2.b, p1.c * p2.a - p1.a * p2.c, p1.a * p2.b - p1.b * p2.a)  # type: ignore[union-attr]
            if math.sqrt(sum(x * x for x in n)) < 1e-12:
                raise GeometryError("the two planes are parallel: no plane perpendicular to both")
            out, _ = g.plane_from_normal(*n, 0.0)
            return Plane(out.a, out.b, out.c, out.a * p.x + out.b * p.y + out.c * p.z)  # type: ignore[union-attr]
        if (
            len(sig) in (1, 2)
            and sig[0] in ("XYPLAN", "YZPLAN", "ZXPLAN")
            and sig[1:] in ((), ("n",))
        ):
            off = v[1] if len(v) == 2 else 0.0
            base = _COORD_PLANES[sig[0]]
            return Plane(base.a, base.b, base.c, off)  # type: ignore[arg-type]
        raise self._no_form(d, sig)

    def _as_plane(self, arg: _Arg) -> Plane:
        if isinstance(arg.value, Plane):
            return arg.value
        if arg.value in _COORD_PLANES:
            return _COORD_PLANES[arg.value]  # type: ignore[index]
        raise self.err(f"expected a PLANE, got {_kind_name(arg.value)}", arg.tok)

    def vector(self, d: Definition, a: list[_Arg], sig: tuple[str, ...]) -> Vector:
        v = [x.value for x in a]
        if sig == ("n", "n", "n"):
            return Vector(*v)  # type: ignore[arg-type]
        if sig == ("P", "P"):
            return Vector(v[1].x - v[0].x, v[1].y - v[0].y, v[1].z - v[0].z)  # type: ignore[union-attr]
        raise self._no_form(d, sig)

    def conic(self, d: Definition, a: list[_Arg], sig: tuple[str, ...]) -> Conic:
        v = [x.value for x in a]
        if sig in (("CENTER", "P", "n", "n"), ("CENTER", "P", "n", "n", "n")):
            p = v[1]
            ang = v[4] if len(v) == 5 else 0.0
            kind = "HYPERB" if d.major == "HYPERB" else "ELLIPS"
            return g.conic(kind, p.x, p.y, v[2], v[3], ang)  # type: ignore[union-attr,arg-type]
        raise self._no_form(d, sig)

    # --- statements -------------------------------------------------------------------------

    def run(self) -> Iterator[ClRecord]:
        for st in parse(self.text, self.file):
            if self.finished:
                self.warn(
                    CamWarning("statement after FINI ignored", st.tok.line, st.tok.col, self.file)
                )
                continue
            if st.kind == "assign":
                assert st.name is not None
                if st.name in self.env:
                    self.warn(
                        CamWarning(f"{st.name} redefined", st.tok.line, st.tok.col, self.file)
                    )
                self.env[st.name] = self.value(st.value)
                continue
            yield from self.command(st)

    def _rec(self, st: Statement, word: str, args: tuple = (), text: str | None = None) -> ClRecord:
        return ClRecord(word, args, text, st.tok.line)

    def command(self, st: Statement) -> Iterator[ClRecord]:
        m = st.major
        assert m is not None
        for p in st.prefix:
            if p.value in TOOL_SIDES:
                self.tool_side = p.value
        if m in ("PARTNO", "PPRINT", "INSERT"):
            yield self._rec(st, m, (), st.text or "")
            return
        if m == "REMARK" or m in ("CLPRNT", "NOPOST", "INTOL", "OUTTOL", "TOLER"):
            return  # tolerances: the contouring here is exact (lines and circles)
        if m in ("TLOFPS", "TLONPS"):
            return  # a flat-bottomed tool on a horizontal part surface: both put the tip on it
        if m in TOOL_SIDES and not st.has_slash:
            self.tool_side = m
            return
        nodes = st.args
        if m == "MACHIN" and nodes and isinstance(nodes[0], Ref):
            nodes = [Minor(nodes[0].name, nodes[0].tok), *nodes[1:]]  # the post's name: a word
        args = self.args(nodes)
        sig = tuple(x.sig for x in args)
        if m in ("FROM", "GOTO", "GODLTA"):
            yield from self.ptp(st, m, args, sig)
        elif m in ("GO", "GOLFT", "GORGT", "GOFWD", "GOBACK", "GOUP", "GODOWN"):
            yield from self.contour(st, m, args, sig)
        elif m == "INDIRV":
            vec = self._vec3(st, args)
            self._set_direction(st, vec[0], vec[1])
        elif m == "INDIRP":
            if sig != ("P",) or self.pos is None:
                raise self.err("INDIRP needs a POINT and a known tool position", st.tok)
            p = args[0].value
            self._set_direction(st, p.x - self.pos[0], p.y - self.pos[1])  # type: ignore[union-attr]
        elif m == "ZSURF":
            if sig == ("n",):
                self.zsurf = args[0].value  # type: ignore[assignment]
            elif sig == ("PL",):
                pl = args[0].value
                if abs(abs(pl.c) - 1) > 1e-9:  # type: ignore[union-attr]
                    raise self.err("ZSURF needs a plane parallel to XY", st.tok)
                self.zsurf = pl.d / pl.c  # type: ignore[union-attr]
            else:
                raise self.err("ZSURF/z or ZSURF/plane", st.tok)
        elif m == "AUTOPS":
            if self.pos is None:
                raise self.err("AUTOPS needs a known tool position", st.tok)
            self.part_surface = Plane(0.0, 0.0, 1.0, self.pos[2])
        elif m == "CUTTER":
            yield self.cutter(st, args, sig)
        elif m == "UNITS":
            if sig not in (("MM",), ("INCHES",)):
                raise self.err("UNITS/MM or UNITS/INCHES", st.tok)
            if self.moved and sig[0] != self.units:
                raise self.err("UNITS changed after motion (one unit system per program)", st.tok)
            self.units = sig[0]
            yield self._rec(st, "UNITS", (sig[0],))
        elif m == "TLAXIS":
            vec = self._vec3(st, args)
            n = math.sqrt(sum(x * x for x in vec))
            if n < 1e-12:
                raise self.err("TLAXIS: zero vector", st.tok)
            self.tool_axis = (vec[0] / n, vec[1] / n, vec[2] / n)
            yield self._rec(st, "TLAXIS", self.tool_axis)
        elif m == "MULTAX":
            on = sig in ((), ("ON",))
            if sig not in ((), ("ON",), ("OFF",)):
                raise self.err("MULTAX, MULTAX/ON or MULTAX/OFF", st.tok)
            self.multax = on
            yield self._rec(st, "MULTAX", ("ON" if on else "OFF",))
        elif m == "FINI":
            self.finished = True
            yield self._rec(st, "FINI")
        elif m in ("RAPID", "END", "STOP", "OPSTOP"):
            if args:
                raise self.err(f"{m} takes no arguments", st.tok)
            yield self._rec(st, m)
        elif m in ("MACHIN", "LOADTL", "TURRET", "SPINDL", "FEDRAT", "COOLNT", "CUTCOM", "DELAY"):
            yield self.post_word(st, m, args, sig)
        elif m in GEOMETRY:
            raise self.err(
                f"{m} is a geometry definition: give it a name ({m[0]}1 = {m}/...)", st.tok
            )
        elif m in ("MACRO", "TERMAC", "CALL", "LOOPST", "LOOPND", "JUMPTO", "IF"):
            raise self.err(f"{m} is not supported by this processor (no macros or loops)", st.tok)
        else:
            raise self.err(f"{m} is not supported by this processor", st.tok)

    def _vec3(self, st: Statement, args: list[_Arg]) -> tuple[float, float, float]:
        sig = tuple(x.sig for x in args)
        if sig == ("n", "n", "n"):
            return tuple(x.value for x in args)  # type: ignore[return-value]
        if sig == ("V",):
            v = args[0].value
            return (v.i, v.j, v.k)  # type: ignore[union-attr]
        raise self.err(f"{st.major} needs i,j,k or a VECTOR", st.tok)

    def _set_direction(self, st: Statement, dx: float, dy: float) -> None:
        n = math.hypot(dx, dy)
        if n < 1e-12:
            raise self.err(f"{st.major}: the direction has no XY component", st.tok)
        self.direction = (dx / n, dy / n)

    def post_word(self, st: Statement, m: str, args: list[_Arg], sig: tuple[str, ...]) -> ClRecord:
        vals = tuple(x.value for x in args)
        nums = [x for x in args if isinstance(x.value, float)]
        if m == "TURRET":
            m = "LOADTL"
        if m == "LOADTL":
            if not nums or nums[0].value < 0 or nums[0].value != int(nums[0].value):  # type: ignore[operator,arg-type]
                raise self.err("LOADTL needs a tool number (a whole number >= 0)", st.tok)
        elif m == "FEDRAT":
            if not nums or not nums[0].value > 0:  # type: ignore[operator]
                raise self.err("FEDRAT needs a feed rate > 0", st.tok)
            bad = [
                x
                for x in args
                if isinstance(x.value, str) and x.value not in ("IPM", "IPR", "MMPM", "MMPR")
            ]
            if bad or len(nums) != 1:
                raise self.err("FEDRAT/f[,IPM|IPR|MMPM|MMPR]", (bad[0].tok if bad else st.tok))
        elif m == "SPINDL":
            words = [x.value for x in args if isinstance(x.value, str)]
            if sig in (("OFF",), ("ON",)):
                pass
            elif (
                not nums
                or not nums[0].value > 0
                or any(w not in ("RPM", "CLW", "CCLW", "SFM", "SMM", "MAXRPM") for w in words)
            ):  # type: ignore[operator]
                raise self.err(
                    "SPINDL/n[,CLW|CCLW], SPINDL/RPM,n,CLW|CCLW, SPINDL/ON or SPINDL/OFF", st.tok
                )
        elif m == "COOLNT":
            if sig not in (("ON",), ("FLOOD",), ("MIST",), ("OFF",)):
                raise self.err("COOLNT/ON, FLOOD, MIST or OFF", st.tok)
        elif m == "CUTCOM":
            if not sig or sig[0] not in ("LEFT", "RIGHT", "OFF") or any(s != "n" for s in sig[1:]):
                raise self.err("CUTCOM/LEFT|RIGHT[,n] or CUTCOM/OFF", st.tok)
        elif m == "DELAY":
            if sig not in (("n",), ("n", "REV")) or not nums[0].value >= 0:  # type: ignore[operator]
                raise self.err("DELAY/seconds (>= 0)", st.tok)
        elif m == "MACHIN" and any(not isinstance(x.value, (float, str)) for x in args):
            raise self.err("MACHIN/name[,n]", st.tok)
        if any(not isinstance(x, (float, str)) for x in vals):
            raise self.err(f"{m} takes numbers and modifier words only", st.tok)
        return self._rec(st, m, vals)

    def cutter(self, st: Statement, args: list[_Arg], sig: tuple[str, ...]) -> ClRecord:
        if not sig or any(s != "n" for s in sig) or len(sig) not in (1, 2, 6, 7):
            raise self.err("CUTTER/d, CUTTER/d,r or CUTTER/d,r,e,f,a,b[,h]", st.tok)
        v = [float(x.value) for x in args]  # type: ignore[arg-type]
        d = v[0]
        r = v[1] if len(v) > 1 else 0.0
        if not d > 0:
            raise self.err(f"CUTTER: the diameter must be > 0, got {d:g}", args[0].tok)
        if r < 0:
            raise self.err(f"CUTTER: the corner radius must be >= 0, got {r:g}", args[1].tok)
        if len(v) >= 6:
            e, f, a_deg, b_deg = v[2:6]
            if not 0 <= a_deg < 90:
                raise self.err(f"CUTTER: A must be in [0, 90) degrees, got {a_deg:g}", args[4].tok)
            if not -90 < b_deg < 90:
                raise self.err(
                    f"CUTTER: B must be in (-90, 90) degrees, got {b_deg:g}", args[5].tok
                )
            if len(v) == 6:
                v.append(H_DEFAULT_INCH * (25.4 if self.units == "MM" else 1.0))
            elif not v[6] > 0:
                raise self.err(f"CUTTER: H must be > 0, got {v[6]:g}", args[6].tok)
            _check_corner(self, st, d, r, e, f, a_deg, b_deg)
        else:
            _check_corner(self, st, d, r, 0.0, 0.0, 0.0, 0.0)
        self.cutter_radius = d / 2
        return self._rec(st, "CUTTER", tuple(v))

    # --- point-to-point ------------------------------------------------------------------------

    def _target(self, st: Statement, args: list[_Arg], sig: tuple[str, ...]) -> tuple[float, ...]:
        if sig == ("P",):
            p = args[0].value
            return (p.x, p.y, p.z)  # type: ignore[union-attr]
        if sig in (("n", "n"), ("n", "n", "n"), ("n",) * 6):
            v = tuple(float(x.value) for x in args)  # type: ignore[arg-type]
            return v if len(v) != 2 else (*v, 0.0)
        raise self.err(f"{st.major}/x,y[,z[,i,j,k]] or {st.major}/point", st.tok)

    def ptp(
        self, st: Statement, m: str, args: list[_Arg], sig: tuple[str, ...]
    ) -> Iterator[ClRecord]:
        if m == "GODLTA":
            if self.pos is None:
                raise self.err("GODLTA needs a known tool position (FROM or GOTO first)", st.tok)
            if sig == ("n",):
                delta = (0.0, 0.0, float(args[0].value))  # type: ignore[arg-type]
            elif sig in (("n", "n"), ("n", "n", "n")):
                dv = [float(x.value) for x in args]  # type: ignore[arg-type]
                delta = (dv[0], dv[1], dv[2] if len(dv) == 3 else 0.0)
            else:
                raise self.err("GODLTA/dz or GODLTA/dx,dy[,dz]", st.tok)
            target: tuple[float, ...] = tuple(p + q for p, q in zip(self.pos, delta, strict=True))
        else:
            target = self._target(st, args, sig)
        if len(target) == 6:
            i, j, k = target[3:]
            n = math.sqrt(i * i + j * j + k * k)
            if abs(n - 1.0) > 1e-3:
                raise self.err(
                    f"{m}: the tool axis ({i:g}, {j:g}, {k:g}) is not a unit vector", st.tok
                )
            self.tool_axis = (i / n, j / n, k / n)
        xyz = (float(target[0]), float(target[1]), float(target[2]))
        if self.pos is not None and m != "FROM":
            self._set_direction_soft(xyz[0] - self.pos[0], xyz[1] - self.pos[1])
        self.pos = xyz
        yield self._motion(st, "FROM" if m == "FROM" else "GOTO")

    def _set_direction_soft(self, dx: float, dy: float) -> None:
        n = math.hypot(dx, dy)
        if n > 1e-12:
            self.direction = (dx / n, dy / n)

    def _motion(self, st: Statement, word: str) -> ClRecord:
        assert self.pos is not None
        self.moved = True
        if self.multax or self.tool_axis != (0.0, 0.0, 1.0):
            return self._rec(st, word, (*self.pos, *self.tool_axis))
        return self._rec(st, word, self.pos)

    # --- continuous path -------------------------------------------------------------------------

    def contour(
        self, st: Statement, m: str, args: list[_Arg], sig: tuple[str, ...]
    ) -> Iterator[ClRecord]:
        if self.pos is None:
            raise self.err(f"{m} needs a known tool position (FROM or GOTO first)", st.tok)
        if self.cutter_radius is None:
            raise self.err(f"{m}: continuous-path motion needs a CUTTER statement first", st.tok)
        if abs(self.tool_axis[2] - 1.0) > 1e-12:
            raise self.err(f"{m}: continuous-path motion needs the tool axis along +Z", st.tok)
        groups = _surface_groups(self, st, args)
        try:
            if m == "GO":
                yield from self.startup(st, groups)
            elif m in ("GOUP", "GODOWN"):
                yield from self.vertical(st, m, groups)
            else:
                yield from self.drive(st, m, groups)
        except GeometryError as e:
            raise self.err(f"{m}: {e}", st.tok) from None

    def _z_at(self, x: float, y: float) -> float:
        assert self.pos is not None
        if self.part_surface is None:
            return self.pos[2]
        return g.plane_z(self.part_surface, x, y)

    def _curve(self, arg: _Arg) -> Line | Circle:
        v = arg.value
        if isinstance(v, (Line, Circle)):
            return v
        if isinstance(v, Plane) and abs(v.c) < 1e-12:  # a vertical plane is a line in XY
            n = math.hypot(v.a, v.b)
            nx, ny = v.a / n, v.b / n
            return Line(nx * v.d / n, ny * v.d / n, -ny, nx)
        raise self.err(f"expected a LINE, CIRCLE or vertical PLANE, got {_kind_name(v)}", arg.tok)

    def _offset_from(
        self, curve: Line | Circle, mod: str, x: float, y: float, tok: Token
    ) -> Line | Circle:
        """The locus of tool centres that are TO / ON / PAST the curve, judged from (x, y)."""
        R = self.cutter_radius or 0.0
        if isinstance(curve, Line):
            if mod == "ON":
                return curve
            sd = curve.signed_distance(x, y)
            if abs(sd) < 1e-9 * _scale(x, y):
                raise self.err(
                    f"{mod}: the tool centre is on the surface, so its near side is undefined", tok
                )
            side = 1 if sd > 0 else -1
            return curve.offset(side * R if mod == "TO" else -side * R)
        dist = math.hypot(x - curve.cx, y - curve.cy)
        inside = dist < curve.r
        if mod == "ON":
            rr = curve.r
        elif mod == "TO":
            rr = curve.r - R if inside else curve.r + R
        else:
            rr = curve.r + R if inside else curve.r - R
        if rr < -1e-12:
            raise self.err(
                f"{mod}: the cutter (radius {R:g}) does not fit inside the circle (radius {curve.r:g})",
                tok,
            )
        return Circle(curve.cx, curve.cy, max(rr, 0.0), curve.cz)

    def startup(self, st: Statement, groups: list[tuple[str, _Arg]]) -> Iterator[ClRecord]:
        assert self.pos is not None
        x0, y0, z0 = self.pos
        if not 1 <= len(groups) <= 3:
            raise self.err("GO/[TO|ON|PAST,]ds[,[TO|ON|PAST,]ps[,[TO|ON|PAST|TANTO,]cs]]", st.tok)
        ds_mod, ds_arg = groups[0]
        ds = self._offset_from(self._curve(ds_arg), ds_mod, x0, y0, ds_arg.tok)
        if len(groups) >= 2:
            ps_mod, ps_arg = groups[1]
            if not isinstance(ps_arg.value, Plane):
                raise self.err(
                    f"the part surface must be a PLANE, got {_kind_name(ps_arg.value)}", ps_arg.tok
                )
            self.part_surface = ps_arg.value
        if len(groups) == 3:
            cs_mod, cs_arg = groups[2]
            if cs_mod == "TANTO":
                raise self.err(
                    "GO: TANTO is a check modifier of GOLFT/GORGT/GOFWD/GOBACK", cs_arg.tok
                )
            cs = self._offset_from(self._curve(cs_arg), cs_mod, x0, y0, cs_arg.tok)
            cands = _intersect(ds, cs)
            if not cands:
                raise self.err(
                    "unreachable check surface: the drive and check surfaces (offset by the cutter) do not meet",
                    cs_arg.tok,
                )
            x, y = min(cands, key=lambda p: (p[0] - x0) ** 2 + (p[1] - y0) ** 2)
        elif isinstance(ds, Line):
            x, y = ds.foot(x0, y0)
        else:
            dx, dy = x0 - ds.cx, y0 - ds.cy
            n = math.hypot(dx, dy)
            if n < 1e-12:
                raise self.err(
                    "GO: the tool is at the circle's centre: every point is nearest", ds_arg.tok
                )
            x, y = ds.cx + ds.r * dx / n, ds.cy + ds.r * dy / n
        z = self._z_at(x, y) if len(groups) >= 2 else z0
        self._set_direction_soft(x - x0, y - y0)
        self.pos = (x, y, z)
        yield self._motion(st, "GOTO")

    def vertical(self, st: Statement, m: str, groups: list[tuple[str, _Arg]]) -> Iterator[ClRecord]:
        assert self.pos is not None
        x, y, z0 = self.pos
        if len(groups) != 2 or not isinstance(groups[1][1].value, Plane):
            raise self.err(
                f"{m}/ds,TO|ON,plane: the check surface of a vertical move is a PLANE", st.tok
            )
        mod, cs_arg = groups[1]
        if mod not in ("TO", "ON"):
            raise self.err(f"{m}: only TO or ON a plane (the tip stops on it)", cs_arg.tok)
        z = g.plane_z(cs_arg.value, x, y)  # type: ignore[arg-type]
        if (m == "GOUP" and not z > z0) or (m == "GODOWN" and not z < z0):
            where = "above" if m == "GOUP" else "below"
            raise self.err(
                f"unreachable check surface: the plane is not {where} the tool", cs_arg.tok
            )
        self.part_surface = cs_arg.value  # type: ignore[assignment]
        self.pos = (x, y, z)
        yield self._motion(st, "GOTO")

    def drive(self, st: Statement, m: str, groups: list[tuple[str, _Arg]]) -> Iterator[ClRecord]:
        assert self.pos is not None
        x0, y0, z0 = self.pos
        if len(groups) != 2:
            raise self.err(f"{m}/ds,[TO|ON|PAST|TANTO,]cs: a drive and a check surface", st.tok)
        ds_arg = groups[0][1]
        cs_mod, cs_arg = groups[1]
        if self.direction is None:
            raise self.err(f"{m}: no direction of motion yet (move first, or INDIRV)", st.tok)
        fx, fy = self.direction
        gx, gy = {"GOFWD": (fx, fy), "GOBACK": (-fx, -fy), "GOLFT": (-fy, fx), "GORGT": (fy, -fx)}[
            m
        ]
        ds = self._curve(ds_arg)
        R = self.cutter_radius or 0.0
        side = {"TLLFT": 1, "TLRGT": -1, "TLON": 0}[self.tool_side]
        scale = _scale(x0, y0)
        if isinstance(ds, Line):
            dot = ds.ux * gx + ds.uy * gy
            if abs(dot) < 1e-9:
                raise self.err(
                    f"{m}: the drive surface is perpendicular to the {m} direction (ambiguous)",
                    ds_arg.tok,
                )
            s = 1 if dot > 0 else -1
            path: Line | Circle = Line(ds.px, ds.py, s * ds.ux, s * ds.uy).offset(side * R)
            off = abs(path.signed_distance(x0, y0))  # type: ignore[union-attr]
            ccw = True
        else:
            rx, ry = x0 - ds.cx, y0 - ds.cy
            rn = math.hypot(rx, ry)
            if rn < 1e-12:
                raise self.err(f"{m}: the tool is at the drive circle's centre", ds_arg.tok)
            tx, ty = -ry / rn, rx / rn  # counter-clockwise tangent
            dot = tx * gx + ty * gy
            if abs(dot) < 1e-9:
                raise self.err(
                    f"{m}: the drive circle's tangent is perpendicular to the {m} direction (ambiguous)",
                    ds_arg.tok,
                )
            ccw = dot > 0
            # moving counter-clockwise the left side is inside
            rr = ds.r - side * R if ccw else ds.r + side * R
            if rr <= 1e-12:
                raise self.err(
                    f"the cutter (radius {R:g}) does not fit inside the drive circle (radius {ds.r:g})",
                    ds_arg.tok,
                )
            path = Circle(ds.cx, ds.cy, rr, ds.cz)
            off = abs(rn - rr)
        if off > ON_TOLERANCE * scale:
            raise self.err(
                f"{m}: the tool centre is {off:.6g} off the drive surface offset {self.tool_side}"
                " by the cutter radius (check TLLFT/TLRGT, or start the contour with GO/...)",
                ds_arg.tok,
            )
        cs = self._curve(cs_arg)
        if cs_mod == "TANTO":
            end = _tangency(ds, cs, path)
            if end is None:
                raise self.err("TANTO: the drive and check surfaces are not tangent", cs_arg.tok)
            cands = [end]
        else:
            cands = _intersect(path, self._offset_from(cs, cs_mod, x0, y0, cs_arg.tok))
        best = None
        for cx, cy in cands:
            if isinstance(path, Line):
                t = (cx - x0) * path.ux + (cy - y0) * path.uy
            else:
                a0 = math.atan2(y0 - path.cy, x0 - path.cx)
                a1 = math.atan2(cy - path.cy, cx - path.cx)
                t = ((a1 - a0) if ccw else (a0 - a1)) % (2 * math.pi)
                t *= path.r
            if t > 1e-9 * scale and (best is None or t < best[0]):
                best = (t, cx, cy)
        if best is None:
            raise self.err(
                "unreachable check surface: the tool never reaches it along the drive surface",
                cs_arg.tok,
            )
        _, x, y = best
        z = self._z_at(x, y)
        if isinstance(path, Circle):
            if self.part_surface is not None and abs(abs(self.part_surface.c) - 1) > 1e-12:
                raise self.err(
                    f"{m}: a circular drive surface needs a horizontal part surface", ds_arg.tok
                )
            yield self._rec(
                st, "CIRCLE", (path.cx, path.cy, z, 0.0, 0.0, 1.0 if ccw else -1.0, path.r)
            )
            rx, ry = x - path.cx, y - path.cy
            rn = math.hypot(rx, ry)
            self.direction = (-ry / rn, rx / rn) if ccw else (ry / rn, -rx / rn)
        else:
            self.direction = (path.ux, path.uy)
        self.pos = (x, y, z)
        yield self._motion(st, "GOTO")


_COORD_PLANES = {
    "XYPLAN": Plane(0.0, 0.0, 1.0, 0.0),
    "YZPLAN": Plane(1.0, 0.0, 0.0, 0.0),
    "ZXPLAN": Plane(0.0, 1.0, 0.0, 0.0),
}


def _tok_of(node: object) -> Token:
    return node.tok  # type: ignore[attr-defined,no-any-return]


def _surface_groups(proc: Processor, st: Statement, args: list[_Arg]) -> list[tuple[str, _Arg]]:
    """[modifier,] surface pairs; a missing modifier is TO."""
    out: list[tuple[str, _Arg]] = []
    pending: str | None = None
    for a in args:
        if isinstance(a.value, str):
            if a.value in ("XYPLAN", "YZPLAN", "ZXPLAN"):
                out.append((pending or "TO", _Arg(_COORD_PLANES[a.value], a.tok)))
                pending = None
                continue
            if a.value not in ("TO", "ON", "PAST", "TANTO") or pending is not None:
                raise proc.err(
                    f"{st.major}: unexpected {a.value} (modifiers are TO, ON, PAST, TANTO)", a.tok
                )
            pending = a.value
            continue
        if not isinstance(a.value, (Line, Circle, Plane)):
            raise proc.err(f"{st.major}: expected a surface, got {_kind_name(a.value)}", a.tok)
        out.append((pending or "TO", a))
        pending = None
    if pending is not None:
        raise proc.err(f"{st.major}: a modifier needs a surface after it", args[-1].tok)
    return out


def _intersect(a: Line | Circle, b: Line | Circle) -> list[tuple[float, float]]:
    if isinstance(a, Line) and isinstance(b, Line):
        try:
            return [g.intersect_lines(a, b)]
        except GeometryError:
            return []
    if isinstance(a, Line):
        return g.intersect_line_circle(a, b)  # type: ignore[arg-type]
    if isinstance(b, Line):
        return g.intersect_line_circle(b, a)
    return g.intersect_circles(a, b)


def _tangency(
    ds: Line | Circle, cs: Line | Circle, path: Line | Circle
) -> tuple[float, float] | None:
    """Where the tool centre is when the drive surface touches the check surface: the
    tangency point carried onto the offset path along the drive surface's normal."""
    if isinstance(ds, Line) and isinstance(cs, Line):
        return None
    if isinstance(ds, Line):
        assert isinstance(cs, Circle) and isinstance(path, Line)
        if abs(abs(ds.signed_distance(cs.cx, cs.cy)) - cs.r) > 1e-6 * _scale(cs.cx, cs.cy, cs.r):
            return None
        return path.foot(*ds.foot(cs.cx, cs.cy))
    assert isinstance(path, Circle)
    if isinstance(cs, Line):
        if abs(abs(cs.signed_distance(ds.cx, ds.cy)) - ds.r) > 1e-6 * _scale(ds.cx, ds.cy, ds.r):
            return None
        tx, ty = cs.foot(ds.cx, ds.cy)
    else:
        dist = math.hypot(cs.cx - ds.cx, cs.cy - ds.cy)
        if dist < 1e-12:
            return None
        if abs(dist - (ds.r + cs.r)) > 1e-6 * _scale(dist) and abs(
            dist - abs(ds.r - cs.r)
        ) > 1e-6 * _scale(dist):
            return None
        sgn = 1.0 if abs(dist - (ds.r + cs.r)) <= 1e-6 * _scale(dist) or ds.r >= cs.r else -1.0
        tx = ds.cx + sgn * ds.r * (cs.cx - ds.cx) / dist
        ty = ds.cy + sgn * ds.r * (cs.cy - ds.cy) / dist
    ux, uy = tx - ds.cx, ty - ds.cy
    n = math.hypot(ux, uy)
    return (path.cx + path.r * ux / n, path.cy + path.r * uy / n)


def _check_corner(
    proc: Processor,
    st: Statement,
    d: float,
    r: float,
    e: float,
    f: float,
    a_deg: float,
    b_deg: float,
) -> None:
    """The corner arc must touch the bottom edge (angle A from the plane normal to the axis)
    and the side edge (angle B from the axis) that meet at radius D/2; when it cannot, the
    normals drawn from the two edges to the arc's centre cross before it and APT calls the
    cutter undefined (seed 004 Fig. 2.71)."""
    if r == 0:
        return
    a, b = math.radians(a_deg), math.radians(b_deg)
    vx, vy = d / 2, d / 2 * math.tan(a)  # the corner where the edges meet
    u1 = (-math.cos(a), -math.sin(a))  # along the bottom edge, towards the axis
    u2 = (math.sin(b), math.cos(b))  # along the side edge, upwards
    cos_t = u1[0] * u2[0] + u1[1] * u2[1]
    theta = math.acos(max(-1.0, min(1.0, cos_t)))
    reach = r / math.tan(theta / 2)  # from the corner to either tangency point
    if reach > (d / 2) / math.cos(a) + 1e-12:
        raise proc.err(
            f"cutter undefined: a corner radius {r:g} does not fit the diameter {d:g}"
            " (the normals from the bottom and side edges intersect before the arc)",
            st.tok,
        )
    if e == 0 and f == 0:
        return  # APT computes E and F: the arc tangent to both edges
    bx, by = u1[0] + u2[0], u1[1] + u2[1]
    bn = math.hypot(bx, by)
    ce = vx + r / math.sin(theta / 2) * bx / bn
    cf = vy + r / math.sin(theta / 2) * by / bn
    if abs(ce - e) > 1e-4 * d or abs(cf - f) > 1e-4 * d:
        raise proc.err(
            f"cutter undefined: a corner radius centre at E={e:g}, F={f:g} is not {r:g} from"
            f" both edges (tangent to both it is at E={ce:.6g}, F={cf:.6g})",
            st.tok,
        )


def process(
    text: str, file: str = "<apt>", warn: WarningSink = ignore_warning
) -> Iterator[ClRecord]:
    """The CL records of an APT program."""
    return Processor(text, file, warn).run()
