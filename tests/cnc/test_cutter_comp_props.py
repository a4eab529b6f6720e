"""Property tests for cutter radius compensation.

Tolerance: a compensated point must lie at distance r from the programmed contour within
TOL_REL * scale, scale = max(1, r, largest |coordinate|), TOL_REL = 3e-9. That covers float
rounding (~1e-15 * scale per operation) and the shallow-corner stand-off of at most
1.25e-9 * r (geometry.SHALLOW_ANGLE).
"""

from __future__ import annotations

import math

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from cnc.cutter_comp import CutterCompensation, Segment
from cnc.errors import NcError

TOL_REL = 3e-9
SETTINGS = settings(
    max_examples=150,
    deadline=None,
    derandomize=True,  # the project wants deterministic tests: a fixed example sequence
    suppress_health_check=[HealthCheck.too_slow],
)


def seg_dist(p, a, b):
    ax, ay = b[0] - a[0], b[1] - a[1]
    den = ax * ax + ay * ay
    t = 0.0 if den == 0 else max(0.0, min(1.0, ((p[0] - a[0]) * ax + (p[1] - a[1]) * ay) / den))
    return math.hypot(p[0] - a[0] - t * ax, p[1] - a[1] - t * ay)


def samples(s: Segment, n: int = 4):
    """Points along an output segment: its ends and n-1 interior points."""
    if s.kind == "line":
        return [
            (
                s.start[0] + (s.end[0] - s.start[0]) * k / n,
                s.start[1] + (s.end[1] - s.start[1]) * k / n,
            )
            for k in range(n + 1)
        ]
    c = s.center
    rad = math.dist(s.start, c)
    a0 = math.atan2(s.start[1] - c[1], s.start[0] - c[0])
    a1 = math.atan2(s.end[1] - c[1], s.end[0] - c[0])
    sweep = (a1 - a0) % (2 * math.pi) if s.ccw else -((a0 - a1) % (2 * math.pi))
    if s.start == s.end:
        sweep = 2 * math.pi if s.ccw else -2 * math.pi
    pts = [c[0] + rad * math.cos(a0 + sweep * k / n) for k in range(n + 1)]
    return (
        [s.start]
        + [(pts[k], c[1] + rad * math.sin(a0 + sweep * k / n)) for k in range(1, n)]
        + [s.end]
    )


def drive(side, r, segs, cancel, lookahead=3):
    cc = CutterCompensation(lookahead=lookahead)
    cc.start(side, r)
    out = []
    for s in segs:
        out += cc.push(s)
    cc.cancel()
    out += cc.push(cancel)
    out += cc.flush()
    assert not cc.active
    return out


def check_continuous_and_payloads(out, first, last, n_inputs):
    assert out[0].start == first and out[-1].end == last
    for prev, nxt in zip(out, out[1:], strict=False):
        assert nxt.start == prev.end
    order = [s.payload for s in out]
    assert order == sorted(order), "output out of program order"
    assert set(order) == set(range(n_inputs)), "a payload was lost"


def with_plunges(points_path, plunge_after):
    """Lines along `points_path` with zero-length segments after the chosen indexes."""
    segs = []
    for i, (a, b) in enumerate(zip(points_path, points_path[1:], strict=False)):
        segs.append(("line", a, b))
        if i in plunge_after:
            segs.append(("line", b, b))
    return segs


def number(specs, startup, cancel):
    """Segments with payload = input index (0 start-up ... last = cancel) and line = index+1."""
    allspecs = [startup, *specs, cancel]
    segs = []
    for i, sp in enumerate(allspecs):
        if sp[0] == "line":
            segs.append(Segment("line", sp[1], sp[2], None, False, i + 1, 1, i))
        else:
            segs.append(Segment("arc", sp[1], sp[2], sp[3], sp[4], i + 1, 1, i))
    return segs


# ------------------------------------------------------------------------ convex polygons

