"""Look-ahead velocity planning over the path: spans, backward/forward passes, S-curves.

The path from the current point to the next stop is cut into *spans*: runs of pieces
whose speed caps agree within SPAN_RATIO and whose junctions allow that speed. The path
acceleration is zero at every span boundary, so each span gets its own closed-form
S-curve (jerk-limited change, cruise, jerk-limited change) with the smallest tangential
limits of its pieces. A backward pass finds the highest entry speed from which every
later cap can still be met; a forward pass takes the highest speed reachable from the
current state.
"""

from __future__ import annotations

from bisect import bisect_left
from math import sqrt
from typing import Final

from cnc.planner.native import mypyc_attr
from cnc.planner.path import Segment
from cnc.planner.scurve import change_distance, change_phases, min_reach, reach

SPAN_RATIO: Final = 0.95
INF: Final = float("inf")
# The S-curve reach results are memoised only when this module runs as Python: compiled,
# `reach` costs less than hashing its four floats into a dict key (same results either way).
REACH_MEMO: Final = __file__.endswith(".py")

Row = tuple[float, float, float, float, float, float]  # (t0, dt, s, v, a, j) of a phase


@mypyc_attr(acyclic=True)
class Part:
    """One stretch of the path planned as one span, as `partition` cuts it.

    `vmax`/`vmax_hi` are the lowest and highest speed caps of its pieces, `at`/`jt` their
    smallest tangential limits, `end_cap` the speed allowed at its end junction, `stop`
    whether it ends at rest, `coast_cap` the end junction's cap when passed in a coast and
    `coast_in`/`coast_out` whether its ends are coasts.
    """

    __slots__ = (
        "s0",
        "s1",
        "vmax",
        "vmax_hi",
        "at",
        "jt",
        "end_cap",
        "stop",
        "coast_cap",
        "coast_in",
        "coast_out",
        "eff",
        "v_back",
    )

    s0: float
    s1: float
    vmax: float
    vmax_hi: float
    at: float
    jt: float
    end_cap: float
    stop: bool
    coast_cap: float
    coast_in: bool
    coast_out: bool
    # scratch of `solve`: the length without coasts, the backward pass's start speed
    eff: float
    v_back: float

    def __init__(self, s0: float, s1: float, vmax: float, at: float, jt: float) -> None:
        self.s0 = s0
        self.s1 = s1
        self.vmax = vmax
        self.vmax_hi = vmax
        self.at = at
        self.jt = jt
        self.end_cap = 0.0
        self.stop = False
        self.coast_cap = 0.0
        self.coast_in = False
        self.coast_out = False
        self.eff = 0.0
        self.v_back = 0.0

    def copy(self) -> Part:
        p = Part(self.s0, self.s1, self.vmax, self.at, self.jt)
        p.vmax_hi = self.vmax_hi
        p.end_cap = self.end_cap
        p.stop = self.stop
        p.coast_cap = self.coast_cap
        p.coast_in = self.coast_in
        p.coast_out = self.coast_out
        return p

    def as_list(self) -> list:
        """[s0, s1, vmax, vmax_hi, at, jt, end_cap, stop, coast_cap, coast_in, coast_out]"""
        return [
            self.s0,
            self.s1,
            self.vmax,
            self.vmax_hi,
            self.at,
            self.jt,
            self.end_cap,
            self.stop,
            self.coast_cap,
            self.coast_in,
            self.coast_out,
        ]

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Part):
            return NotImplemented
        return self.as_list() == other.as_list()

    def __repr__(self) -> str:
        return f"Part({self.as_list()!r})"


@mypyc_attr(acyclic=True)
class PlanMemo:
    """What one plan leaves for the next (see `solve` and `partition_again`): its parts,
    its spans and its S-curve reach results, each by what it depends on."""

    __slots__ = ("spans", "reach", "part_key", "part_raw", "part_ends")

    spans: dict[float, Span]  # by start position; the other inputs are checked on the span
    reach: dict[tuple[float, float, float, float], float]
    part_key: tuple[float, float] | None
    part_raw: list[Part]
    part_ends: dict[float, int]

    def __init__(self) -> None:
        self.spans = {}
        self.reach = {}
        # the parts of the last partition_again (before coasts), by their end position
        self.part_key = None
        self.part_raw = []
        self.part_ends = {}


