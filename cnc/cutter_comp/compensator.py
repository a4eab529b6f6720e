"""G40/G41/G42 cutter radius compensation as a pure read-ahead state machine.

The interpreter pushes the programmed contour one in-plane element at a time; the
compensator holds back the newest element until the next one arrives (one element of
read-ahead), because an element's end point on the tool-centre path depends on the corner
it makes with its successor. See docs/cutter_comp.md for the geometry and the figures.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace
from enum import Enum
from typing import Literal

from cnc.cutter_comp import geometry as g
from cnc.cutter_comp import interference as clash
from cnc.errors import NcError

Point = tuple[float, float]

#: Fanuc's alarm for an arc in the start-up or cancel block (Series 0i/30i: PS0034).
_ALARM_ARC = "NO CIRC ALLOWED IN ST-UP/EXT BLK (Fanuc PS0034)"


@dataclass(frozen=True, slots=True)
class Segment:
    """One in-plane element of the programmed or the compensated path.

    `start`, `end` and `center` are (u, v) in the active plane (G17: X,Y; G18: Z,X; G19:
    Y,Z) in program coordinates. `ccw` is the arc direction seen from the plane's +normal
    (G3 = True). An arc whose start equals its end is a full circle. A segment whose in-plane
    start equals its end (a Z plunge, a dwell the interpreter wants kept in order) is
    "zero-length": it never takes part in a corner, and comes out at the tool's current
    in-plane position. `payload` is opaque and copied to every output segment derived from
    this one.

    `role` (an extra beyond the interpreter contract, defaulted) says what an output segment
    is: "contour" (a programmed element, trimmed or extended), "startup" (the G41/G42
    approach), "cancel" (the G40 departure) or "corner" (an arc inserted around an outside
    corner; it carries the line, column and payload of the element after the corner).

    `rapid` (defaulted) marks a positioning move (G00): it is compensated like any other,
    and its tool path is checked, but its programmed path is air the tool travels through,
    never a wall of the part, so the interference check measures no path against it.
    """

    kind: Literal["line", "arc"]
    start: tuple[float, float]
    end: tuple[float, float]
    center: tuple[float, float] | None
    ccw: bool
    line: int
    col: int
    payload: object = None
    role: str = "contour"
    rapid: bool = False


class _Mode(Enum):
    INACTIVE = "G40"  # segments pass unchanged
    STARTUP = "G41/G42 issued"  # the next in-plane segment is the start-up move
    ACTIVE = "compensating"
    CANCEL = "G40 issued"  # the next in-plane segment is the cancel move


@dataclass(slots=True)
class _Staged:
    """A compensated segment waiting for the interference check of later elements."""

    seg: Segment
    tag: int  # index of the contour element it belongs to
    shape: clash.Element | None  # None: not checked (start-up, cancel, zero-length)
    box: clash.Box | None = None


@dataclass(slots=True)
class _Held:
    """The element read ahead: its start on the tool path is known, its end is not."""

    seg: Segment
    elem: g.OffsetElement
    startup: bool


class CutterCompensation:
    """Cutter radius compensation (G41 left / G42 right / G40 cancel) in one plane.

    Start-up and cancel follow Fanuc type A: the start-up line runs from the uncompensated
    point to the perpendicular offset of the next element's start; the cancel line runs
    from the perpendicular offset of the last element's end to the uncompensated end point.
    Inside corners trim both offset elements to their intersection; outside corners get an
    arc of the tool radius around the programmed corner (line/line corners turning less
    than `geometry.SHALLOW_ANGLE` are extended to their intersection instead).

    Read-ahead: one in-plane element resolves a corner; on top of that each compensated
    segment is held until `lookahead` further contour elements are known and is checked
    against its own programmed element and the `lookahead` after it (the interference
    check, forward as a control's read-ahead): closer than the tool radius is a gouge. A
    backward check would refuse a second lap of a contour entered along the extension of
    its first element, which real controls run. Zero-length
    segments are queued in order, never counted. `lookahead=0` keeps only the corner
    read-ahead and the local checks (reversed or vanished elements, inside arcs, no
    intersection). Every refusal is an `NcError` naming the offending segment's line and
    column.
    """

    def __init__(self, file: str = "<program>", lookahead: int = 3) -> None:
        if lookahead < 0:
            raise ValueError("lookahead must be >= 0")
        self._file = file
        # How far the caller moved the programmed contour (widen_slack) since start-up.
        self._slack = 0.0
        self._lookahead = lookahead
        self._queue: deque[_Staged] = deque()
        # (index, programmed segment, shape) of the last contour elements
        self._window: deque[tuple[int, Segment, clash.Element, clash.Box]] = deque(
            maxlen=lookahead + 2
        )
        self._idx = 0  # index of the newest contour element
        self._mode = _Mode.INACTIVE
        self._side = 1.0
        self._r = 0.0
        self._held: _Held | None = None
        self._trail: list[Segment] = []
        # Element already emitted up to its perpendicular end by flush(): the next corner
        # cannot trim it any more.
        self._released: g.OffsetElement | None = None
        self._tool: Point = (0.0, 0.0)  # in-plane position at the end of the emitted path
        self._prog: Point | None = None  # programmed end of the last pushed segment
        self._scale = 1.0
        # A gouge against the newest contour element waits for the next push: if that is the
        # cancel move and the element is a lead-out (_settle_wall_gouge), it is no wall.
        self._wall_gouge: NcError | None = None
        self._newest_leaves_to_tool_side = False

    # --- public API -----------------------------------------------------------------

    @property
    def active(self) -> bool:
        """True from start() until the cancel move has been pushed (G41/G42 in effect)."""
        return self._mode is not _Mode.INACTIVE

    @property
    def side(self) -> Literal["left", "right"]:
        """The effective side after a negative radius has swapped it."""
        return "left" if self._side > 0 else "right"

    @property
    def radius(self) -> float:
        """The effective (non-negative) tool radius."""
        return self._r

    def start(
        self, side: Literal["left", "right"], radius: float, *, line: int = 0, col: int = 0
    ) -> None:
        """G41 (left) / G42 (right) with tool radius `radius`: the next pushed in-plane
        segment is the start-up move. A negative radius swaps the side (Fanuc)."""
        if side not in ("left", "right"):
            raise self._error(
                f"cutter compensation side must be left or right, not {side!r}", line, col
            )
        if not math.isfinite(radius):
            raise self._error(f"cutter compensation radius {radius!r} is not finite", line, col)
        s = 1.0 if side == "left" else -1.0
        if radius < 0.0:
            s = -s
        r = abs(radius)
        if self._mode in (_Mode.INACTIVE, _Mode.STARTUP):
            if self._mode is _Mode.INACTIVE:
                self._slack = 0.0
            self._side, self._r = s, r
            self._mode = _Mode.STARTUP
            self._scale = max(self._scale, r)
            return
        if (s, r) == (self._side, self._r):
            if self._mode is _Mode.CANCEL:
                self._mode = _Mode.ACTIVE  # G40 then G41 again before any move: no-op
            return
        raise self._error(
            "cutter compensation is already on: program G40 and a cancel move before "
            "changing side or radius",
            line,
            col,
        )

    def widen_slack(self, moved: float) -> None:
        """The caller moved a programmed element by `moved` (an arc centre put on the chord's
        bisector to make its end radii equal): until the next start-up the interference check
        does not refuse a path closer than r by less than twice the largest such correction
        (two elements, each moved towards the other)."""
        if moved > self._slack and math.isfinite(moved):
            self._slack = moved

    def cancel(self) -> None:
        """G40: the next pushed in-plane segment is the cancel move."""
        if self._mode is _Mode.STARTUP:
            self._mode = _Mode.INACTIVE  # no start-up move was made: nothing to undo
        elif self._mode is _Mode.ACTIVE:
            self._mode = _Mode.CANCEL

    def push(self, seg: Segment) -> list[Segment]:
        """Feed the next programmed segment; returns the compensated segments now final."""
        mode = self._mode
        if mode is _Mode.INACTIVE:
            return [seg]
        self._validate(seg)
        self._grow_scale(seg)
        zero = self._is_zero(seg)
        if mode is _Mode.STARTUP:
            if zero:
                return [seg]  # still uncompensated: the tool is where the program says
            if seg.kind == "arc":
                raise self._error(
                    f"cutter compensation start-up move must be a line, not an arc: {_ALARM_ARC}",
                    seg.line,
                    seg.col,
                )
            elem = g.make_line(seg.start, seg.end, self._side, self._r)
            self._held = _Held(seg, elem, startup=True)
            self._released = None
            self._trail = []
            self._prog = seg.end
            self._mode = _Mode.ACTIVE
            return []

        if not zero or mode is _Mode.CANCEL:  # a Z retract before G40 keeps the question open
            self._settle_wall_gouge()
        self._check_continuity(seg)
        self._prog = seg.end
        if zero:
            if mode is _Mode.CANCEL and self._held is not None:
                self._stage(self._finish_held(), self._idx)  # G40 fixes the end: perpendicular
            if self._held is None:
                self._stage([self._at_tool(seg)], self._idx)
            else:
                self._trail.append(seg)
            # after G40 no contour element can follow: nothing is left to check against
            return self._release(everything=mode is _Mode.CANCEL)

        if mode is _Mode.CANCEL:
            if seg.kind == "arc":
                raise self._error(
                    f"cutter compensation cancel move must be a line, not an arc: {_ALARM_ARC}",
                    seg.line,
                    seg.col,
                )
            out = self._finish_held() if self._held is not None else []
            out.append(
                Segment(
                    "line",
                    self._tool,
                    seg.end,
                    None,
                    False,
                    seg.line,
                    seg.col,
                    seg.payload,
                    "cancel",
                )
            )
            self._stage(out, self._idx)
            self._settle_wall_gouge()
            self._mode = _Mode.INACTIVE
            self._released = None
            self._tool = seg.end
            self._window.clear()  # the next G41/G42 starts a new contour
            return self._release(everything=True)

        elem = self._element(seg)
        held = self._held
        # Local checks first (their messages are the most specific), then the window.
        if held is not None and held.startup:
            out = [self._startup_segment(held, elem.off_start)]
            out.extend(self._trail_at(elem.off_start))
            elem.ps, elem.ts = elem.off_start, 0.0
            base = 1
        elif held is not None:
            out, base = self._corner(held, elem, seg), 0
        elif self._released is not None:
            out, base = self._corner_after_sync(self._released, elem, seg), 1
        else:  # pragma: no cover - ACTIVE always holds or has released an element
            raise self._error("cutter compensation: internal state lost", seg.line, seg.col)
        self._newest_leaves_to_tool_side = (
            held is not None
            and not held.startup
            and elem.kind == "arc"
            and self._side * elem.sigma > 0.0  # its centre on the tool side
            # tangent junction (to the rounding of CAM output)
            and g.turn_angle(held.elem.tangent_end(), elem.tangent_start()) <= g.LEAD_OUT_TANGENT
        )
        self._add_contour(seg, elem)
        self._stage(out, self._idx - 1 + base)
        self._held = _Held(seg, elem, startup=False)
        self._released = None
        return self._release()

    @property
    def cancelling(self) -> bool:
        """True after G40 until the cancel move: compensation is programmed off."""
        return self._mode is _Mode.CANCEL

    def finish(self) -> list[Segment]:
        """End a pending G40 without a cancel move: emit everything held and switch off.

        For a block that needs compensation over (G28/G30/G53, a plane change, a canned
        cycle) when G40 came without an in-plane move: the last element ends at its
        perpendicular offset, as before a cancel move, and the tool stays there; the next
        move leaves that point uncompensated. Outside CANCEL it is `flush()`.
        """
        self._settle_wall_gouge()
        out = self.flush()
        if self._mode is _Mode.CANCEL:
            self._mode = _Mode.INACTIVE
            self._released = None
            self._window.clear()  # the next G41/G42 starts a new contour
        return out

    def flush(self) -> list[Segment]:
        """End of program or a synchronisation point: emit everything held back.

        The held element ends at its perpendicular offset (as Fanuc does when a block
        without motion breaks the read-ahead). Compensation stays on; if the next element
        then makes an inside corner with it, that is a gouge (the released element can no
        longer be trimmed) and push() raises.
        """
        self._settle_wall_gouge()
        if self._held is not None:
            self._stage(self._finish_held(), self._idx)
        self._settle_wall_gouge()
        return self._release(everything=True)

    # --- interference check -------------------------------------------------------------

    def _add_contour(self, seg: Segment, elem: g.OffsetElement) -> None:
        """Register a new programmed contour element and check the held output against it."""
        self._idx += 1
        if seg.rapid:
            return  # a positioning move's programmed path is no wall: not in the window
        if seg.kind == "line":
            shape: clash.Element = (seg.start, seg.end)
        else:
            assert seg.center is not None
            full = elem.sweep >= 2.0 * math.pi
            shape = clash.Arc.of(seg.start, seg.end, seg.center, seg.ccw, full)
        box = clash.bbox(shape)
        self._window.append((self._idx, seg, shape, box))
        for staged in self._queue:
            if staged.shape is not None and staged.tag >= self._idx - self._lookahead:
                self._interfere(staged, seg, shape, box, newest=True)

    def _stage(self, outs: list[Segment], tag: int) -> None:
        checking = self._lookahead > 0 and self._r > self._tol
        for seg in outs:
            own = self._idx if seg.role in ("corner", "startup") else tag
            shape: clash.Element | None = None
            if checking and seg.role in ("contour", "corner") and seg.start != seg.end:
                shape = (seg.start, seg.end)
                if seg.kind == "arc":
                    assert seg.center is not None
                    shape = clash.Arc.of(seg.start, seg.end, seg.center, seg.ccw, False)
            elif checking and seg.kind == "arc" and seg.role == "contour":
                assert seg.center is not None  # a full circle: start == end
                shape = clash.Arc.of(seg.start, seg.end, seg.center, seg.ccw, True)
            staged = _Staged(seg, own, shape, None if shape is None else clash.bbox(shape))
            if shape is not None:
                # A trimmed element keeps exactly r from its own programmed element by
                # construction; a corner arc need not (an arc after it may curl back).
                skip = own if seg.role == "contour" else -1
                for idx, prog, pshape, pbox in self._window:
                    if idx >= own and idx != skip:
                        self._interfere(staged, prog, pshape, pbox, newest=idx == self._idx)
            self._queue.append(staged)

    def _interfere(
        self,
        staged: _Staged,
        prog: Segment,
        pshape: clash.Element,
        pbox: clash.Box,
        newest: bool = False,
    ) -> None:
        """Refuse a staged path closer than r to a programmed element; against the newest
        element the refusal waits for the next push (`_settle_wall_gouge`)."""
        assert staged.shape is not None and staged.box is not None
        # two elements may each have been moved by the slack, towards each other
        limit = self._r - max(g.INTERFERENCE_TOL_REL * self._scale, 2.0 * self._slack)
        if clash.box_gap(staged.box, pbox) >= limit:
            return
        d = clash.distance(staged.shape, pshape)
        if d < limit:
            err = self._gouge(
                staged.seg,
                f"the tool path of this block passes {d:.6g} from the programmed contour of "
                f"line {prog.line}, {self._r - d:.6g} closer than the tool radius "
                f"{self._r:.6g} (interference check over {self._lookahead} elements)",
            )
            if not newest:
                raise err
            if self._wall_gouge is None:
                self._wall_gouge = err

    def _settle_wall_gouge(self) -> None:
        """Raise the gouge held against the newest element unless it was a lead-out.

        A lead-out is the last element before the cancel move that leaves the contour
        tangentially, curving to the tool side: it runs through the area the tool has just
        cleared (the inside of a bore after the full circle), so an earlier element's tool
        path crossing it cuts air. Fanuc's interference check (a direction check on the
        compensation vectors) does not refuse it either.
        """
        err = self._wall_gouge
        if err is None:
            return
        self._wall_gouge = None
        if not (self._mode is _Mode.CANCEL and self._newest_leaves_to_tool_side):
            raise err

    def _release(self, everything: bool = False) -> list[Segment]:
        """Hand over the segments no later element can still veto."""
        out: list[Segment] = []
        q = self._queue
        while q and (everything or q[0].tag + self._lookahead <= self._idx):
            out.append(q.popleft().seg)
        return out

    # --- corners ----------------------------------------------------------------------

    def _corner(self, held: _Held, b: g.OffsetElement, bseg: Segment) -> list[Segment]:
        a = held.elem
        corner = a.p1
        ne, ns = a.off_end, b.off_start
        t_in, t_out = a.tangent_end(), b.tangent_start()
        turn = g.cross(t_in, t_out)
        tol = self._tol
        inserts: list[Segment] = []
        if g.dist(ne, ns) <= tol:
            x = xb = ne  # tangent junction: offsets meet, nothing to insert
        elif self._side * turn > 0.0:  # inside corner: trim both to their intersection
            hit = self._line_line_meet(a, b, -1.0) or g.intersect_offsets(a, b, corner)
            if hit is None:
                raise self._gouge(
                    bseg,
                    f"the offset of this element does not meet the offset of line {held.seg.line} "
                    "at their inside corner",
                )
            x = xb = hit
        elif a.kind == "line" and b.kind == "line" and g.turn_angle(t_in, t_out) <= g.SHALLOW_ANGLE:
            x = xb = self._line_line_meet(a, b, 1.0) or ne
        else:  # outside corner: roll around the programmed corner with the tool radius
            x, xb = ne, ns
            inserts.append(self._corner_arc(ne, ns, corner, bseg))
        out = [self._contour(held, x, a.param(x, near_end=True, tol=tol))]
        out.extend(self._trail_at(x))
        out.extend(inserts)
        b.ps, b.ts = xb, b.param(xb, near_end=False, tol=self._tol)
        self._tool = xb
        return out

    def _line_line_meet(self, a: g.OffsetElement, b: g.OffsetElement, way: float) -> Point | None:
        """Where two offset lines meet, walked from A's perpendicular end along A.

        The distance is r*tan(turn/2) = r*|sin|/(1+cos): exact to rounding even for the
        nearly parallel lines of shallow corners, unlike a general 2x2 solve. `way` is -1
        to trim (inside corner), +1 to extend (shallow outside corner).
        """
        if a.kind != "line" or b.kind != "line":
            return None
        c, d = g.cross(a.d, b.d), g.dot(a.d, b.d)
        if 1.0 + d <= 1e-12:
            return None
        k = way * self._r * abs(c) / (1.0 + d)
        return (a.off_end[0] + a.d[0] * k, a.off_end[1] + a.d[1] * k)

    def _corner_after_sync(
        self, a: g.OffsetElement, b: g.OffsetElement, bseg: Segment
    ) -> list[Segment]:
        ne, ns = a.off_end, b.off_start
        out: list[Segment] = []
        if g.dist(ne, ns) <= self._tol:
            xb = ne
        elif self._side * g.cross(a.tangent_end(), b.tangent_start()) > 0.0:
            raise self._gouge(
                bseg,
                "inside corner right after a synchronisation point (the previous element was "
                "already released up to its perpendicular end and cannot be trimmed); keep "
                "non-motion blocks that wait for the machine out of compensated contours",
            )
        else:
            xb = ns
            out.append(self._corner_arc(ne, ns, a.p1, bseg))
        b.ps, b.ts = xb, b.param(xb, near_end=False, tol=self._tol)
        self._tool = xb
        return out

    def _corner_arc(self, ne: Point, ns: Point, corner: Point, bseg: Segment) -> Segment:
        # Going around an outside corner turns against the tool side: clockwise for G41.
        return Segment(
            "arc", ne, ns, corner, self._side < 0, bseg.line, bseg.col, bseg.payload, "corner"
        )

    # --- emitting -----------------------------------------------------------------------

    def _finish_held(self) -> list[Segment]:
        held = self._held
        assert held is not None
        a = held.elem
        if held.startup:
            out = [self._startup_segment(held, a.off_end)]
        else:
            out = [self._contour(held, a.off_end, a.off_length)]
        out.extend(self._trail_at(a.off_end))
        self._tool = a.off_end
        self._released = a
        self._held = None
        return out

    def _contour(self, held: _Held, pe: Point, te: float) -> Segment:
        a, seg = held.elem, held.seg
        length = te - a.ts
        if length <= self._tol:
            raise self._gouge(
                seg,
                "the compensated element "
                + ("vanishes" if length > -self._tol else "reverses direction")
                + f" (offset length {length:.6g}): the element is too short for a tool of "
                f"radius {self._r:.6g} at its inside corner(s) (Fanuc PS0041 interference in "
                "CRC: a groove or step narrower than the tool)",
            )
        self._tool = pe
        if a.kind == "line":
            return Segment("line", a.ps, pe, None, False, seg.line, seg.col, seg.payload)
        full = 2.0 * math.pi * a.off_radius
        if length > full + self._tol:
            raise self._gouge(seg, "the compensated arc would exceed a full turn")
        if length >= full - self._tol:
            pe = a.ps  # a full circle stays a full circle (start == end)
        return Segment("arc", a.ps, pe, a.center, a.ccw, seg.line, seg.col, seg.payload)

    def _startup_segment(self, held: _Held, end: Point) -> Segment:
        seg = held.seg
        self._tool = end
        return Segment(
            "line", seg.start, end, None, False, seg.line, seg.col, seg.payload, "startup"
        )

    def _trail_at(self, p: Point) -> list[Segment]:
        out = [self._place(s, p) for s in self._trail]
        self._trail = []
        return out

    def _at_tool(self, seg: Segment) -> Segment:
        return self._place(seg, self._tool)

    @staticmethod
    def _place(seg: Segment, p: Point) -> Segment:
        if seg.kind == "arc":  # a radius-0 arc: no in-plane motion at all
            return replace(seg, kind="line", start=p, end=p, center=None)
        return replace(seg, start=p, end=p)

    # --- checks -------------------------------------------------------------------------

    def _element(self, seg: Segment) -> g.OffsetElement:
        if seg.kind == "line":
            return g.make_line(seg.start, seg.end, self._side, self._r)
        if seg.center is None:
            raise self._error(
                "cutter compensation: arc segment without a centre", seg.line, seg.col
            )
        full = g.dist(seg.start, seg.end) <= self._tol
        e = g.make_arc(seg.start, seg.end, seg.center, seg.ccw, self._side, self._r, full)
        if e.off_radius <= self._tol:
            raise self._gouge(
                seg,
                f"arc radius {e.radius:.6g} is not larger than the tool radius {self._r:.6g} "
                "on the inside of the arc",
            )
        return e

    def _validate(self, seg: Segment) -> None:
        if seg.kind not in ("line", "arc"):
            raise self._error(
                f"cutter compensation: unknown segment kind {seg.kind!r}", seg.line, seg.col
            )
        coords = [*seg.start, *seg.end, *(seg.center or ())]
        if not all(math.isfinite(c) for c in coords):
            raise self._error(
                "cutter compensation: non-finite coordinate in the move", seg.line, seg.col
            )

    def _is_zero(self, seg: Segment) -> bool:
        if seg.kind == "arc":
            return seg.center is not None and g.dist(seg.start, seg.center) <= self._tol
        return g.dist(seg.start, seg.end) <= self._tol

    def _check_continuity(self, seg: Segment) -> None:
        if self._prog is None:
            return
        gap = g.dist(seg.start, self._prog)
        if gap > g.CONTINUITY_TOL_REL * self._scale:
            raise self._error(
                f"cutter compensation: this move starts {gap:.6g} away from where the previous "
                "one ended (was a work offset or G92 changed while compensation is on?)",
                seg.line,
                seg.col,
            )

    @property
    def _tol(self) -> float:
        return g.LEN_TOL_REL * self._scale

    def _grow_scale(self, seg: Segment) -> None:
        m = max(abs(seg.start[0]), abs(seg.start[1]), abs(seg.end[0]), abs(seg.end[1]))
        if seg.center is not None:
            m = max(m, abs(seg.center[0]), abs(seg.center[1]))
        if m > self._scale and math.isfinite(m):
            self._scale = m

    def _gouge(self, seg: Segment, detail: str) -> NcError:
        return self._error(f"cutter compensation gouge: {detail}", seg.line, seg.col)

    def _error(self, message: str, line: int, col: int) -> NcError:
        return NcError(message, line, col, self._file)