polygons = st.fixed_dictionaries(
    {
        "angles": st.lists(
            st.floats(0, 2 * math.pi, exclude_max=True), min_size=3, max_size=10, unique=True
        ),
        "rho": st.floats(1.0, 200.0),
        "cx": st.floats(-500.0, 500.0),
        "cy": st.floats(-500.0, 500.0),
        "ccw": st.booleans(),
        "side": st.sampled_from(["left", "right"]),
        "r_frac": st.one_of(st.just(0.0), st.floats(0.0, 1.5)),
        "plunges": st.sets(st.integers(0, 12), max_size=4),
    }
)


@SETTINGS
@given(polygons)
def test_convex_polygon_offsets_at_tool_radius(p):
    angles = sorted(p["angles"])
    gaps = [(angles[(i + 1) % len(angles)] - angles[i]) % (2 * math.pi) for i in range(len(angles))]
    assume(min(gaps) > 1e-3 and max(gaps) < math.pi - 1e-3)  # a proper convex polygon
    c, rho = (p["cx"], p["cy"]), p["rho"]
    verts = [(c[0] + rho * math.cos(a), c[1] + rho * math.sin(a)) for a in angles]
    if not p["ccw"]:
        verts.reverse()
    n = len(verts)
    r = p["r_frac"] * rho
    inside = (p["side"] == "left") == p["ccw"]
    mid = ((verts[0][0] + verts[1][0]) / 2, (verts[0][1] + verts[1][1]) / 2)
    path = [mid, *verts[1:], verts[0], mid]
    q = c if inside else (mid[0] + 2 * (mid[0] - c[0]), mid[1] + 2 * (mid[1] - c[1]))
    specs = with_plunges(path, p["plunges"])
    segs = number(specs, ("line", q, mid), ("line", mid, q))
    scale = max(1.0, r, *(abs(v) for pt in [*path, q] for v in pt))
    tol = TOL_REL * scale

    # Oracle for the inside offset of a convex polygon: each element keeps a positive
    # length after r*tan(turn/2) is trimmed at each of its corners.
    def turn(i):  # exterior angle at vertex i
        a, b, d = verts[i - 1], verts[i], verts[(i + 1) % n]
        u, v = (b[0] - a[0], b[1] - a[1]), (d[0] - b[0], d[1] - b[1])
        return math.atan2(abs(u[0] * v[1] - u[1] * v[0]), u[0] * v[0] + u[1] * v[1])

    trims = [r * math.tan(turn(i) / 2) for i in range(n)] if inside else [0.0] * n
    slack = [math.dist(mid, verts[1]) - trims[1]]
    slack += [math.dist(verts[i], verts[i + 1]) - trims[i] - trims[i + 1] for i in range(1, n - 1)]
    slack += [math.dist(verts[n - 1], verts[0]) - trims[n - 1] - trims[0]]
    slack += [math.dist(verts[0], mid) - trims[0]]
    assume(all(abs(s) > 1e-6 * scale for s in slack))
    if min(slack) < 0:
        with pytest.raises(NcError, match="gouge"):
            drive(p["side"], r, segs[:-1], segs[-1])
        return

    out = drive(p["side"], r, segs[:-1], segs[-1])
    check_continuous_and_payloads(out, q, q, len(segs))
    edges = list(zip(verts, verts[1:] + verts[:1], strict=True))
    for s in out:
        if s.role in ("startup", "cancel"):
            continue
        for pt in samples(s):
            d = min(seg_dist(pt, a, b) for a, b in edges)
            assert abs(d - r) <= tol, (s, pt, d, r)
            if r > tol:
                crosses = [
                    (b[0] - a[0]) * (pt[1] - a[1]) - (b[1] - a[1]) * (pt[0] - a[0])
                    for a, b in edges
                ]
                is_in = all(x > 0 for x in crosses) or all(x < 0 for x in crosses)
                assert is_in == inside, (s, pt)


# ------------------------------------------------------------------------------- circles