@mypyc_attr(acyclic=True)
class Span:
    """One planned stretch [s0, s1] of the path: phases (t0, dt, s, v, a, j), s relative."""

    __slots__ = (
        "s0",
        "s1",
        "phases",
        "dur",
        "v0",
        "v1",
        "stop",
        "vmax",
        "jerk_limit",
        "single_block_stop",
        "coast_in_t",
        "coast_out_t",
        "accel_limit",
        "room",
        "reserve_out",
        "fits",
    )

    s0: float
    s1: float
    phases: list[Row]
    dur: float
    v0: float
    v1: float
    stop: bool
    vmax: float
    jerk_limit: float
    single_block_stop: bool
    coast_in_t: float
    coast_out_t: float
    accel_limit: float  # the tangential acceleration limit it was planned with
    room: float  # the length its speed changes were planned in (see `_span`)
    reserve_out: float  # the length kept at its end for a coast at the end junction's cap
    fits: bool  # its phases cover no more than its length (else a plan is infeasible)

    def __init__(
        self,
        s0: float,
        s1: float,
        phases: list[Row],
        dur: float,
        v0: float,
        v1: float,
        stop: bool,
        vmax: float,
        jerk_limit: float = 0.0,
    ) -> None:
        self.s0 = s0
        self.s1 = s1
        self.phases = phases
        self.dur = dur
        self.v0 = v0
        self.v1 = v1
        self.stop = stop
        self.vmax = vmax
        self.jerk_limit = jerk_limit
        self.single_block_stop = False
        self.coast_in_t = 0.0  # leading/trailing constant-speed time around a junction
        self.coast_out_t = 0.0
        self.accel_limit = 0.0
        self.room = 0.0
        self.reserve_out = 0.0
        self.fits = True

    def state(self, t: float, hint: int = 0) -> tuple[float, float, float, int]:
        """(s, v, a, phase index) at time t into the span; s is absolute and clamped."""
        ph = self.phases
        i = hint
        n = len(ph)
        while i + 1 < n and t >= ph[i + 1][0]:
            i += 1
        t0, _dt, s, v, a, j = ph[i]
        x = t - t0
        sa = s + x * (v + x * (0.5 * a + x * j / 6.0))
        va = v + x * (a + 0.5 * j * x)
        aa = a + j * x
        length = self.s1 - self.s0
        if sa > length:
            sa = length
        elif sa < 0.0:
            sa = 0.0
        return self.s0 + sa, va, aa, i


@mypyc_attr(acyclic=True, free_list_len=1)
class _Rows:
    """Phases (dt, jerk) integrated into rows (t0, dt, s, v, a, j) as they are made, times
    and s relative to the span start: no list of phases in between."""

    __slots__ = ("rows", "tt", "ss", "vv", "aa")

    rows: list[Row]
    tt: float
    ss: float
    vv: float
    aa: float

    def __init__(self, v: float) -> None:
        self.rows = []
        self.tt = self.ss = self.aa = 0.0
        self.vv = v

    def add(self, dt: float, j: float) -> None:
        if dt <= 0.0:
            return
        vv, aa = self.vv, self.aa
        self.rows.append((self.tt, dt, self.ss, vv, aa, j))
        self.ss += dt * (vv + dt * (0.5 * aa + dt * j / 6.0))
        self.vv = vv + dt * (aa + 0.5 * j * dt)
        self.aa = aa + j * dt
        self.tt += dt

    def change(self, va: float, vb: float, a: float, j: float) -> None:
        """The phases of scurve.change_phases(va, vb, a, j), in order."""
        if vb == va:
            return
        sj = j if vb > va else -j
        dv = vb - va if vb > va else va - vb
        if dv * j >= a * a:
            t1 = a / j
            t2 = dv / a - t1
            self.add(t1, sj)
            if t2 > 0.0:
                self.add(t2, 0.0)
            self.add(t1, -sj)
            return
        t1 = sqrt(dv / j)
        self.add(t1, sj)
        self.add(t1, -sj)


def span_phases(
    v0: float, v1: float, vmax: float, length: float, at: float, jt: float
) -> tuple[list[tuple[float, float]], float]:
    """(dt, jerk) phases covering `length` from v0 to v1 under vmax; returns peak too."""
    vp, cruise = _span_peak(v0, v1, vmax, length, at, jt)
    phases = change_phases(v0, vp, at, jt)
    if cruise > 0.0 and vp > 0.0:
        phases.append((cruise / vp, 0.0))
    phases += change_phases(vp, v1, at, jt)
    return phases, vp


