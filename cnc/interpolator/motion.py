"""`Motion`: the look-ahead planner and the IPO-cycle interpolator behind one pure API.

The machine drives it once per IPO cycle::

    m = Motion(params)
    while program:                     # feed the look-ahead while it has room
        if not m.push(cmd): break
    s = m.step()                       # next setpoint: s.pose, s.velocity, s.line, s.sync
    if s.sync is not None:             # a sync point (M-function, dwell, tool change...)
        ...do it...; m.acknowledge()   # motion stays at rest until acknowledged

No clock is read: time advances by exactly one IPO cycle per `step()`, so the same
commands always give the same samples, bit for bit.
"""

from __future__ import annotations

from typing import Final

from cnc.canon import ArcFeed, SetPathMode, StraightFeed, StraightTraverse
from cnc.errors import NcError
from cnc.interpolator.sample import Sample
from cnc.params import MachineParams
from cnc.planner.geometry import Line, Vec, Vec3
from cnc.planner.limits import AxisLimits
from cnc.planner.path import Path
from cnc.planner.profile import INF, PlanMemo, Row, Span, partition, partition_again, solve
from cnc.planner.scurve import change_distance

DROP_EVERY: Final = 256

__all__ = ["Motion", "Peaks", "Sample"]


class Peaks:
    """Per-axis maxima of |v|, |a|, |j| over IPO samples, by the discrete definition of
    docs/motion.md (backward differences, at rest before the first sample).

    Kept here so that it runs compiled with the interpolator: `Motion.run` feeds it every
    pose without a Python-level loop (`nc plan` without a trace).
    """

    t: float
    p: Vec3
    v: Vec3
    a: Vec3
    vmax: Vec3
    amax: Vec3
    jmax: Vec3

    def __init__(self, start: Vec3, ipo: float) -> None:
        self.t = ipo
        self.p = (float(start[0]), float(start[1]), float(start[2]))
        self.v = self.a = (0.0, 0.0, 0.0)
        self.vmax = self.amax = self.jmax = (0.0, 0.0, 0.0)

    def add(self, pose: Vec3) -> None:
        t = self.t
        p0, p1, p2 = self.p
        v0, v1, v2 = self.v
        a0, a1, a2 = self.a
        x0, x1, x2 = pose
        w0, w1, w2 = (x0 - p0) / t, (x1 - p1) / t, (x2 - p2) / t
        b0, b1, b2 = (w0 - v0) / t, (w1 - v1) / t, (w2 - v2) / t
        j0, j1, j2 = (b0 - a0) / t, (b1 - a1) / t, (b2 - a2) / t
        self.p = (x0, x1, x2)
        self.v = (w0, w1, w2)
        self.a = (b0, b1, b2)
        self.vmax = _absmax(self.vmax, w0, w1, w2)
        self.amax = _absmax(self.amax, b0, b1, b2)
        self.jmax = _absmax(self.jmax, j0, j1, j2)


def _absmax(m: Vec3, x: float, y: float, z: float) -> Vec3:
    m0, m1, m2 = m
    if x < 0.0:
        x = -x
    if y < 0.0:
        y = -y
    if z < 0.0:
        z = -z
    return (x if x > m0 else m0, y if y > m1 else m1, z if z > m2 else m2)


