"""The look-ahead path: canonical motion commands turned into pieces with junctions.

Each motion block becomes one or two `Segment`s (a G64 corner between two lines adds a
circular blend and trims both lines). Pieces are laid end to end on one path-length axis
`s`, so the velocity profile is a function of time to s and knows nothing of geometry.
Non-motion commands become sync points: they hang on the segment they follow, whose end
is then an exact stop.
"""

from __future__ import annotations

from collections.abc import Iterable
from math import cos, isinf, isnan, sqrt
from typing import Final

from cnc.canon import ArcFeed, PathMode, SetPathMode, StraightFeed, StraightTraverse
from cnc.errors import NcError
from cnc.params import MachineParams
from cnc.planner.geometry import Arc, Line, Piece, Vec, Vec3, arc_from_canon, blend_arc
from cnc.planner.limits import (
    INF,
    AxisLimits,
    arc_limits,
    arc_limits_at,
    centripetal,
    coast_cap,
    junction_cap,
    line_limits,
    rotary_caps,
)
from cnc.planner.native import mypyc_attr

KINK_SPAN_BREAK: Final = 1e-9  # tangent jumps above this end a velocity span (a = 0 there)
MotionCommand = StraightTraverse | StraightFeed | ArcFeed


@mypyc_attr(acyclic=True)
class Segment:
    """One piece of the path with its static limits and its end junction."""

    __slots__ = (
        "geom",
        "s0",
        "s1",
        "line",
        "block",
        "block_last",
        "vphys",
        "at",
        "jt",
        "feed",
        "normal_axis",
        "stop_end",
        "jcap_end",
        "jcoast",
        "jump_end",
        "jdu",
        "jdk",
        "next_geom",
        "break_end",
        "sync_after",
        "exact",
        "tolerance",
        "lim_v",
        "lim_at",
        "lim_jt",
        "lim",
        "rapid",
        "feed_v",
        "rot0",
        "rot1",
        "rq",
        "rotating",
        "jdur",
    )

    geom: Piece
    s0: float
    s1: float
    line: int
    block: int
    block_last: bool
    vphys: float
    at: float
    jt: float
    feed: float | None  # mm/s, None for rapid
    normal_axis: int
    stop_end: bool
    jcap_end: float
    jcoast: float
    jump_end: bool
    jdu: Vec3
    jdk: Vec3
    next_geom: Piece | None
    break_end: bool
    sync_after: tuple  # sync commands hanging on the segment's end (immutable: shared ())
    exact: bool
    tolerance: float
    lim_v: float
    lim_at: float
    lim_jt: float
    lim: AxisLimits
    rapid: bool  # feed is None (a typed copy for the planner's inner loops)
    feed_v: float  # feed, or 0.0 for a rapid
    # rotary axes (mill4/mill5): their angles at both ends, linear in s between them
    # (empty on a machine without rotary axes), and their degrees per unit of s
    rot0: Vec
    rot1: Vec
    rq: Vec3
    rotating: bool
    jdur: Vec3  # rotary rate jump at the end junction

    def __init__(
        self,
        geom: Piece,
        line: int,
        block: int,
        feed: float | None,
        normal_axis: int,
        lim: AxisLimits,
        exact: bool,
        tolerance: float,
        rot0: Vec = (),
        rot1: Vec = (),
    ) -> None:
        self.geom = geom
        self.s0 = 0.0
        self.s1 = 0.0
        self.line = line
        self.block = block
        self.block_last = True
        self.feed = feed
        self.rapid = feed is None
        self.feed_v = 0.0 if feed is None else feed
        self.normal_axis = normal_axis
        self.rot0 = rot0
        self.rot1 = rot1
        self.rq = self.jdur = (0.0, 0.0, 0.0)
        self.rotating = False
        self.lim_v = -1.0
        self.lim_at = self.lim_jt = 0.0
        if isinstance(geom, Line):
            self.vphys, self.at, self.jt = line_limits(lim, geom.u)
            if rot0 and rot0 != rot1:
                n = geom.length
                q = [(b - a) / n for a, b in zip(rot0, rot1, strict=True)]
                while len(q) < 3:
                    q.append(0.0)
                self.rq = (q[0], q[1], q[2])
                self.rotating = True
                self.vphys, self.at, self.jt = rotary_caps(
                    lim, self.rq, self.vphys, self.at, self.jt
                )
        else:
            assert isinstance(geom, Arc)
            # the limits at the programmed feed come with the cap: a plan asks for both
            vslow = -1.0 if feed is None else feed
            self.vphys, self.at, self.jt, at2, jt2 = arc_limits_at(
                lim, geom, normal_axis, INF, vslow
            )
            if 0.0 < vslow < self.vphys:
                self.lim_v = vslow
                self.lim_at = at2
                self.lim_jt = jt2
        self.stop_end = True  # until the next piece is known
        self.jcap_end = 0.0
        self.jcoast = -1.0  # coasted junction cap, computed when a span boundary needs it
        self.jump_end = True
        self.jdu = self.jdk = (0.0, 0.0, 0.0)
        self.next_geom = None
        self.break_end = True
        self.sync_after = ()
        self.exact = exact
        self.tolerance = tolerance
        self.lim = lim

    def limits_at(self, v: float) -> tuple[float, float]:
        """Tangential (accel, jerk) valid up to path speed v (arcs allow more when slower)."""
        geom = self.geom
        if v >= self.vphys or not isinstance(geom, Arc):
            return self.at, self.jt
        if v != self.lim_v:
            _v, self.lim_at, self.lim_jt = arc_limits(self.lim, geom, self.normal_axis, v)
            self.lim_v = v
        return self.lim_at, self.lim_jt

    @property
    def jcoast_end(self) -> float:
        """Cap of the end junction when passed in a coast (see limits.coast_cap)."""
        if self.jcoast < 0.0:
            lim = self.lim
            nxt = self.next_geom
            assert nxt is not None, "coast cap of a junction not yet known"
            ka1, kj1 = centripetal(lim, self.geom)
            ka2, kj2 = centripetal(lim, nxt)
            if isinstance(self.geom, Arc) or isinstance(nxt, Arc):
                # the larger of the two pieces, per axis (two lines: both zero)
                ka1 = (
                    ka1[0] if ka1[0] >= ka2[0] else ka2[0],
                    ka1[1] if ka1[1] >= ka2[1] else ka2[1],
                    ka1[2] if ka1[2] >= ka2[2] else ka2[2],
                )
                kj1 = (
                    kj1[0] if kj1[0] >= kj2[0] else kj2[0],
                    kj1[1] if kj1[1] >= kj2[1] else kj2[1],
                    kj1[2] if kj1[2] >= kj2[2] else kj2[2],
                )
            self.jcoast = coast_cap(lim, self.jdu, self.jdk, ka1, kj1)
            rl = lim.rot
            if rl is not None and _nonzero3(self.jdur):
                zero = (0.0, 0.0, 0.0)
                rc = coast_cap(rl, self.jdur, zero, zero, zero)
                if rc < self.jcoast:
                    self.jcoast = rc
        return self.jcoast

    def vcap(self, feed_ovr: float, rapid_ovr: float) -> float:
        if self.rapid:
            return self.vphys * rapid_ovr
        v = self.feed_v * feed_ovr
        return v if v < self.vphys else self.vphys