def _span_peak(
    v0: float, v1: float, vmax: float, length: float, at: float, jt: float
) -> tuple[float, float]:
    """Peak speed and cruise length of the span_phases profile."""
    if v0 <= vmax:
        lo = v0 if v0 > v1 else v1
    else:
        lo = v1  # starting above the cap (override lowered): brake first
    hi = vmax
    d1 = change_distance(v0, hi, at, jt)
    d2 = change_distance(hi, v1, at, jt)
    if d1 + d2 <= length or lo >= hi:
        vp = hi
    else:
        vp = _peak_acc_limited(v0, v1, length, at, jt)
        if lo <= vp <= hi:
            d1 = change_distance(v0, vp, at, jt)
            d2 = change_distance(vp, v1, at, jt)
        else:
            vp, d1, d2 = _peak_search(v0, v1, length, at, jt, lo, hi, d1 + d2 - length)
    return vp, length - d1 - d2


def _peak_acc_limited(v0: float, v1: float, length: float, a: float, j: float) -> float:
    """Peak speed when both changes reach the acceleration limit (closed form), else -1.

    (vp^2 - v0^2)/(2a) + (vp^2 - v1^2)/(2a) + a/(2j) (2 vp + v0 + v1) = length.
    """
    aj = a * a / j
    qa = 1.0 / a
    qb = a / j
    qc = -(v0 * v0 + v1 * v1) / (2.0 * a) + 0.5 * qb * (v0 + v1) - length
    disc = qb * qb - 4.0 * qa * qc
    if disc < 0.0:
        return -1.0
    vp = (-qb + sqrt(disc)) / (2.0 * qa)
    if vp - v0 < aj or vp - v1 < aj:
        return -1.0
    # the closed form may land a rounding step past the length: nudge down if so
    while change_distance(v0, vp, a, j) + change_distance(vp, v1, a, j) > length and vp > 0:
        vp *= 1.0 - 1e-15
    return vp


def _peak_search(
    v0: float,
    v1: float,
    length: float,
    at: float,
    jt: float,
    lo: float,
    hi: float,
    fhi: float,
) -> tuple[float, float, float]:
    """Largest vp in [lo, hi] with both changes fitting `length` (Illinois regula falsi).

    `fhi` is the excess length at hi (the caller has it). Returns vp and the lengths of
    the two changes at vp. The returned side always fits; whatever length is left is
    cruised at vp, so the profile covers `length` exactly and a 1e-6 shortfall only costs
    that much speed.
    """
    d1 = change_distance(v0, lo, at, jt)
    d2 = change_distance(lo, v1, at, jt)
    flo = d1 + d2 - length
    side = 0
    for _ in range(100):
        if hi - lo <= 1e-12 * hi or -flo <= 1e-6 * length:
            break
        x = hi - fhi * (hi - lo) / (fhi - flo) if fhi != flo else 0.5 * (lo + hi)
        if not lo < x < hi:
            x = 0.5 * (lo + hi)
        x1 = change_distance(v0, x, at, jt)
        x2 = change_distance(x, v1, at, jt)
        fx = x1 + x2 - length
        if fx <= 0.0:
            lo, flo, d1, d2 = x, fx, x1, x2
            if side == -1:
                fhi *= 0.5
            side = -1
        else:
            hi, fhi = x, fx
            if side == 1:
                flo *= 0.5
            side = 1
        if fx == 0.0:
            break
    return lo, d1, d2


