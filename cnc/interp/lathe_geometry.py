"""The lathe cycles' pass lists: pure functions of points in the XZ plane.

Points are `(x, z)` in program coordinates, mm, **X as a radius** (the interpreter halves a
diameter word before it gets here). A contour is a tuple of `Seg` (line or arc, rapid or
feed) from its first point A' to its last point B. Every cycle returns a list of `Move`:
`(kind, x, z, cx, cz)` with kind RAPID / FEED / CW / CCW (arcs, centre cx cz) / THREAD
(a spindle-synchronised feed whose F is the lead). The interpreter emits them in order
through its ordinary move emitters (cnc.interp.lathe_cycles).

G72 (facing) and G74 (face grooving) are G71 and G75 with X and Z exchanged: `swap` maps a
contour into the exchanged frame (an arc's direction flips with the handedness) and the
same pass generator runs there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from cnc.errors import CncError

RAPID, FEED, CW, CCW, THREAD = 0, 1, 2, 3, 32
MAX_MOVES = 1_000_000  # one cycle block's moves: a tiny depth or step cannot flood the planner
MAX_DIVISIONS = 9999  # G73 passes
EPS = 1e-9
TOL = 1e-6  # mm: a point this close to a level counts as on it

Pt = tuple[float, float]
Move = tuple[int, float, float, float, float]


@dataclass(frozen=True, slots=True)
class Seg:
    """One contour element: `kind` RAPID/FEED (line) or CW/CCW (arc about `c`), a -> b."""

    kind: int
    a: Pt
    b: Pt
    c: Pt | None = None
    line: int = 0  # source line of the block that made it

    @property
    def arc(self) -> bool:
        return self.kind in (CW, CCW)


class CycleGeometryError(CncError, ValueError):
    """A contour or a cycle's words the cycle cannot run; `line` is the offending block."""

    def __init__(self, message: str, line: int = 0, alarm: str = "") -> None:
        super().__init__(message)
        self.message = message
        self.line = line
        self.alarm = alarm


def mv(kind: int, p: Pt, c: Pt | None = None) -> Move:
    return (kind, p[0], p[1], c[0] if c else 0.0, c[1] if c else 0.0)


# --- contour transforms ---------------------------------------------------------------


def shift(segs: tuple[Seg, ...], dx: float, dz: float) -> tuple[Seg, ...]:
    """The contour translated by (dx, dz): Fanuc's finishing allowance is a translation."""
    if dx == 0.0 and dz == 0.0:
        return segs
    out = []
    for s in segs:
        c = (s.c[0] + dx, s.c[1] + dz) if s.c else None
        out.append(Seg(s.kind, (s.a[0] + dx, s.a[1] + dz), (s.b[0] + dx, s.b[1] + dz), c, s.line))
    return tuple(out)


def swap(segs: tuple[Seg, ...]) -> tuple[Seg, ...]:
    """Exchange X and Z (a reflection: arcs change direction)."""
    out = []
    for s in segs:
        kind = {CW: CCW, CCW: CW}.get(s.kind, s.kind)
        c = (s.c[1], s.c[0]) if s.c else None
        out.append(Seg(kind, (s.a[1], s.a[0]), (s.b[1], s.b[0]), c, s.line))
    return tuple(out)


def swap_moves(moves: list[Move]) -> list[Move]:
    out = []
    for k, x, z, cx, cz in moves:
        out.append(({CW: CCW, CCW: CW}.get(k, k), z, x, cz, cx))
    return out


# --- arcs -------------------------------------------------------------------------------


def _ang(c: Pt, p: Pt) -> float:
    return math.atan2(p[0] - c[0], p[1] - c[1])  # angle in the (z, x) frame


def _sweep(s: Seg) -> float:
    """Signed sweep (radians) from a to b: CCW positive in the (z, x) frame."""
    assert s.c is not None
    a0, a1 = _ang(s.c, s.a), _ang(s.c, s.b)
    d = a1 - a0
    if s.kind == CCW:
        while d <= EPS:
            d += 2 * math.pi
    else:
        while d >= -EPS:
            d -= 2 * math.pi
    return d


def _arc_point(s: Seg, t: float) -> Pt:
    """The arc's point at fraction t of its sweep."""
    assert s.c is not None
    r = math.hypot(s.a[0] - s.c[0], s.a[1] - s.c[1])
    th = _ang(s.c, s.a) + t * _sweep(s)
    return (s.c[0] + r * math.sin(th), s.c[1] + r * math.cos(th))