circles = st.fixed_dictionaries(
    {
        "rho": st.floats(0.5, 300.0),
        "cx": st.floats(-500.0, 500.0),
        "cy": st.floats(-500.0, 500.0),
        "phi0": st.floats(-math.pi, math.pi),
        "pieces": st.integers(1, 5),
        "ccw": st.booleans(),
        "side": st.sampled_from(["left", "right"]),
        "r_frac": st.floats(0.0, 2.0),
    }
)


@SETTINGS
@given(circles)
def test_circle_offsets_at_tool_radius(p):
    c, rho, k = (p["cx"], p["cy"]), p["rho"], p["pieces"]
    sgn = 1 if p["ccw"] else -1
    pts = [
        (
            c[0] + rho * math.cos(p["phi0"] + sgn * 2 * math.pi * i / k),
            c[1] + rho * math.sin(p["phi0"] + sgn * 2 * math.pi * i / k),
        )
        for i in range(k)
    ]
    pts.append(pts[0])
    r = p["r_frac"] * rho
    inside = (p["side"] == "left") == p["ccw"]
    start = pts[0]
    q = c if inside else (c[0] + 3 * (start[0] - c[0]), c[1] + 3 * (start[1] - c[1]))
    specs = [("arc", a, b, c, p["ccw"]) for a, b in zip(pts, pts[1:], strict=False)]
    segs = number(specs, ("line", q, start), ("line", start, q))
    scale = max(1.0, r, *(abs(v) for pt in [*pts, q, c] for v in pt))
    tol = TOL_REL * scale
    if inside:
        assume(abs(rho - r) > 1e-6 * scale)
        if r > rho:
            with pytest.raises(NcError, match="gouge"):
                drive(p["side"], r, segs[:-1], segs[-1])
            return
    out = drive(p["side"], r, segs[:-1], segs[-1])
    check_continuous_and_payloads(out, q, q, len(segs))
    assert [s.role for s in out[1:-1]] == ["contour"] * k  # all junctions are tangent
    for s in out[1:-1]:
        assert s.ccw == p["ccw"]
        for pt in samples(s):
            d = math.dist(pt, c)
            assert abs(abs(d - rho) - r) <= tol
            if r > tol:
                assert (d < rho) == inside


# ---------------------------------------------------- random open contours: local invariants

steps = st.lists(
    st.one_of(
        st.tuples(st.just("line"), st.floats(-50, 50), st.floats(-50, 50)),
        st.tuples(
            st.just("arc"),
            st.floats(-30, 30),
            st.floats(-30, 30),
            st.builds(lambda a, ccw: a if ccw else -a, st.floats(1e-3, 2 * math.pi), st.booleans()),
        ),
        st.tuples(st.just("zero"), st.just(0.0), st.just(0.0)),
    ),
    min_size=1,
    max_size=12,
)