def _span(
    s0: float,
    s1: float,
    vmax: float,
    at: float,
    jt: float,
    v: float,
    v1: float,
    cin: float,
    cout: float,
    stop: bool,
    room: float,
    reserve_out: float,
) -> Span:
    """The S-curve of one part: from v to v1 under vmax, coasts of cin/cout seconds.

    The speed changes are planned within `room`, the length `solve` left for them (the
    part without the lengths reserved for its coasts at the junctions' caps), not within
    all that the coasts at the actual speeds leave: a re-plan that starts inside this
    span counts the same reserve for the coast at its end, so every state this span
    passes through can still meet v1 in the new plan's accounting (a stoppable tail; see
    docs/motion.md, Re-planning). What the coasts leave over is run at constant speed:
    up to `reserve_out` minus the end coast at v1 just before that coast, the rest in
    the cruise.
    """
    planned_room = room
    middle = s1 - s0 - cin * v - cout * v1
    if middle < 0.0:
        middle = 0.0
    if room > middle or room < 0.0 or v1 <= 0.0:
        room = middle  # (ending at rest: no coast at the end, nothing to keep for it)
    spare = middle - room
    hold = 0.0  # constant v1 before the end coast
    if v1 > 0.0 and spare > 0.0:
        hold = reserve_out - cout * v1
        if hold > spare:
            hold = spare
        elif hold < 0.0:
            hold = 0.0
        if hold > 2.0 * cout * v1:
            # v1 below a third of the reserved coast speed: holding it would crawl for
            # more than 2 coasts; plan the changes in all the length as before (a re-plan
            # inside this span may then find no room and keep this plan, see Motion)
            room = middle
            spare = 0.0
            hold = 0.0
    # the phases of span_phases, integrated into rows as they come
    out = _Rows(v)
    if cin:  # the leading coast: constant speed
        out.rows.append((0.0, cin, 0.0, v, 0.0, 0.0))
        out.ss = cin * v
        out.tt = cin
    vp, cruise = _span_peak(v, v1, vmax, room, at, jt)
    cruise += spare - hold
    out.change(v, vp, at, jt)
    if cruise > 0.0 and vp > 0.0:
        out.add(cruise / vp, 0.0)
    out.change(vp, v1, at, jt)
    if hold > 0.0:
        out.add(hold / v1, 0.0)
    if cout:
        out.add(cout, 0.0)
    rows = out.rows
    if not rows:
        rows = [(0.0, 0.0, 0.0, v, 0.0, 0.0)]
    sp = Span(s0, s1, rows, out.tt, v, v1, stop, vmax, jt)
    sp.coast_in_t = cin
    sp.coast_out_t = cout
    sp.accel_limit = at
    sp.room = planned_room
    sp.reserve_out = reserve_out
    length = s1 - s0
    sp.fits = out.ss <= length + 1e-9 * length + 1e-12
    return sp


def partition(
    segs: list[Segment],
    k: int,
    s_start: float,
    feed_ovr: float,
    rapid_ovr: float,
    single_block: bool,
    stop_s: float | None,
    vclamp: float = INF,
    ipo: float = 0.0,
) -> list[Part]:
    """Cut the path from s_start to the next stop into spans.

    Each item is a `Part`. A boundary at a junction with a tangent or curvature jump is
    passed in a coast (3 IPO cycles of constant speed each side) when that allows a higher
    speed than the junction's share inside a span; each coast may use at most half of a
    span that has a coast at both ends (all of it otherwise), so the spans always hold them.
    """
    out: list[Part] = []
    has_stop = stop_s is not None
    _cut(
        segs,
        k,
        s_start,
        feed_ovr,
        rapid_ovr,
        single_block,
        has_stop,
        stop_s if stop_s is not None else 0.0,
        vclamp,
        ipo,
        out,
        None,
    )
    if ipo > 0.0:
        _coasts(out, ipo)
    return out


def partition_again(
    segs: list[Segment],
    k: int,
    s_start: float,
    feed_ovr: float,
    rapid_ovr: float,
    ipo: float,
    memo: PlanMemo,
    changed_s: float,
    stop_s: float = INF,
) -> list[Part]:
    """`partition(segs, k, s_start, feed_ovr, rapid_ovr, False, stop_s, ipo=ipo)` (no stop
    point when `stop_s` is INF), taking the parts of the previous such call (kept in
    `memo`) where nothing they depend on changed.

    A part that ends at piece e depends on the pieces up to e + 1 (the next speed cap)
    and, once the cut reaches one of its boundaries, not on where the cut began. So the
    cut runs from k until it ends a part where a previous part ended, takes the previous
    parts from there on as long as they end before `changed_s` (the lowest path position
    of a piece changed since, see `Path.changed_s`), and cuts the rest afresh. The result
    equals the full cut (tests/cnc/test_planner_incremental.py).
    """
    raw: list[Part] = []
    key = (feed_ovr, rapid_ovr)
    ends: dict[float, int] | None = memo.part_ends if memo.part_key == key else None
    n = len(segs)
    has_stop = stop_s < INF
    stop_at = stop_s if has_stop else 0.0
    while True:
        hit = _cut(
            segs, k, s_start, feed_ovr, rapid_ovr, False, has_stop, stop_at, INF, ipo, raw, ends
        )
        if hit < 0:
            break
        # the cut met a boundary of the previous cut: take its parts while unchanged (not
        # a part that ended at the previous stop: the stop may have moved on since)
        old = memo.part_raw
        j = hit + 1
        m = len(old)
        while j < m and old[j].s1 < changed_s and not old[j].stop and old[j].s1 < stop_s:
            raw.append(old[j].copy())
            j += 1
        s_next = raw[-1].s1
        k = bisect_left(segs, s_next, key=_seg_start)
        if k >= n:
            break
        s_start = s_next
        ends = None  # cut the rest afresh
    memo.part_key = key
    memo.part_raw = [p.copy() for p in raw]
    memo.part_ends = {p.s1: i for i, p in enumerate(raw) if not p.stop}
    if ipo > 0.0:
        _coasts(raw, ipo)
    return raw