def _arc_fractions_at_x(s: Seg, x: float) -> list[float]:
    """Fractions t in [0, 1] where the arc crosses X = x, in order along the arc."""
    assert s.c is not None
    r = math.hypot(s.a[0] - s.c[0], s.a[1] - s.c[1])
    sx = (x - s.c[0]) / r
    if abs(sx) > 1.0 + 1e-12:
        return []
    sx = max(-1.0, min(1.0, sx))
    base = math.asin(sx)
    a0 = _ang(s.c, s.a)
    sw = _sweep(s)
    out = []
    for th in (base, math.pi - base):
        d = th - a0
        # bring d into the sweep's direction, within one turn
        if sw > 0:
            d %= 2 * math.pi
        else:
            d = -((-d) % (2 * math.pi))
        t = d / sw
        if -1e-12 <= t <= 1.0 + 1e-12:
            out.append(min(max(t, 0.0), 1.0))
    return sorted(set(out))


def _extremes_inside(s: Seg) -> tuple[bool, bool]:
    """Whether the arc passes an X extreme / a Z extreme strictly between its ends."""
    assert s.c is not None
    a0 = _ang(s.c, s.a)
    sw = _sweep(s)
    has_x = has_z = False
    for k in range(-8, 9):
        th = k * math.pi / 2.0
        d = th - a0
        t = d / sw
        if 1e-9 < t < 1.0 - 1e-9:
            if k % 2:  # sin = +-1: X extreme
                has_x = True
            else:  # cos = +-1: Z extreme
                has_z = True
    return has_x, has_z


# --- monotony -------------------------------------------------------------------------


def monotony_fault(segs: tuple[Seg, ...], check_x: bool) -> tuple[int, str] | None:
    """The first element where X (if `check_x`) or Z turns back: (index, axis) or None.

    The contour's direction on each axis is taken from its first element that moves that
    axis; type I needs both axes monotonic, type II only Z (the cutting direction).
    """
    dirs = {"X": 0.0, "Z": 0.0}
    for i, s in enumerate(segs):
        for axis, idx in (("X", 0), ("Z", 1)):
            if axis == "X" and not check_x:
                continue
            d = s.b[idx] - s.a[idx]
            if s.arc:
                ext = _extremes_inside(s)[0 if axis == "X" else 1]
                if ext:
                    return i, axis
                # an arc ending where it starts on this axis (half circle) moves both ways
                if abs(d) <= TOL:
                    mid = _arc_point(s, 0.5)[idx] - s.a[idx]
                    if abs(mid) > TOL:
                        return i, axis
                    continue
            if abs(d) <= TOL:
                continue
            sg = 1.0 if d > 0 else -1.0
            if dirs[axis] == 0.0:
                dirs[axis] = sg
            elif sg != dirs[axis]:
                return i, axis
    return None


# --- level crossings ------------------------------------------------------------------


def _material_spans(segs: tuple[Seg, ...], level: float, s: float) -> list[tuple[float, float]]:
    """Z spans at X = level where the contour lies on the start side of the level.

    `s` is the stepping direction of the levels (-1: outside turning, levels go down
    towards the axis; +1: boring). Material at the level is where the contour is beyond the
    level seen from the start (`-s * (x - level) < 0`). Returns (z_from, z_to) spans in
    the contour's order; the first starts at the contour's first point.
    """

    def h(p: Pt) -> float:
        return -s * (p[0] - level)

    spans: list[tuple[float, float]] = []
    inside = h(segs[0].a) < -TOL
    z_from = segs[0].a[1]
    for seg in segs:
        # crossing points along this element, in order
        if seg.arc:
            ts = _arc_fractions_at_x(seg, level)
            pts = [(t, _arc_point(seg, t)) for t in ts]
        else:
            ha, hb = h(seg.a), h(seg.b)
            pts = []
            if (ha < -TOL) != (hb < -TOL):
                if abs(ha - hb) < EPS:
                    t = 0.0
                else:
                    t = min(max(ha / (ha - hb), 0.0), 1.0)
                p = (
                    seg.a[0] + t * (seg.b[0] - seg.a[0]),
                    seg.a[1] + t * (seg.b[1] - seg.a[1]),
                )
                pts = [(t, p)]
        for t, p in pts:
            # the state just after the crossing decides entering or leaving
            after = (
                seg.b
                if t >= 1.0 - 1e-12
                else (
                    _arc_point(seg, min(1.0, t + 1e-6))
                    if seg.arc
                    else (
                        seg.a[0] + min(1.0, t + 1e-6) * (seg.b[0] - seg.a[0]),
                        seg.a[1] + min(1.0, t + 1e-6) * (seg.b[1] - seg.a[1]),
                    )
                )
            )
            now_inside = h(after) < -TOL
            if inside and not now_inside:
                spans.append((z_from, p[1]))
                inside = False
            elif not inside and now_inside:
                z_from = p[1]
                inside = True
        if not seg.arc and (h(seg.b) < -TOL) != inside:
            # an element ending exactly on the level
            if inside:
                spans.append((z_from, seg.b[1]))
                inside = False
            else:
                z_from = seg.b[1]
                inside = True
    if inside:
        spans.append((z_from, segs[-1].b[1]))
    return [sp for sp in spans if abs(sp[1] - sp[0]) > TOL]