@SETTINGS
@given(steps, st.sampled_from(["left", "right"]), st.floats(-5.0, 5.0))
def test_random_contours_either_refuse_or_stay_on_their_offsets(moves, side, radius):
    p = (0.0, 0.0)
    specs = []
    for m in moves:
        if m[0] == "line":
            nxt = (p[0] + m[1], p[1] + m[2])
            assume(math.dist(p, nxt) > 1e-3)
            specs.append(("line", p, nxt))
        elif m[0] == "zero":
            specs.append(("line", p, p))
            nxt = p
        else:
            c = (p[0] + m[1], p[1] + m[2])
            rad = math.dist(p, c)
            assume(rad > 1e-3)
            a = math.atan2(p[1] - c[1], p[0] - c[0]) + m[3]
            nxt = (c[0] + rad * math.cos(a), c[1] + rad * math.sin(a))
            assume(math.dist(p, nxt) > 1e-6)  # full circles are covered elsewhere
            specs.append(("arc", p, nxt, c, m[3] > 0))
        p = nxt
    q = (-20.0, -20.0)
    segs = number(specs, ("line", q, (0.0, 0.0)), ("line", p, q))
    try:  # local checks only, so that most random contours get through
        out = drive(side, radius, segs[:-1], segs[-1], lookahead=0)
    except NcError as e:
        assert e.message.startswith("cutter compensation") and 1 <= e.line <= len(segs)
        return
    check_continuous_and_payloads(out, q, q, len(segs))
    r = abs(radius)
    scale = max(1.0, r, *(abs(v) for sp in specs for pt in sp[1:3] for v in pt))
    # every contour point sits at distance r from the supporting line/circle of its own
    # programmed element; every corner arc point at distance r from its programmed corner
    for s in out:
        if s.role in ("startup", "cancel"):
            continue
        src = segs[s.payload]
        for pt in samples(s):
            if s.role == "corner":
                d = math.dist(pt, src.start)
            elif src.start == src.end and src.kind == "line":
                continue  # zero-length: placed at the tool position, checked by continuity
            elif src.kind == "line":
                ux, uy = src.end[0] - src.start[0], src.end[1] - src.start[1]
                d = abs(ux * (pt[1] - src.start[1]) - uy * (pt[0] - src.start[0])) / math.hypot(
                    ux, uy
                )
            else:
                d = abs(math.dist(pt, src.center) - math.dist(src.start, src.center))
            assert abs(d - r) <= 1e-8 * scale, (s, src, pt, d, r)


@SETTINGS
@given(
    st.sampled_from([1e-7, 1e-6, 1e-5, 5e-5, 9.9e-5, 1.01e-4, 3e-4, 1e-3, 1e-2, 0.3]),
    st.booleans(),
    st.sampled_from(["left", "right"]),
    st.floats(0.01, 50.0),
    st.floats(-math.pi, math.pi),
)
def test_shallow_corners_stay_within_tolerance(turn, left_turn, side, r, heading):
    # Two lines meeting at a tiny angle: below SHALLOW_ANGLE the outside corner is extended
    # to the intersection; its stand-off beyond r must stay inside the stated tolerance.
    turn = turn if left_turn else -turn
    d0 = (math.cos(heading), math.sin(heading))
    d1 = (math.cos(heading + turn), math.sin(heading + turn))
    a, b = (-30 * d0[0], -30 * d0[1]), (0.0, 0.0)
    e = (30 * d1[0], 30 * d1[1])
    q = (a[0] - 60 * d0[1], a[1] + 60 * d0[0])
    segs = number([("line", a, b), ("line", b, e)], ("line", q, a), ("line", e, q))
    out = drive(side, r, segs[:-1], segs[-1])
    check_continuous_and_payloads(out, q, q, len(segs))
    tol = TOL_REL * max(1.0, r, 30.0, *map(abs, q))
    for s in out:
        if s.role not in ("startup", "cancel"):
            for pt in samples(s):
                assert abs(min(seg_dist(pt, a, b), seg_dist(pt, b, e)) - r) <= tol, (s, pt)


# ------------------------------------------------------- exact distances vs dense sampling

pts = st.tuples(st.floats(-20, 20), st.floats(-20, 20))


@st.composite
def elements(draw):
    a = draw(pts)
    if draw(st.booleans()):
        b = draw(pts)
        assume(math.dist(a, b) > 1e-3)
        return ("line", a, b)
    c = draw(pts)
    rad = math.dist(a, c)
    assume(rad > 1e-2)
    sweep = draw(st.floats(1e-2, 2 * math.pi)) * draw(st.sampled_from([1, -1]))
    a0 = math.atan2(a[1] - c[1], a[0] - c[0])
    b = (c[0] + rad * math.cos(a0 + sweep), c[1] + rad * math.sin(a0 + sweep))
    full = abs(abs(sweep) - 2 * math.pi) < 1e-9
    return ("arc", a, a if full else b, c, sweep > 0)