# not acyclic: one per Motion (nothing to gain) and it holds the machine parameters and
# the pending sync commands, objects the planner does not own
class Path:
    """Segments not yet executed, in order, with absolute path coordinates."""

    params: MachineParams
    lim: AxisLimits
    _segs: list[Segment]
    # the end junction of the second-last piece into the last one, not yet computed:
    # the next blend usually uses the last line up and replaces that junction, so it
    # is computed only when someone looks (see `segs`) or the next block keeps it
    _pend_a: Segment | None
    _pend_b: Segment | None
    _exact_mode: bool  # mode is PathMode.EXACT_STOP
    changed_s: float
    base: int
    end_pose: Vec3
    end_rot: Vec  # the rotary angles at the path end (empty: no rotary axes)
    nrot: int
    end_s: float
    mode: PathMode
    tolerance: float
    blocks: int
    max_feed: float
    head_sync: list
    max_blend_deviation: float

    def __init__(self, params: MachineParams, lim: AxisLimits, start: Vec) -> None:
        self.params = params
        self.lim = lim
        self._segs = []
        self._pend_a = self._pend_b = None
        # lowest path position of a piece added or changed since the planner last reset
        # it (profile.partition_again takes earlier parts of its last cut as they were)
        self.changed_s = INF
        self.base = 0  # executed segments dropped from the front of `segs`
        if len(start) != 3 + lim.nrot:
            raise NcError(
                f"the planner moves poses of {3 + lim.nrot} axes; got a start pose of"
                f" {len(start)} axes"
            )
        self.end_pose = (float(start[0]), float(start[1]), float(start[2]))
        self.nrot = lim.nrot
        self.end_rot = tuple([float(v) for v in start[3 : 3 + self.nrot]])
        self.end_s = 0.0
        self.mode = PathMode.CONTINUOUS
        self._exact_mode = False
        self.tolerance = params.default_path_tolerance
        self.blocks = 0
        self.max_feed = params.max_feed / 60.0
        self.head_sync = []  # sync commands before any pending segment
        # largest distance of a G64 blend from its two lines (at its middle): the path's
        # only departure from the programmed geometry (`nc plan` reports it)
        self.max_blend_deviation = 0.0

    @property
    def segs(self) -> list[Segment]:
        """The pieces not yet executed, every junction computed."""
        if self._pend_a is not None:
            self._settle()
        return self._segs

    # -- building -----------------------------------------------------------------------
    def set_path_mode(self, cmd: SetPathMode) -> None:
        self.mode = cmd.mode
        self._exact_mode = cmd.mode is PathMode.EXACT_STOP
        tol = cmd.tolerance
        self.tolerance = tol if tol > 0.0 else self.params.default_path_tolerance

    def add_motion(self, cmd: MotionCommand, protect_s: float, join: bool = True) -> None:
        """Append a motion block. Path before `protect_s` is committed and never reshaped.

        `join=False` makes the junction with the previous block an exact stop (single block).
        """
        start = self.end_pose
        raw_end: Iterable[float] = cmd.end  # a tuple, but a list must not be a TypeError
        cmd_end = raw_end if isinstance(raw_end, tuple) else tuple(raw_end)
        nrot = self.nrot
        if len(cmd_end) != 3 + nrot:
            raise NcError(f"pose has {len(cmd_end)} axes, machine has {3 + nrot}", cmd.line)
        x, y, z = float(cmd_end[0]), float(cmd_end[1]), float(cmd_end[2])
        rot0 = self.end_rot
        rot1 = rot0
        rot_len = 0.0
        if nrot:
            rot1 = tuple([float(v) for v in cmd_end[3:]])
            for a, b in zip(rot0, rot1, strict=True):
                if not _finite(b):
                    raise NcError(f"rotary end angle {b} is not finite", cmd.line)
                rot_len += (b - a) * (b - a)
            rot_len = sqrt(rot_len)
        end = (x, y, z)
        if not _finite(x) or not _finite(y) or not _finite(z):
            raise NcError(f"end point {end} is not a finite position", cmd.line)
        exact = self._exact_mode or bool(cmd.exact_stop)
        geom: Piece
        feed: float | None
        if isinstance(cmd, StraightTraverse):
            geom = Line(start, end)
            feed = None
            normal = -1
        elif isinstance(cmd, StraightFeed):
            geom = Line(start, end)
            feed = self._feed(cmd)
            normal = -1
        elif isinstance(cmd, ArcFeed):
            normal = cmd.plane.value
            center = tuple([float(c) for c in cmd.center])
            if not all(_finite(c) for c in center):
                raise NcError(f"arc centre {center} is not a finite position", cmd.line)
            if len(center) != 3 + nrot:
                raise NcError(
                    f"arc centre has {len(center)} axes, machine has {3 + nrot}", cmd.line
                )
            if rot_len > 0.0:
                raise NcError("a rotary axis cannot turn in a circular (G2/G3) block", cmd.line)
            center = center[:3]
            r0 = _plane_dist(start, center, normal)
            r1 = _plane_dist(end, center, normal)
            if r0 <= 1e-9 or r1 <= 1e-9:
                raise NcError("arc with zero radius", cmd.line)
            geom = arc_from_canon(start, end, center, normal, cmd.clockwise, cmd.turns)
            feed = self._feed(cmd)
        else:  # pragma: no cover - guarded by the caller
            raise TypeError(cmd)
        self.end_pose = end
        self.end_rot = rot1
        if rot_len > 0.0 and geom.length <= 1e-12:
            # a pure rotary move: s runs in degrees along the rotary axes (its F is
            # deg/min, Fanuc), X Y Z stand; it starts and ends at rest (units of s differ)
            geom = Line(start, start, (0.0, 0.0, 0.0))
            geom.length = rot_len
            exact = True
            if self._segs:
                self._segs[-1].exact = True
        if geom.length <= 1e-12:
            return  # a zero-length move does not touch the path
        self.blocks += 1
        seg = Segment(
            geom, cmd.line, self.blocks, feed, normal, self.lim, exact, self.tolerance, rot0, rot1
        )
        prev = self._segs[-1] if self._segs else None
        if prev is None:
            seg.s0 = self.end_s
        elif not join:
            seg.s0 = prev.s1
        else:
            self._join(prev, seg, protect_s)
        seg.s1 = seg.s0 + seg.geom.length
        self._segs.append(seg)
        self.end_s = seg.s1
        if seg.s0 < self.changed_s:
            self.changed_s = seg.s0

    def _feed(self, cmd: StraightFeed | ArcFeed) -> float:
        raw: object = cmd.feed  # None when the program never set F
        if not raw:
            raise NcError("feed move without a feed rate (F)", cmd.line)
        if not isinstance(raw, float | int):
            raise NcError(f"feed rate {raw!r} is not a number", cmd.line)
        feed = float(raw)
        if feed <= 0.0:
            raise NcError("feed move without a feed rate (F)", cmd.line)
        if not _finite(feed):
            raise NcError(f"feed rate {raw} is not finite", cmd.line)
        f = feed / 60.0
        return f if f < self.max_feed else self.max_feed

    def add_sync(self, cmd: object) -> None:
        if self._pend_a is not None:
            self._settle()
        if self._segs:
            last = self._segs[-1]
            last.sync_after = (*last.sync_after, cmd)
            if self._segs[-1].s0 < self.changed_s:
                self.changed_s = self._segs[-1].s0
            self._finalised(len(self._segs) - 1)
        else:
            self.head_sync.append(cmd)

    def finish(self) -> None:
        """End of program: the last segment keeps its length."""
        if self._pend_a is not None:
            self._settle()
        if self._segs:
            self._finalised(len(self._segs) - 1)

    def _finalised(self, i: int) -> None:
        """Segment i's length is final: its start junction may now count it as its gap."""
        if i <= 0:
            return
        before, seg = self._segs[i - 1], self._segs[i]
        if before.exact or before.sync_after or not isinstance(seg.geom, Line):
            return
        if before.s1 != seg.s0 or seg.geom.length <= before.geom.length:
            return  # not joined, or the gap (the longer piece) does not change
        self._set_junction(before, seg, True)

    def _join(self, prev: Segment, seg: Segment, protect_s: float) -> None:
        """Decide the junction prev -> seg: blend, pass at a capped speed, or stop."""
        seg.s0 = prev.s1
        if prev.exact or prev.sync_after:
            self._finalised(len(self._segs) - 1)
            return  # prev.stop_end stays True: exact stop or sync point
        pg, sg = prev.geom, seg.geom
        if (
            isinstance(pg, Line)
            and isinstance(sg, Line)
            and prev.rapid == seg.rapid
            and not prev.rotating
            and not seg.rotating
        ):
            # the blend may use what is left of prev (never what the executor has committed
            # to) and of seg: all of it when prev's rest is at most 3/4 of seg (so chains of
            # short lines become chains of arcs with no leftover line between them), else
            # half, the other half being kept for seg's own end
            rest = min(pg.length, prev.s1 - max(protect_s, prev.s0))
            avail2 = rest if rest <= 0.75 * sg.length else 0.5 * sg.length
            arc = blend_arc(pg.end, pg.u, sg.u, prev.tolerance, rest, avail2) if rest > 0 else None
            if arc is not None:
                d = arc.trim
                dev = arc.r0 * (1.0 - cos(0.5 * arc.sweep))
                if dev > self.max_blend_deviation:
                    self.max_blend_deviation = dev
                lim = self.lim
                bseg = Segment(
                    arc,
                    prev.line,
                    prev.block,
                    prev.feed,
                    -1,
                    lim,
                    False,
                    prev.tolerance,
                    prev.rot1,
                    prev.rot1,
                )
                if pg.length - d <= 1e-12 and protect_s <= prev.s0:
                    # the previous line is used up: the blend takes its place
                    self._segs.pop()
                    if prev.s0 < self.changed_s:
                        self.changed_s = prev.s0
                    arc.start = pg.start
                    bseg.block_last = prev.block_last
                    before = self._segs[-1] if self._segs else None
                    bseg.s0 = prev.s0
                    if self._pend_a is not None and self._pend_b is prev:
                        # the junction before -> prev was never computed: replaced here
                        # (a pending junction has its first piece before prev)
                        self._pend_a = self._pend_b = None
                        assert before is not None
                        self._set_junction(before, bseg, True)
                    elif before is not None and not before.stop_end:
                        self._set_junction(before, bseg, True)
                else:
                    if prev.s0 < self.changed_s:
                        self.changed_s = prev.s0
                    prev.geom = pg.with_ends(pg.start, arc.start)
                    prev.s1 = prev.s0 + prev.geom.length
                    prev.block_last = False
                    bseg.s0 = prev.s1
                    self._finalised(len(self._segs) - 1)
                    self._set_junction(prev, bseg, True)
                bseg.s1 = bseg.s0 + arc.length
                self._segs.append(bseg)
                # (in place: seg's own line, nothing else refers to it yet)
                sg.move_start(arc.end)
                seg.s0 = bseg.s1
                self._defer_junction(bseg, seg)
                return
        self._finalised(len(self._segs) - 1)
        self._defer_junction(prev, seg)

    def _defer_junction(self, a: Segment, b: Segment) -> None:
        """Junction a -> b with b the new last piece (b_final False), computed later."""
        if self._pend_a is not None:
            self._settle()
        self._pend_a = a
        self._pend_b = b

    def _settle(self) -> None:
        a, b = self._pend_a, self._pend_b
        assert a is not None and b is not None
        self._pend_a = self._pend_b = None
        self._set_junction(a, b, False)

    def _set_junction(self, a: Segment, b: Segment, b_final: bool) -> None:
        if self._pend_a is a:
            self._pend_a = self._pend_b = None  # superseded
        if a.s0 < self.changed_s:
            self.changed_s = a.s0
        ga, gb = a.geom, b.geom
        ta, tb, ka, kb = ga.t1, gb.t0, ga.k1, gb.k0
        du0, du1, du2 = tb[0] - ta[0], tb[1] - ta[1], tb[2] - ta[2]
        du = (du0, du1, du2)
        dk = (kb[0] - ka[0], kb[1] - ka[1], kb[2] - ka[2])
        big = (
            du0 > KINK_SPAN_BREAK
            or -du0 > KINK_SPAN_BREAK
            or du1 > KINK_SPAN_BREAK
            or -du1 > KINK_SPAN_BREAK
            or du2 > KINK_SPAN_BREAK
            or -du2 > KINK_SPAN_BREAK
        )
        at_max = a.at if a.at > b.at else b.at
        # a line that is still the last piece may yet be used up by the next blend
        after = gb.length if b_final or type(gb) is not Line else 0.0
        gap = ga.length if ga.length > after else after
        cap = junction_cap(self.lim, du, dk, gap, at_max, not big)
        rot_jump = False
        rl = self.lim.rot
        if rl is not None and (a.rotating or b.rotating):
            qa, qb = a.rq, b.rq
            dr = (qb[0] - qa[0], qb[1] - qa[1], qb[2] - qa[2])
            a.jdur = dr
            if dr[0] != 0.0 or dr[1] != 0.0 or dr[2] != 0.0:
                big = big or _big3(dr)
                rot_jump = True
                rcap = junction_cap(rl, dr, (0.0, 0.0, 0.0), gap, at_max, not big)
                if rcap < cap:
                    cap = rcap
        if big and a.rapid != b.rapid:
            cap = 0.0  # a corner between a rapid and a feed move is an exact stop
        jump = rot_jump or bool(du0 or du1 or du2 or dk[0] or dk[1] or dk[2])
        a.jcap_end = cap
        a.jcoast = -1.0 if jump and cap > 0.0 else 0.0
        a.jdu = du
        a.jdk = dk
        a.next_geom = gb
        a.jump_end = jump
        a.break_end = big
        a.stop_end = cap <= 0.0


def _big3(d: Vec3) -> bool:
    return (
        d[0] > KINK_SPAN_BREAK
        or -d[0] > KINK_SPAN_BREAK
        or d[1] > KINK_SPAN_BREAK
        or -d[1] > KINK_SPAN_BREAK
        or d[2] > KINK_SPAN_BREAK
        or -d[2] > KINK_SPAN_BREAK
    )


def _nonzero3(d: Vec3) -> bool:
    return d[0] != 0.0 or d[1] != 0.0 or d[2] != 0.0


def _finite(x: float) -> bool:
    """math.isfinite (which mypyc would call through Python; these two are native)."""
    return not (isinf(x) or isnan(x))


def _plane_dist(p: Vec, c: Vec, normal: int) -> float:
    return sum((p[i] - c[i]) ** 2 for i in range(len(p)) if i != normal) ** 0.5