# --- G71 / G72 ------------------------------------------------------------------------


def rough_turning(
    start: Pt,
    contour: tuple[Seg, ...],
    depth: float,
    retract: float,
    allowance: Pt,
    type2: bool,
    max_passes: int = 100_000,
) -> list[Move]:
    """G71 stock removal in turning: paraxial passes along Z, then the contour pass.

    `start` A = (x0, z0) is the cycle's start point, outside the stock; `contour` runs
    from A' (the ns block's end point) to B (the nf block's end point) and is cut
    translated by `allowance` (U/2, W). Levels step from x0 towards A' by `depth`; at each
    level the tool feeds along Z from z0 until it meets the (translated) contour, pulls
    off at 45 degrees by `retract` and returns to z0 in rapid. Type II: every span of
    material is cut (pockets), pocket after pocket (`_pocket_order`), a pocket's pass
    reached from x0 down the column at the span's start. Last: rapid to A' (translated), the
    contour at feed, rapid out to x0, then to z0.
    """
    if depth <= 0.0:
        raise CycleGeometryError("depth of cut must be greater than 0", alarm="PS0062")
    x0, z0 = start
    prof = shift(contour, allowance[0], allowance[1])
    xa = prof[0].a[0]
    s = -1.0 if xa < x0 else 1.0  # -1: outside turning (levels go down)
    end_z = prof[-1].b[1]
    zdir = -1.0 if end_z < z0 else 1.0
    moves: list[Move] = []
    n = int(math.floor(abs(x0 - xa) / depth - 1e-9))
    if n > max_passes:
        raise CycleGeometryError(
            f"cycle expands to more than {max_passes} passes (depth of cut too small)",
            alarm="PS0062",
        )
    levels: list[tuple[float, list[tuple[float, float]]]] = []
    for k in range(1, n + 1):
        level = x0 + s * k * depth
        spans = _material_spans(prof, level, s)
        if spans:
            levels.append((level, spans if type2 else spans[:1]))
    order = _pocket_order(levels)
    for i, (li, si) in enumerate(order):
        level, (za, zb) = levels[li][0], levels[li][1][si]
        if si == 0:  # the span from the contour's start: entered at z0, as in type I
            moves.append(mv(RAPID, (level, z0)))
        else:  # a pocket: out to x0, along Z, down to the level above (cut), feed in
            prev = levels[li - 1][0] if li > 0 else x0
            moves.append(mv(RAPID, (x0, moves[-1][2])))
            moves.append(mv(RAPID, (x0, za)))
            moves.append(mv(RAPID, (prev, za)))
            moves.append(mv(FEED, (level, za)))
        moves.append(mv(FEED, (level, zb)))
        moves.append(mv(FEED, (level - s * retract, zb - zdir * retract)))
        if si == 0 and (i + 1 == len(order) or order[i + 1][1] == 0):
            moves.append(mv(RAPID, (level - s * retract, z0)))
        if len(moves) > MAX_MOVES:
            raise CycleGeometryError(
                f"cycle expands to more than {MAX_MOVES} moves (depth of cut too small)",
                alarm="PS0062",
            )
    if order and order[-1][1] != 0:  # after the last pocket: out to x0, back to z0
        moves.append(mv(RAPID, (x0, moves[-1][2])))
        moves.append(mv(RAPID, (x0, z0)))
    moves.extend(contour_pass(start, prof))
    return moves