def as_shape(e):
    from cnc.cutter_comp.interference import Arc

    if e[0] == "line":
        return (e[1], e[2])
    return Arc.of(e[1], e[2], e[3], e[4], e[1] == e[2])


def dense(e, n=400):
    s = Segment(e[0], e[1], e[2], e[3] if e[0] == "arc" else None, e[0] == "arc" and e[4], 0, 0)
    return samples(s, n)


@SETTINGS
@given(elements(), elements())
def test_exact_distance_agrees_with_dense_sampling(e, f):
    from cnc.cutter_comp.interference import distance

    d = distance(as_shape(e), as_shape(f))
    pe, pf = dense(e), dense(f)
    # sampled pairs can only be farther apart; with 400 samples of elements at most ~250 long
    # the sampled minimum exceeds the true one by at most half a sample spacing each side
    sampled = min(math.dist(p, q) for p in pe for q in pf[::8])
    sampled = min(sampled, min(math.dist(p, q) for p in pe[::8] for q in pf))
    assert d <= sampled + 1e-9
    spacing = max(
        max(math.dist(a, b) for a, b in zip(pe, pe[1:], strict=False)),
        max(math.dist(a, b) for a, b in zip(pf, pf[1:], strict=False)),
    )
    assert sampled - d <= 8 * spacing + 1e-9


# ------------------------------------------- interference window: two-sided sampled oracle


def point_element(pt, sp):
    """Exact distance from a point to a programmed line or arc (independent of the module)."""
    if sp[0] == "line":
        return seg_dist(pt, sp[1], sp[2])
    _, a, b, c, ccw = sp
    rad = math.dist(a, c)
    a0 = math.atan2(a[1] - c[1], a[0] - c[0])
    a1 = math.atan2(b[1] - c[1], b[0] - c[0])
    sweep = ((a1 - a0) if ccw else (a0 - a1)) % (2 * math.pi) or 2 * math.pi
    ang = math.atan2(pt[1] - c[1], pt[0] - c[0])
    rel = ((ang - a0) if ccw else (a0 - ang)) % (2 * math.pi)
    if rel <= sweep:
        return abs(math.dist(pt, c) - rad)
    return min(math.dist(pt, a), math.dist(pt, b))


def arc_length(s: Segment) -> float:
    if s.kind == "line":
        return math.dist(s.start, s.end)
    pts = samples(s, 64)
    return sum(math.dist(a, b) for a, b in zip(pts, pts[1:], strict=False)) * 1.001


@SETTINGS
@given(steps, st.sampled_from(["left", "right"]), st.floats(0.05, 5.0))
def test_interference_window_agrees_with_a_sampled_oracle(moves, side, radius):
    # Distance to a fixed element is 1-Lipschitz along the tool path, so n samples of a
    # compensated segment of length l bound its true minimum distance within l/(2n). If every
    # sample of every segment keeps r + l/(2n) + eps from its own programmed element and the
    # 3 after it (the read-ahead), the window check must accept; if some sample comes closer
    # than r - eps, it must refuse.
    p = (0.0, 0.0)
    specs = []
    for m in moves:
        if m[0] == "line":
            nxt = (p[0] + m[1], p[1] + m[2])
            assume(math.dist(p, nxt) > 1e-3)
            specs.append(("line", p, nxt))
        elif m[0] == "arc":
            c = (p[0] + m[1], p[1] + m[2])
            rad = math.dist(p, c)
            assume(rad > 1e-3)
            a = math.atan2(p[1] - c[1], p[0] - c[0]) + m[3]
            nxt = (c[0] + rad * math.cos(a), c[1] + rad * math.sin(a))
            assume(math.dist(p, nxt) > 1e-6)
            specs.append(("arc", p, nxt, c, m[3] > 0))
        else:
            continue
        p = nxt
    assume(specs)
    q = (-20.0, -20.0)
    segs = number(specs, ("line", q, (0.0, 0.0)), ("line", p, q))
    try:
        local = drive(side, radius, segs[:-1], segs[-1], lookahead=0)
    except NcError:
        assume(False)
    scale = max(1.0, radius, *(abs(v) for sp in specs for pt in sp[1:3] for v in pt))
    eps = 1e-6 * scale
    n = 32
    clear, hit = True, False
    for s in local:
        if s.role in ("startup", "cancel") or (s.kind == "line" and s.start == s.end):
            continue
        slack = arc_length(s) / (2 * n)
        for k in range(max(1, s.payload), min(len(specs), s.payload + 3) + 1):
            d = min(point_element(pt, specs[k - 1]) for pt in samples(s, n))
            clear = clear and d >= radius + slack + eps
            hit = hit or d < radius - eps
    if clear:
        assert drive(side, radius, segs[:-1], segs[-1]) == local
    elif hit:
        with pytest.raises(NcError, match="gouge"):
            drive(side, radius, segs[:-1], segs[-1])