def _seg_start(g: Segment) -> float:
    return g.s0


def _cut(
    segs: list[Segment],
    k: int,
    s_start: float,
    feed_ovr: float,
    rapid_ovr: float,
    single_block: bool,
    has_stop: bool,
    stop_s: float,
    vclamp: float,
    ipo: float,
    out: list[Part],
    ends: dict[float, int] | None,
) -> int:
    """Append the parts from piece k to the next stop to `out` (coasts not decided yet).

    `stop_s` is a stop point when `has_stop`. With `ends` (end position -> index of a part
    of a previous cut), stop after a part that ends where a previous part ended and return
    that index; else return -1.
    """
    cur: Part | None = None
    n = len(segs)
    last = n - 1
    vn = -1.0  # speed cap of segs[k] when already known from the previous step
    while k < n:
        g = segs[k]
        a = s_start if s_start > g.s0 else g.s0
        b = g.s1
        if vn >= 0.0:
            vc = vn
        else:
            vc = g.vcap(feed_ovr, rapid_ovr)
            if vc > vclamp:
                vc = vclamp
        if vc < g.vphys:
            gat, gjt = g.limits_at(vc)
        else:
            gat, gjt = g.at, g.jt
        stop_here = False
        if has_stop and stop_s <= b:
            b = stop_s
            stop_here = True
        if cur is None:
            cur = Part(a, b, vc, gat, gjt)
        else:
            cur.s1 = b
            if vc < cur.vmax:
                cur.vmax = vc
            if vc > cur.vmax_hi:
                cur.vmax_hi = vc
            if gat < cur.at:
                cur.at = gat
            if gjt < cur.jt:
                cur.jt = gjt
        if stop_here or g.stop_end or k == last or (single_block and g.block_last):
            cur.stop = True
            out.append(cur)
            cur = None
            break
        # Segment.vcap written out: this loop runs for every piece of every plan
        h = segs[k + 1]
        if h.rapid:
            vn = h.vphys * rapid_ovr
        else:
            vn = h.feed_v * feed_ovr
            if vn > h.vphys:
                vn = h.vphys
        if vn > vclamp:
            vn = vclamp
        jc = g.jcap_end
        lo = cur.vmax if cur.vmax < vn else vn
        hi = cur.vmax_hi if cur.vmax_hi > vn else vn
        if g.break_end or jc < lo or lo < SPAN_RATIO * hi:
            cur.end_cap = jc if jc < lo else lo
            if g.jump_end and ipo > 0.0:
                jco = g.jcoast
                if jco < 0.0:
                    jco = g.jcoast_end
                cur.coast_cap = jco if jco < lo else lo
            out.append(cur)
            if ends is not None:
                hit = ends.get(b, -1)
                if hit >= 0:
                    return hit
            cur = None
        k += 1
    if cur is not None:
        cur.stop = True
        out.append(cur)
    return -1


def _coasts(parts: list[Part], ipo: float) -> None:
    """Decide which span boundaries are passed in a coast, and at what speed."""
    n = len(parts)
    cand = [p.coast_cap > p.end_cap for p in parts]
    t3 = 3.0 * ipo
    for i in range(n - 1):
        if not cand[i]:
            continue
        left, right = parts[i], parts[i + 1]
        room_l = (left.s1 - left.s0) * (0.5 if i > 0 and cand[i - 1] else 1.0)
        room_r = (right.s1 - right.s0) * (0.5 if cand[i + 1] and not right.stop else 1.0)
        # min(coast_cap, room_l / t3, room_r / t3), written out (builtin min of three is a
        # generic call in the compiled module; the same first-smallest value)
        v = left.coast_cap
        x = room_l / t3
        if x < v:
            v = x
        x = room_r / t3
        if x < v:
            v = x
        if v > left.end_cap:
            left.end_cap = v
            left.coast_out = True
            right.coast_in = True