def _pocket_order(levels: list[tuple[float, list[tuple[float, float]]]]) -> list[tuple[int, int]]:
    """(level index, span index) of every pass, pocket after pocket.

    A span of material at a level lies inside one span of the level above (the contour is
    beyond a deeper level only where it is beyond the shallower one), so the spans form a
    tree. Depth first, children in the contour's order: the region at the contour's start
    down to A' first, then each pocket from its top level to its bottom before the next,
    as type II roughing runs (the tool follows the contour from one pocket to the next, as
    LinuxCNC's G71 does; a Fanuc pocket is likewise finished before the next).
    """
    order: list[tuple[int, int]] = []

    def inside(child: tuple[float, float], parent: tuple[float, float]) -> bool:
        lo, hi = min(parent) - TOL, max(parent) + TOL
        return lo <= child[0] <= hi and lo <= child[1] <= hi

    stack = [(0, si) for si in reversed(range(len(levels[0][1])))] if levels else []
    while stack:
        li, si = stack.pop()
        order.append((li, si))
        if li + 1 < len(levels):
            span = levels[li][1][si]
            kids = [k for k, sp in enumerate(levels[li + 1][1]) if inside(sp, span)]
            stack.extend((li + 1, k) for k in reversed(kids))
    return order


def contour_pass(start: Pt, prof: tuple[Seg, ...]) -> list[Move]:
    """From A: rapid to A' in X then Z, the contour (rapids stay rapids), out to x0, to z0."""
    x0, z0 = start
    first = prof[0].a
    out: list[Move] = [mv(RAPID, (first[0], z0))]
    if abs(first[1] - z0) > TOL:
        out.append(mv(RAPID, first))
    out.extend(follow(prof))
    last = prof[-1].b
    if abs(last[0] - x0) > TOL:
        out.append(mv(RAPID, (x0, last[1])))
    out.append(mv(RAPID, (x0, z0)))
    return out


def follow(prof: tuple[Seg, ...]) -> list[Move]:
    return [mv(s.kind, s.b, s.c) for s in prof]


def rough_facing(
    start: Pt,
    contour: tuple[Seg, ...],
    depth: float,
    retract: float,
    allowance: Pt,
    type2: bool,
) -> list[Move]:
    """G72: G71 with X and Z exchanged (levels in Z, passes along X)."""
    moves = rough_turning(
        (start[1], start[0]), swap(contour), depth, retract, (allowance[1], allowance[0]), type2
    )
    return swap_moves(moves)


# --- G73 ------------------------------------------------------------------------------


def pattern_repeat(
    start: Pt, contour: tuple[Seg, ...], relief: Pt, divisions: int, allowance: Pt
) -> list[Move]:
    """G73: the contour `divisions` times, shifted by relief x (d - k) / (d - 1) + allowance.

    Pass k = 1..d: rapid to its shifted A', the shifted contour at feed, rapid out to x0
    and back to A. The first pass is the whole relief (Δi, Δk) off, the last one the
    finishing allowance only.
    """
    if not 1 <= divisions <= MAX_DIVISIONS:
        raise CycleGeometryError(f"G73 divisions must be 1..{MAX_DIVISIONS}", alarm="PS0062")
    if divisions * (len(contour) + 3) > MAX_MOVES:
        raise CycleGeometryError(f"G73 expands to more than {MAX_MOVES} moves", alarm="PS0062")
    x0, z0 = start
    moves: list[Move] = []
    for k in range(1, divisions + 1):
        f = (divisions - k) / (divisions - 1) if divisions > 1 else 0.0
        prof = shift(contour, relief[0] * f + allowance[0], relief[1] * f + allowance[1])
        moves.append(mv(RAPID, prof[0].a))
        moves.extend(follow(prof))
        last = prof[-1].b
        if abs(last[0] - x0) > TOL:
            moves.append(mv(RAPID, (x0, last[1])))
        moves.append(mv(RAPID, (x0, z0)))
    return moves


# --- G74 / G75 ------------------------------------------------------------------------