# ------------------------------------------------------------- random API call sequences

_start = st.tuples(
    st.just("start"), st.sampled_from(["left", "right"]), st.sampled_from([-2.0, 0.0, 0.5, 2.0])
)
_line = st.tuples(st.just("line"), st.integers(-20, 20), st.integers(-20, 20))
_arc = st.tuples(st.just("arc"), st.integers(-10, 10), st.integers(-10, 10), st.integers(-300, 300))
_other = st.sampled_from([("cancel",), ("flush",), ("zero",), ("restart",)])
ops = st.builds(
    lambda first, lead, body: [first, lead, *body],
    _start,
    _line,
    st.lists(st.one_of(_line, _line, _line, _arc, _arc, _other, _other), min_size=3, max_size=30),
)


@SETTINGS
@given(ops, st.integers(0, 3))
def test_any_call_sequence_is_continuous_or_a_clean_error(seq, lookahead):
    # Whatever order the interpreter calls in, the output stream is one continuous path that
    # starts at the program's start, carries every payload once or more in program order,
    # and any refusal is an NcError with a source position.
    cc = CutterCompensation(lookahead=lookahead)
    p = (0.0, 0.0)
    out = []
    pushed = 0
    try:
        for op in seq:
            if op[0] == "start":
                cc.start(op[1], op[2], line=pushed + 1, col=1)
            elif op[0] == "restart":  # G41/G42 again with the first block's side and D
                cc.start(seq[0][1], seq[0][2], line=pushed + 1, col=1)
            elif op[0] == "cancel":
                cc.cancel()
            elif op[0] == "flush":
                out += cc.flush()
            else:
                if op[0] == "line":
                    nxt, seg = (p[0] + op[1], p[1] + op[2]), None
                    seg = Segment("line", p, nxt, None, False, pushed + 1, 1, pushed)
                elif op[0] == "zero":
                    nxt = p
                    seg = Segment("line", p, p, None, False, pushed + 1, 1, pushed)
                else:
                    c = (p[0] + op[1], p[1] + op[2])
                    if c == p:
                        continue
                    rad = math.dist(p, c)
                    ang = math.atan2(p[1] - c[1], p[0] - c[0]) + math.radians(op[3])
                    nxt = (c[0] + rad * math.cos(ang), c[1] + rad * math.sin(ang))
                    seg = Segment("arc", p, nxt, c, op[3] > 0, pushed + 1, 1, pushed)
                out += cc.push(seg)
                pushed += 1
                p = nxt
        out += cc.flush()
    except NcError as e:
        assert e.message.startswith("cutter compensation") and 1 <= e.line <= pushed + 1
        return
    if not out:
        return
    assert out[0].start == (0.0, 0.0)
    for prev, nxt in zip(out, out[1:], strict=False):
        assert math.dist(nxt.start, prev.end) <= 1e-9 * 100, (prev, nxt)
    order = [s.payload for s in out]
    assert order == sorted(order) and set(order) == set(range(pushed))