class Motion:
    """Look-ahead planner + interpolator for one machine (pure, stepped per IPO cycle)."""

    params: MachineParams
    ipo: float
    lim: AxisLimits
    _pose: Vec3
    path: Path
    single_block: bool
    _feed_ovr: float
    _rapid_ovr: float
    _hold: bool
    _eop: bool
    _cycle: int
    _s: float
    _v: float
    _a: float
    _spans: list[Span]
    _si: int
    _t: float
    _hint: int
    _kp: int
    _kdone: int
    _blocks_done: int
    _line: int
    _last_block: int
    _sync_queue: list
    _waiting: object | None
    _dirty: bool
    _urgent: bool
    _sb_wait: bool
    replans: int
    fallbacks: int
    run_cycles: int
    _memo: PlanMemo
    _lookahead: int  # params.lookahead, or the G103 limit (SetPathMode.lookahead)
    _nrot: int  # rotary axes after X Y Z in a pose (mill4: 1, mill5: 2)
    _rpose: Vec  # their angles now, degrees

    def __init__(
        self,
        params: MachineParams,
        start: Vec | None = None,
        ipo_cycle_s: float | None = None,
    ) -> None:
        t = params.ipo_cycle_s if ipo_cycle_s is None else ipo_cycle_s
        if not 0.0005 <= t <= 0.008 + 1e-12:
            raise NcError(f"IPO cycle {t * 1000:g} ms outside 0.5..8 ms")
        if params.lookahead < 1:
            raise NcError("look-ahead must hold at least one block")
        self.params = params
        self._lookahead = params.lookahead
        self.ipo = t
        self.lim = AxisLimits.from_params(params, t)
        nrot = self.lim.nrot
        self._nrot = nrot
        if start is None:
            start = (0.0,) * (3 + nrot)
        if len(start) != 3 + nrot:
            raise NcError(
                f"the planner moves poses of {3 + nrot} axes; got a start pose of {len(start)} axes"
            )
        self._pose = (float(start[0]), float(start[1]), float(start[2]))
        self._rpose = tuple([float(v) for v in start[3:]])
        self.path = Path(params, self.lim, start)
        self.single_block = False
        self._feed_ovr = 1.0
        self._rapid_ovr = 1.0
        self._hold = False
        self._eop = False
        self._cycle = 0
        self._s = 0.0
        self._v = 0.0
        self._a = 0.0
        self._spans = []
        self._si = 0
        self._t = 0.0
        self._hint = 0
        self._kp = 0  # segment under the current position
        self._kdone = 0  # first segment not yet finished
        self._blocks_done = 0
        self._line = 0
        self._last_block = 0
        self._sync_queue = []
        self._waiting = None
        self._dirty = False
        self._urgent = False
        self._sb_wait = False
        self.replans = 0
        self.fallbacks = 0  # re-plans refused because the running plan had to stay
        self.run_cycles = 0  # cycles the last `run` stepped
        # spans of the last plan by their inputs: a re-plan for new blocks rebuilds only
        # the spans whose inputs changed (see profile.solve)
        self._memo = PlanMemo()

    # -- feeding ------------------------------------------------------------------------
    def space(self) -> int:
        """Motion blocks the look-ahead can still take."""
        return self._lookahead - (self.path.blocks - self._blocks_done)

    def push(self, cmd: object) -> bool:
        """Queue one canonical command; False (nothing queued) when the look-ahead is full."""
        if isinstance(cmd, (StraightTraverse, StraightFeed, ArcFeed)):  # canon.MOTION_TYPES
            if self._lookahead <= self.path.blocks - self._blocks_done:  # space() <= 0
                return False
            self.path.add_motion(cmd, self._protect_s(), not self.single_block)
            self._dirty = True
        elif isinstance(cmd, SetPathMode):
            self.path.set_path_mode(cmd)
            # G103 P: the blocks after it are planned with at most P blocks ahead (the
            # blocks already queued stay; no new one is taken until fewer are left)
            limit = int(cmd.lookahead)
            full = self.params.lookahead
            self._lookahead = limit if 0 < limit < full else full
        elif self._s >= self.path.end_s and not self._ahead():
            self._sync_queue.append(cmd)
        else:
            self.path.add_sync(cmd)
        return True

    def end_of_program(self) -> None:
        """No more commands will come: the path end is final."""
        if not self._eop:
            self._eop = True
            self.path.finish()
            self._dirty = True

    def continued(self) -> Motion:
        """A Motion at rest at this one's pose that has dropped the rest of the path, with
        the same path mode, look-ahead limit, overrides and single-block switch: how the
        program goes on after a G31 stopped at its skip signal (cnc.controller)."""
        m = Motion(self.params, start=self.pose, ipo_cycle_s=self.ipo)
        path = self.path
        m.path.set_path_mode(SetPathMode(self._line, path.mode, path.tolerance))
        m._lookahead = self._lookahead
        m._feed_ovr = self._feed_ovr
        m._rapid_ovr = self._rapid_ovr
        m.single_block = self.single_block
        m._cycle = self._cycle
        m._line = self._line
        return m

    # -- operator -----------------------------------------------------------------------
    def set_feed_override(self, f: float) -> None:
        """Feed override 0..2 (0..200 %); 0 holds feed moves like a feed hold."""
        f = min(max(float(f), 0.0), 2.0)
        if f != self._feed_ovr:
            self._feed_ovr = f
            self._urgent = True

    def set_rapid_override(self, f: float) -> None:
        """Rapid override 0..1 (0..100 %); 0 holds like a feed hold."""
        f = min(max(float(f), 0.0), 1.0)
        if f != self._rapid_ovr:
            self._rapid_ovr = f
            self._urgent = True

    def feed_hold(self) -> None:
        """Decelerate along the path (jerk-limited) to rest; `resume()` continues."""
        if not self._hold:
            self._hold = True
            self._urgent = True

    def resume(self) -> None:
        """Cycle start: leave feed hold or a single-block stop."""
        if self._hold or self._sb_wait:
            self._hold = False
            self._sb_wait = False
            self._urgent = True

    def set_single_block(self, on: bool) -> None:
        if bool(on) != self.single_block:
            self.single_block = bool(on)
            self._urgent = True

    def acknowledge(self) -> None:
        """The sync-point command last reported is done; motion may continue."""
        self._waiting = None

    # -- status -------------------------------------------------------------------------
    @property
    def feed_override(self) -> float:
        return self._feed_ovr

    @property
    def rapid_override(self) -> float:
        return self._rapid_ovr

    @property
    def waiting(self) -> object | None:
        """The sync-point command awaiting `acknowledge()`, or None."""
        return self._waiting

    @property
    def holding(self) -> bool:
        return self._hold or self._sb_wait

    @property
    def idle(self) -> bool:
        """Nothing left to move or hand over (the program may still push more)."""
        return (
            not self._ahead()
            and self._v == 0.0
            and self._waiting is None
            and not self._sync_queue
            and not self.path.head_sync
        )

    @property
    def pose(self) -> Vec:
        """The commanded pose: X Y Z, then the rotary axes (if any)."""
        if self._nrot:
            return self._pose + self._rpose
        return self._pose

    def segment_ends(self) -> tuple[Vec, Vec] | None:
        """Start and end pose (X Y Z and rotary) of the feed piece under the current
        position: the straight line it programs. None before the first piece and on a
        rapid (G0 programs no path, only its end point)."""
        segs = self.path.segs
        if self._kp >= len(segs):
            return None
        g = segs[self._kp]
        if g.rapid:
            return None
        return g.geom.start + g.rot0, g.geom.end + g.rot1

    @property
    def block(self) -> int:
        """Number (1, 2, ... in push order) of the motion block under the current position;
        0 before the first. Moves shorter than 1e-12 mm are dropped and not numbered."""
        segs = self.path.segs
        if self._kp < len(segs) and self._s > 0.0:
            return segs[self._kp].block
        return self._last_block

    @property
    def path_position(self) -> float:
        """Path length travelled since the start, mm."""
        return self._s

    # -- the IPO cycle ------------------------------------------------------------------
    def step(self) -> Sample:
        """Advance one IPO cycle and return the setpoint."""
        self._cycle += 1
        tnow = self._cycle * self.ipo
        if self._waiting is not None:
            return Sample(tnow, self.pose, 0.0, self._line)
        if self.path.head_sync:
            self._sync_queue.extend(self.path.head_sync)
            self.path.head_sync.clear()
        if self._sync_queue:
            cmd = self._sync_queue.pop(0)
            self._waiting = cmd
            self._line = getattr(cmd, "line", self._line)
            return Sample(tnow, self.pose, 0.0, self._line, cmd)
        self._maybe_replan()
        self._advance(self.ipo)
        return Sample(tnow, self.pose, self._v, self._line)

    def run(self, limit: int, peaks: Peaks, feeding: bool) -> Sample:
        """`step()` up to `limit` times (at least once), each pose into `peaks`; returns
        the last sample. Stops early after a cycle that reports a sync command, when the
        machine is idle, or, while the caller has blocks to push (`feeding`), as soon
        as the look-ahead has room for one: the samples are those of calling `step()`
        in a loop that pushes whenever there is room, without a Python-level loop."""
        s = self.step()
        peaks.add(self._pose)  # s.pose, typed as the pose it is
        n = 1
        while n < limit and s.sync is None:
            if feeding and self._lookahead > self.path.blocks - self._blocks_done:
                break
            if self.idle:
                break
            s = self.step()
            peaks.add(self._pose)
            n += 1
        self.run_cycles = n
        return s

    # -- internals ----------------------------------------------------------------------
    def _ahead(self) -> bool:
        return self._s < self.path.end_s

    def _protect_s(self) -> float:
        """Path the running plan covers: a new block's blend never reshapes it, so the
        plan stays valid whatever the new block asks for (see `_replan`). It ends at the
        stoppable tail (`_tail_start`), so blends still use all of the last line."""
        if self._si < len(self._spans):
            return self._spans[-1].s1
        return self._s

    def _in_coast(self) -> bool:
        """Inside the constant-speed cycles around a junction: its sampling window must
        see no path acceleration, so no re-plan may start here."""
        if self._si >= len(self._spans):
            return False
        sp = self._spans[self._si]
        if self._v == 0.0:
            return False
        return self._t < sp.coast_in_t or (
            sp.coast_out_t > 0.0 and self._t > sp.dur - sp.coast_out_t
        )

    def _maybe_replan(self) -> None:
        if self._sb_wait or (self._hold and self._v == 0.0 and not self._spans):
            self._urgent = False
            return
        if self._in_coast():
            return
        if (
            self._urgent
            or self._dirty
            or self._si >= len(self._spans)
            and self._ahead()
            and self._v == 0.0
        ):
            self._replan()

    def _ovr_hold(self) -> bool:
        return self._feed_ovr == 0.0 or self._rapid_ovr == 0.0

    def _replan(self) -> None:
        urgent = self._urgent
        self._urgent = False
        self._dirty = False
        self.replans += 1
        lead = self._lead(urgent)
        if lead is not None:
            s0, v0 = lead.s1, lead.v1
        else:
            s0, v0 = self._s, self._v
        segs = self.path.segs
        k = self._kp
        n = len(segs)
        while k < n and segs[k].s1 <= s0:
            k += 1
        fo, ro = self._feed_ovr, self._rapid_ovr
        spans: list[Span] = []
        if lead is not None and lead.stop:
            pass  # the lead ends at rest: the next plan starts from there
        elif k < n:
            if self._hold or self._ovr_hold():
                spans = self._plan_stop(k, s0, v0, fo, ro)
            elif self.single_block:
                spans = self._plan_single_block(k, s0, v0, fo, ro)
            else:
                path = self.path
                tail = self._tail_start(s0)
                parts = partition_again(
                    segs, k, s0, fo, ro, self.ipo, self._memo, path.changed_s, tail
                )
                path.changed_s = INF
                spans, ok = solve(parts, v0, self.ipo, self._memo)
                if not ok and not urgent and self._si < len(self._spans):
                    # The new blocks ask for less than the committed state can give (a
                    # plan from it would break a limit). The running plan stays: it ends
                    # at rest before any path the new blocks could change, so it is still
                    # valid; the re-plan is tried again next cycle from a later state.
                    self._dirty = True
                    self.fallbacks += 1
                    return
        if lead is not None:
            spans.insert(0, lead)
        self._spans = spans
        self._si = 0
        self._t = 0.0
        self._hint = 0

    def _tail_start(self, s0: float) -> float:
        """Where the plan must come to rest: the start of the last piece while the next
        block may still reshape it (INF when the path end is final or already reached).

        The next block's G64 blend may use up all of the last line not yet committed, and
        its junctions then ask for speeds no plan made before could know: so the window
        keeps a stoppable tail, the plan covers only path that can no longer change, and
        a re-plan never has to demand more than the limits from a committed state.
        """
        if self._eop:
            return INF
        segs = self.path.segs
        if not segs:
            return INF
        last = segs[-1]
        if last.exact or last.sync_after or not isinstance(last.geom, Line):
            return INF  # only a line is blended, and not before an exact stop or sync point
        if last.s0 <= s0:
            return INF  # already on it (look-ahead 1, or resting there): runs to its end
        return last.s0

    def _lead(self, urgent: bool) -> Span | None:
        """The part of the current motion that must run on as planned (a != 0 now)."""
        if self._si >= len(self._spans) or self._a == 0.0:
            return None
        sp = self._spans[self._si]
        rows = sp.phases
        i = self._hint
        t0, dt, s, v, a, j = rows[i]
        x = self._t - t0
        a_now = a + j * x
        s_now = self._s - sp.s0
        v_now = v + x * (a + 0.5 * j * x)
        tail: list[Row]
        if urgent and a_now > 0.0:
            jj = sp.jerk_limit
            tail = [(0.0, a_now / jj, 0.0, v_now, a_now, -jj)]
        else:
            tail = [(0.0, t0 + dt - self._t, 0.0, v_now, a_now, j)]
            k = i + 1
            acc = a + j * dt
            while k < len(rows) and abs(acc) > 1e-9 * max(1.0, abs(a_now)):
                tt0, tdt, _ts, _tv, ta, tj = rows[k]
                tail.append((0.0, tdt, 0.0, 0.0, ta, tj))
                acc = ta + tj * tdt
                k += 1
        # re-integrate the tail so times and states are relative to now
        out: list[Row] = []
        tt = 0.0
        ss = 0.0
        vv = v_now
        aa = a_now
        for _t0, d, _s, _v, _a, jj2 in tail:
            if d <= 0.0:
                continue
            out.append((tt, d, ss, vv, aa, jj2))
            ss += d * (vv + d * (0.5 * aa + d * jj2 / 6.0))
            vv += d * (aa + 0.5 * jj2 * d)
            aa += jj2 * d
            tt += d
        if not out:
            return None
        s1 = sp.s0 + s_now + ss
        if s1 > sp.s1:
            s1 = sp.s1
        lead = Span(self._s, s1, out, tt, v_now, vv, False, sp.vmax, sp.jerk_limit)
        if s1 >= sp.s1:
            lead.stop = sp.stop
            lead.single_block_stop = sp.single_block_stop
        if vv <= 0.0:
            lead.v1 = 0.0
            lead.stop = True
        return lead

    def _stop_limits(self, k: int, s0: float, dist: float, v0: float) -> tuple[float, float]:
        segs = self.path.segs
        at = jt = INF
        while k < len(segs):
            g = segs[k]
            gat, gjt = g.limits_at(v0)
            at = min(at, gat)
            jt = min(jt, gjt)
            if g.s1 >= s0 + dist:
                break
            k += 1
        return at, jt

    def _plan_stop(self, k: int, s0: float, v0: float, fo: float, ro: float) -> list[Span]:
        if v0 == 0.0:
            return []
        segs = self.path.segs
        at, jt = segs[k].limits_at(v0)
        dist = change_distance(v0, 0.0, at, jt)
        for _ in range(4):
            at, jt = self._stop_limits(k, s0, dist, v0)
            dist = change_distance(v0, 0.0, at, jt)
        extra = 0.0
        for _ in range(60):
            stop_s = s0 + dist * (1.0 + 1e-9) + extra + 1e-9
            # a hold only ever slows down: caps clamped to the current speed
            parts = partition(segs, k, s0, max(fo, 1.0), max(ro, 1.0), False, stop_s, v0, self.ipo)
            for p in parts:
                if p.end_cap > v0:
                    p.end_cap = v0
            spans, ok = solve(parts, v0, self.ipo)
            if ok:
                return spans
            extra = extra * 2.0 + 0.05 * dist + 1e-6
        return spans

    def _plan_single_block(self, k: int, s0: float, v0: float, fo: float, ro: float) -> list[Span]:
        segs = self.path.segs
        kk = k
        spans: list[Span] = []
        while kk < len(segs):
            while kk < len(segs) and not segs[kk].block_last:
                kk += 1
            if kk >= len(segs):
                kk = len(segs) - 1
            parts = partition(segs, k, s0, fo, ro, False, segs[kk].s1, ipo=self.ipo)
            spans, ok = solve(parts, v0, self.ipo)
            if ok:
                break
            kk += 1
        if spans:
            spans[-1].single_block_stop = True
        return spans

    def _advance(self, dt: float) -> None:
        while True:
            if self._si >= len(self._spans):
                if self._spans:
                    self._spans = []
                    self._si = 0
                if self._ahead() and not self.holding and not self._ovr_hold():
                    self._replan()
                    if not self._spans:
                        self._v = 0.0
                        self._a = 0.0
                        return
                    continue
                self._v = 0.0
                self._a = 0.0
                return
            sp = self._spans[self._si]
            t = self._t + dt
            if t < sp.dur:
                self._t = t
                s, v, a, self._hint = sp.state(t, self._hint)
                self._s, self._v, self._a = s, v, a
                self._place(s)
                return
            dt = t - sp.dur
            self._s = sp.s1
            self._v = sp.v1
            self._a = 0.0
            self._place(sp.s1)
            self._si += 1
            self._t = 0.0
            self._hint = 0
            if sp.stop or sp.v1 == 0.0:
                # at rest: the rest of this cycle is spent standing, so a stop point is
                # always sampled exactly; sync commands hanging here come next
                self._v = 0.0
                self._spans = []
                self._si = 0
                self._arrived()
                if sp.single_block_stop:
                    self._sb_wait = True
                return
            if self._dirty and not (
                self._si < len(self._spans) and self._spans[self._si].coast_in_t > 0.0
            ):
                self._replan()

    def _arrived(self) -> None:
        segs = self.path.segs
        k = self._kdone - 1
        if 0 <= k < len(segs) and segs[k].s1 == self._s and segs[k].sync_after:
            self._sync_queue.extend(segs[k].sync_after)
            segs[k].sync_after = ()

    def _place(self, s: float) -> None:
        segs = self.path.segs
        n = len(segs)
        kp = self._kp
        while kp < n - 1 and s > segs[kp].s1:
            kp += 1
        kd = self._kdone
        while kd < n and segs[kd].s1 <= s:
            if segs[kd].block_last:
                self._blocks_done += 1
            kd += 1
        if kp < n:
            g = segs[kp]
            self._last_block = g.block
            # at a piece end take the stored end point: s0 + length - s0 may round short
            self._pose = g.geom.end if s >= g.s1 else g.geom.point(s - g.s0)
            if self._nrot:
                r0, r1 = g.rot0, g.rot1
                if s >= g.s1 or r0 == r1:
                    self._rpose = r1
                else:
                    f = (s - g.s0) / (g.s1 - g.s0)
                    self._rpose = tuple([a + (b - a) * f for a, b in zip(r0, r1, strict=True)])
            self._line = g.line
        drop = min(kp, kd - 1)
        if drop >= DROP_EVERY:
            del segs[:drop]
            kp -= drop
            kd -= drop
        self._kp = kp
        self._kdone = kd