def grooving(
    start: Pt,
    end: Pt,
    peck: float,
    shift_step: float,
    retract: float,
    relief: float = 0.0,
    max_pecks: int = 100_000,
) -> list[Move]:
    """G75 OD grooving: pecks along X to `end` x, grooves stepped along Z to `end` z.

    Each groove: feed `peck` towards end x, rapid back `retract`, feed on (the last peck
    reaches end x exactly); at the bottom relieve by `relief` against the shift direction;
    rapid out to x0; shift by `shift_step` in Z (the last groove lands on end z exactly).
    A zero `peck` plunges in one feed. Ends back at A.
    """
    x0, z0 = start
    xe, ze = end
    if peck < 0 or shift_step < 0 or retract < 0:
        raise CycleGeometryError("peck, shift and retract must not be negative", alarm="PS0062")
    span_z = ze - z0
    if abs(span_z) > TOL and shift_step <= 0.0:
        raise CycleGeometryError(
            "grooving across Z needs the shift per groove (Q, Haas K)", alarm="PS0062"
        )
    s = 1.0 if xe > x0 else -1.0
    zdir = 1.0 if span_z > 0 else -1.0
    n = int(math.ceil(abs(span_z) / shift_step - 1e-9)) if abs(span_z) > TOL else 0
    depth = abs(xe - x0)
    pecks = int(math.ceil(depth / peck - 1e-9)) if peck > 0 else 1
    if pecks * (n + 1) > max_pecks:
        raise CycleGeometryError(
            f"grooving cycle expands to more than {max_pecks} pecks", alarm="PS0062"
        )
    grooves = [z0 + zdir * min(i * shift_step, abs(span_z)) for i in range(n + 1)]
    moves: list[Move] = []
    for i, zg in enumerate(grooves):
        if i:
            moves.append(mv(RAPID, (x0, zg)))
        x = x0
        while True:
            nxt = x + s * peck if peck > 0 else xe
            if (nxt - xe) * s >= -TOL:
                nxt = xe
            moves.append(mv(FEED, (nxt, zg)))
            if nxt == xe:
                break
            moves.append(mv(RAPID, (nxt - s * retract, zg)))
            x = nxt
        if relief > 0.0:
            moves.append(mv(FEED, (xe, zg - zdir * relief)))
        moves.append(mv(RAPID, (x0, moves[-1][2])))
    if abs(moves[-1][2] - z0) > TOL or abs(moves[-1][1] - x0) > TOL:
        moves.append(mv(RAPID, (x0, z0)))
    return moves


def face_grooving(
    start: Pt, end: Pt, peck: float, shift_step: float, retract: float, relief: float = 0.0
) -> list[Move]:
    """G74: G75 with X and Z exchanged (pecks along Z, grooves stepped along X)."""
    moves = grooving((start[1], start[0]), (end[1], end[0]), peck, shift_step, retract, relief)
    return swap_moves(moves)


# --- threading ------------------------------------------------------------------------


def thread_depths(
    height: float, first: float, min_cut: float = 0.0, allowance: float = 0.0, spring: int = 1
) -> list[float]:
    """G76 infeed depths: first x sqrt(n) (constant chip area), each cut at least
    `min_cut`, up to height - allowance; then `spring` passes at the full height.

    Fanuc: Δd√n roughing to k - d, the finishing allowance d and the m finishing passes at
    k. Haas one-block G76: allowance 0 and one pass at K (the last roughing pass reaches it).
    """
    if height <= 0.0 or first <= 0.0:
        raise CycleGeometryError(
            "G76 needs a thread height and a first cut depth greater than 0", alarm="PS0062"
        )
    rough_to = height - allowance
    if rough_to <= 0.0:
        raise CycleGeometryError(
            "G76 finishing allowance is not below the thread height", alarm="PS0062"
        )
    out: list[float] = []
    n = 1
    prev = 0.0
    while True:
        d = first * math.sqrt(n)
        if d - prev < min_cut:
            d = prev + min_cut
        if d >= rough_to - TOL:
            out.append(rough_to)
            break
        out.append(d)
        prev = d
        n += 1
        if n > 10_000:
            raise CycleGeometryError("G76 expands to more than 10000 passes", alarm="PS0062")
    if allowance > 0.0:
        out.append(height)
        spring = max(spring - 1, 0)
    out.extend([height] * spring)
    return out