def solve(
    parts: list[Part], v_start: float, ipo: float = 0.0, memo: PlanMemo | None = None
) -> tuple[list[Span], bool]:
    """Backward and forward passes over the spans, then one S-curve per span.

    The flag is False when the start speed is too high to meet a later cap (the plan then
    brakes as hard as it may and the caller looks for a later stop point).

    `memo` (optional) holds the spans and reach results of the caller's previous plan by
    their inputs; a span with the same part, limits and end speeds is taken from it
    instead of being built again (a span is a pure function of these), and it is refilled
    with this plan's. A re-plan for new blocks at the path end changes only the spans near
    its start and its end, so most come from the memo. Spans handed out must not change.
    """
    n = len(parts)
    ok = True
    if n == 0:
        return [], ok
    t3 = 3.0 * ipo
    # per part: `eff`, its length without the coasts, and `v_back`, the highest speed at
    # its start from which every later cap can be met (kept on the parts: native floats)
    for i in range(n):
        p = parts[i]
        length = p.s1 - p.s0
        if p.coast_in and i > 0:
            length -= t3 * parts[i - 1].end_cap
        if p.coast_out:
            length -= t3 * p.end_cap
        p.eff = length if length > 0.0 else 0.0
    v_end = 0.0 if parts[-1].stop else parts[-1].end_cap
    rmemo: dict[tuple[float, float, float, float], float] | None = None
    smemo: dict[float, Span] | None = None
    rfresh: dict[tuple[float, float, float, float], float] = {}
    fresh: dict[float, Span] = {}
    if memo is not None:
        smemo = memo.spans
        if REACH_MEMO:
            rmemo = memo.reach
    # reach(v, ...) >= v, so when the speed to meet already reaches the caps the caps
    # decide and the S-curve reach need not be computed (most spans of a capped path)
    for i in range(n - 1, -1, -1):
        p = parts[i]
        cap = p.vmax
        if i > 0 and parts[i - 1].end_cap < cap:
            cap = parts[i - 1].end_cap
        v = parts[i + 1].v_back if i + 1 < n else v_end
        if v < cap:
            if rmemo is None:
                v = reach(v, p.eff, p.at, p.jt)
            else:
                rkey = (v, p.eff, p.at, p.jt)
                x = rmemo.get(rkey)
                if x is None:
                    x = reach(v, p.eff, p.at, p.jt)
                rfresh[rkey] = x
                v = x
            if v > cap:
                v = cap
        else:
            v = cap
        p.v_back = v
    spans: list[Span] = []
    v = v_start
    for i in range(n):
        p = parts[i]
        at, jt = p.at, p.jt
        length = p.eff
        v1 = parts[i + 1].v_back if i + 1 < n else v_end
        if v < v1:
            if rmemo is None:
                x = reach(v, length, at, jt)
            else:
                rkey = (v, length, at, jt)
                y = rmemo.get(rkey)
                if y is None:
                    y = reach(v, length, at, jt)
                rfresh[rkey] = y
                x = y
            if x < v1:
                v1 = x
        if v > v1 and change_distance(v, v1, at, jt) > length * (1.0 + 1e-12) + 1e-12:
            v1 = min_reach(v, length, at, jt)
            ok = False
        # the coasts actually run at v and v1 (<= the caps reserved above)
        cin = t3 if p.coast_in and v > 0.0 else 0.0
        cout = t3 if p.coast_out and v1 > 0.0 else 0.0
        res_out = t3 * p.end_cap if p.coast_out else 0.0
        stop = p.stop and i == n - 1
        if smemo is None:
            sp = _span(p.s0, p.s1, p.vmax, at, jt, v, v1, cin, cout, stop, length, res_out)
        else:
            # a span of the last plan that starts here, if all its inputs are these
            # (compared one by one: cheaper than hashing all of them into the key)
            got = smemo.get(p.s0)
            if (
                got is not None
                and got.s1 == p.s1
                and got.vmax == p.vmax
                and got.accel_limit == at
                and got.jerk_limit == jt
                and got.v0 == v
                and got.v1 == v1
                and got.coast_in_t == cin
                and got.coast_out_t == cout
                and got.stop == stop
                and got.room == length
                and got.reserve_out == res_out
            ):
                sp = got
            else:
                sp = _span(p.s0, p.s1, p.vmax, at, jt, v, v1, cin, cout, stop, length, res_out)
            fresh[p.s0] = sp
        if not sp.fits:
            ok = False
        spans.append(sp)
        v = v1
    if memo is not None:
        memo.spans = fresh
        memo.reach = rfresh
    return spans, ok