def constant_depths(height: float, step: float) -> list[float]:
    """Infeed depths of a constant depth per pass (Haas G76 P3/P4): step, 2 step, ... height."""
    if height <= 0.0 or step <= 0.0:
        raise CycleGeometryError(
            "G76 needs a thread height and a cut depth greater than 0", alarm="PS0062"
        )
    n = int(math.ceil(height / step - 1e-9))
    if n > 10_000:
        raise CycleGeometryError("G76 expands to more than 10000 passes", alarm="PS0062")
    return [min(k * step, height) for k in range(1, n + 1)]


def thread_passes(
    start: Pt,
    end: Pt,
    depths: list[float],
    height: float,
    taper: float = 0.0,
    angle_deg: float = 0.0,
    chamfer: float = 0.0,
    alternate: bool = False,
) -> list[Move]:
    """G76 passes: for each infeed depth, from A rapid in Z (flank infeed shift), rapid in
    X to the pass's start diameter, the thread (THREAD moves) to the end point, rapid out
    to x0, rapid back to A.

    `end` is the thread's end at the root (X the root radius); `height` the thread depth
    (radius); `taper` the radius difference start - end (Fanuc R i); `angle_deg` the tool
    angle: each pass starts (height - depth) x tan(angle/2) back towards A, so the tool
    feeds along one flank and is on the programmed thread at full depth (`alternate`: the
    flanks take turns, Haas P2/P4); `chamfer` the pull-out length at the end (45 degrees).
    """
    x0, z0 = start
    xe, ze = end
    s = 1.0 if xe < x0 else -1.0  # +1: outside thread (crest above the root)
    zdir = -1.0 if ze < z0 else 1.0
    tan_half = math.tan(math.radians(angle_deg) / 2.0)
    moves: list[Move] = []
    for i, d in enumerate(depths):
        x = xe + s * (height - d)
        back = (height - d) * tan_half
        if alternate and i % 2:
            back = -back
        zs = z0 - zdir * back
        if abs(zs - z0) > TOL:
            moves.append(mv(RAPID, (x0, zs)))
        moves.append(mv(RAPID, (x + taper, zs)))
        moves.extend(_thread_cut((x + taper, zs), (x, ze), chamfer, s, zdir))
        moves.append(mv(RAPID, (x0, ze)))
        moves.append(mv(RAPID, (x0, z0)))
    return moves


def _thread_cut(a: Pt, b: Pt, chamfer: float, s: float, zdir: float) -> list[Move]:
    if chamfer <= TOL:
        return [mv(THREAD, b)]
    length = abs(b[1] - a[1])
    c = min(chamfer, length)
    t = (length - c) / length if length > 0 else 0.0
    mid = (a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]))
    return [mv(THREAD, mid), mv(THREAD, (b[0] + s * c, b[1]))]


def single_thread(start: Pt, end: Pt, taper: float = 0.0, chamfer: float = 0.0) -> list[Move]:
    """G92: rapid X to the pass diameter, thread to the end, rapid out to x0, back to z0."""
    x0, z0 = start
    xe, ze = end
    s = 1.0 if xe < x0 else -1.0
    zdir = -1.0 if ze < z0 else 1.0
    moves = [mv(RAPID, (xe + taper, z0))]
    moves.extend(_thread_cut((xe + taper, z0), end, chamfer, s, zdir))
    moves.append(mv(RAPID, (x0, moves[-1][2])))
    moves.append(mv(RAPID, (x0, z0)))
    return moves


def single_turning(start: Pt, end: Pt, taper: float = 0.0) -> list[Move]:
    """G90: rapid X to x + i, feed to the end point (x, z), feed out to x0, rapid to z0."""
    x0, z0 = start
    xe, ze = end
    return [
        mv(RAPID, (xe + taper, z0)),
        mv(FEED, (xe, ze)),
        mv(FEED, (x0, ze)),
        mv(RAPID, (x0, z0)),
    ]


def single_facing(start: Pt, end: Pt, taper: float = 0.0) -> list[Move]:
    """G94: rapid Z to z + k, feed to the end point (x, z), feed back to z0, rapid to x0."""
    x0, z0 = start
    xe, ze = end
    return [
        mv(RAPID, (x0, ze + taper)),
        mv(FEED, (xe, ze)),
        mv(FEED, (xe, z0)),
        mv(RAPID, (x0, z0)),
    ]
