"""Lathe cycles (Fanuc T, G-code system A): the code handlers and their contour reader.

G70 finishing, G71/G72 stock removal (turning / facing, type I and II), G73 pattern
repeating, G74/G75 face / OD grooving (peck drilling), G76 multi-pass threading: non-modal
codes whose handler reads the block's words (Fanuc two-block format or the one-block format
of Haas and the Fanuc 0-TC), reads the contour between the blocks numbered P and Q where
the cycle needs one, computes the pass list with the pure functions of
cnc.interp.lathe_geometry and emits it through the interpreter's move emitters — so the
generated path comes out of the interpreter as ordinary canonical moves (offsets, soft
limits and `nc plan` traces apply as to programmed moves).

G32 thread cutting and the G90/G92/G94 single cycles are modal (Fanuc group 01; here the
interpreter's cycle mode, cancelled by G0..G3 or G80 like the mill's canned cycles): a
block with only X (or Z) under G90 repeats the cycle to the new point.

Threading feed: F is the lead (mm/rev, in/rev under G20); the feed along the thread's long
axis is lead x spindle rpm at the start of the pass (under G96, the speed at the pass's
start diameter, clamped by G50 S). A lead whose axis feed exceeds the axis' maximum
velocity (or the machine's maximum feed) is refused.

Alarm numbers are Fanuc's (Series 0i-TF): PS0061 P or Q missing, PS0062 an illegal value
(depth, count), PS0063 the block of a sequence number not found, PS0064 / PS0329 the
finishing shape not monotonic (first / second axis), PS0065 the ns block not G00/G01,
PS0066 a code not allowed between the ns and nf blocks.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from cnc.canon import ArcFeed, Plane, SpindleDirection, SpindleSync, StraightFeed, ThreadFeed
from cnc.errors import NcError
from cnc.gcode.lexer import Block, MarkedBlock, parse_line
from cnc.gcode.source import _read_file_from
from cnc.interp import lathe_geometry as lg
from cnc.interp.gnum import G0, G1, G2, G3, G40, G41, G42, G80

if TYPE_CHECKING:
    from cnc.interp.context import BlockRun, Context

MAX_CONTOUR_LINES = 100_000  # lines between N p and N q
MAX_CYCLE_MOVES = 1_000_000
DEFAULT_RETRACT_MM = 0.5  # G71/G72 e (Fanuc parameter 5133) when no first block gave R
DEFAULT_GROOVE_RETRACT_MM = 0.254  # G74/G75 e (Haas setting 22: 0.010 in)
DEFAULT_THREAD_ANGLE = 60.0  # Fanuc G76 P...aa when no first block gave it
_CONTOUR_G = frozenset((G0, G1, G2, G3, G40, G41, G42))
_FLOW_M = frozenset((2, 30, 98, 99))


class LatheCycleData:
    """Modal data of the lathe cycles: the first blocks' words, the single cycle's point."""

    __slots__ = (
        "depth71",
        "retract71",
        "depth72",
        "retract72",
        "g73",
        "retract74",
        "retract75",
        "g76",
        "single",
        "contours",
        "thread_end",
    )

    def __init__(self) -> None:
        self.depth71: float | None = None
        self.retract71 = DEFAULT_RETRACT_MM
        self.depth72: float | None = None
        self.retract72 = DEFAULT_RETRACT_MM
        self.g73: tuple[float, float, int] | None = None  # Δi (radius), Δk, divisions
        self.retract74 = DEFAULT_GROOVE_RETRACT_MM
        self.retract75 = DEFAULT_GROOVE_RETRACT_MM
        # finishing passes m, chamfer (x 0.1 lead), tool angle a, minimum cut, allowance d
        self.g76: tuple[int, float, float, float, float] = (1, 0.0, DEFAULT_THREAD_ANGLE, 0.0, 0.0)
        # modal single cycle: start point, end point (x radius, z), taper, lead
        self.single: dict[str, object] = {}
        self.contours: dict[tuple, list[tuple[int, str]]] = {}
        self.thread_end: tuple[float, ...] | None = None  # machine point of the last thread move


def state(ip: Context) -> LatheCycleData:
    st = getattr(ip, "lcyc", None)
    if st is None:
        st = LatheCycleData()
        ip.lcyc = st  # type: ignore[attr-defined]
    return st


# --- errors -----------------------------------------------------------------------------


def _alarm(ip: Context, blk: Block, msg: str, alarm: str = "", letter: str | None = None):
    text = f"{alarm} {msg}" if alarm else msg
    return ip._err(text, blk, letter)


def _at_line(ip: Context, line: int, text: str, msg: str, alarm: str = "") -> NcError:
    fr = ip._frames[-1] if ip._frames else None  # type: ignore[attr-defined]
    stripped = text.lstrip()
    col = len(text) - len(stripped) + 1 if stripped else 1
    return NcError(f"{alarm} {msg}" if alarm else msg, line, col, fr.file if fr else ip.file)


# --- words ------------------------------------------------------------------------------


def _radius(ip: Context, blk: Block, letter: str) -> float:
    """A diameter word (X, U as an allowance) as a radius in mm."""
    v = ip._dim(blk, letter)
    return v * 0.5 if ip._diam else v


def _increments(ip: Context, blk: Block, letter: str) -> float:
    """A Fanuc P/Q depth word of G74-G76: least increments without a point (µm, 0.0001 in)."""
    if "." in _word_text(blk, letter):
        return ip._dim(blk, letter)
    inc = ip.params.least_increment_inch * 25.4 if ip._inch else ip.params.least_increment_mm
    return blk.words[letter] * inc


def _word_text(blk: Block, letter: str) -> str:
    col = blk.col(letter) - 1
    text = blk.text
    i = col + 1
    while i < len(text) and (text[i] in "+-.0123456789 \t"):
        i += 1
    return text[col:i]


def _seq(ip: Context, blk: Block, letter: str, code: str) -> int:
    if letter not in blk.words:
        raise _alarm(
            ip,
            blk,
            f"{code} needs P and Q (the contour's first and last sequence numbers)",
            "PS0061",
            "G",
        )
    v = blk.words[letter]
    if v != int(v) or v < 0:
        raise _alarm(ip, blk, f"{code} {letter} must be a sequence number", "PS0061", letter)
    return int(v)


# --- the contour ------------------------------------------------------------------------


def _reopen(ip: Context):
    """The current program's lines again from its start, or None for a streamed program."""
    fr = ip._frames[-1]  # type: ignore[attr-defined]
    lib = ip._lib  # type: ignore[attr-defined]
    if fr.number is not None:
        opened = lib.open(fr.number)
        return opened[0] if opened else None
    idx = lib.in_file
    if idx is None:
        return None
    seq = getattr(idx, "seq", None)
    if seq is not None:
        return ((i + 1, seq[i]) for i in range(len(seq)))
    return _read_file_from(idx.path, 0, 1)


def _n_of(ip: Context, lineno: int, text: str, file: str) -> tuple[Block | None, int | None]:
    b = parse_line(text, lineno, file, ip._li)  # type: ignore[attr-defined]
    if b is None:
        return None, None
    n = b.words.get("N")
    return b, (int(n) if n is not None else None)


def contour_lines(
    ip: Context, blk: Block, p: int, q: int, code: str, consume: bool
) -> list[tuple[int, str]]:
    """The source lines from the block numbered N p to the one numbered N q.

    When the N p block is the next block (the usual G71/G72/G73 layout) and `consume` is
    set, the lines are taken from the program stream: execution resumes after N q. Else
    the program is read again from its start (a file, a stored program or an in-memory
    text; a streamed program can only have its contour after the cycle block).
    """
    fr = ip._frames[-1]  # type: ignore[attr-defined]
    key = (fr.file, fr.number, p, q)
    st = state(ip)
    it = fr.it
    if consume and hasattr(it, "push"):
        pulled: list[tuple[int, str]] = []
        got = None
        for item in it:
            pulled.append(item)
            try:
                b, n = _n_of(ip, item[0], item[1], fr.file)
            except NcError:
                break
            if b is None:
                continue
            if n == p:
                got = _collect(ip, blk, [item], it, q, code, fr.file)
            break
        if got is not None:
            st.contours[key] = got
            return got
        for item in reversed(pulled):
            it.push(item)
    cached = st.contours.get(key)
    if cached is not None:
        return cached
    src = _reopen(ip)
    if src is None:
        raise _alarm(
            ip,
            blk,
            f"{code}: the block N{p} does not follow the cycle and the program is streamed "
            "(it cannot be read again)",
            "PS0063",
            "P",
        )
    for item in src:
        try:
            b, n = _n_of(ip, item[0], item[1], fr.file)
        except NcError:
            continue
        if n == p:
            got = _collect(ip, blk, [item], src, q, code, fr.file)
            st.contours[key] = got
            return got
    raise _alarm(ip, blk, f"{code}: no block with sequence number N{p} (P)", "PS0063", "P")


def _collect(ip, blk, first, it, q: int, code: str, file: str) -> list[tuple[int, str]]:
    lines = list(first)
    _, n = _n_of(ip, first[0][0], first[0][1], file)
    n0 = n
    if n == q:
        return lines
    for item in it:
        lines.append(item)
        if len(lines) > MAX_CONTOUR_LINES:
            break
        b, n = _n_of(ip, item[0], item[1], file)
        if n == q:
            return lines
    raise _alarm(
        ip,
        blk,
        f"{code}: no block with sequence number N{q} (Q) after the block N{n0}",
        "PS0063",
        "Q",
    )


def read_contour(
    ip: Context, lines: list[tuple[int, str]], code: str
) -> tuple[tuple[lg.Seg, ...], Block, bool]:
    """The contour's elements from A (the tool now) through A' to B, the ns block, and
    whether the ns block names Z (W): (segments, ns block, ns_has_z).

    Geometry only: X/Z/U/W end points (diameter, units and the decimal rule as for any
    block), G0..G3 with R or I/K. G40/G41/G42 and F, S, T words are allowed (they act in
    G70); any other G code, and M98/M99/M2/M30, is refused (PS0066).
    """
    fr = ip._frames[-1]  # type: ignore[attr-defined]
    saved = ip._pos
    x, y, z = saved
    motion: int | None = None
    segs: list[lg.Seg] = []
    ns: Block | None = None
    ns_z = False
    try:
        for lineno, text in lines:
            b = parse_line(text, lineno, fr.file, ip._li)  # type: ignore[attr-defined]
            if b is None:
                continue
            if type(b) is MarkedBlock and b.delete and ip.block_delete:  # type: ignore[attr-defined]
                continue  # a `/` block with BLOCK DELETE on is not part of the contour
            if type(b) is MarkedBlock and (b.tape or b.program is not None):
                raise _at_line(
                    ip, lineno, text, f"{code}: program mark inside the contour", "PS0066"
                )
            for i, g in enumerate(b.g):
                if g in _CONTOUR_G:
                    if g <= G3:
                        motion = g
                    continue
                raise ip._err(
                    f"PS0066 {code}: G{g / 10:g} is not allowed between the contour's first and "
                    "last block",
                    b,
                    "G",
                    i + 1,
                )
            for i, m in enumerate(b.m):
                if m in _FLOW_M:
                    raise ip._err(f"PS0066 {code}: M{m} inside the contour", b, "M", i + 1)
            if ns is None:
                ns = b
                if motion not in (G0, G1) or not any(k in b.words for k in "XZUW"):
                    raise ip._err(
                        f"PS0065 {code}: the contour's first block (N P) must be G00 or G01 with "
                        "X (U)",
                        b,
                    )
                ns_z = "Z" in b.words or "W" in b.words
            if not any(k in b.words for k in "XZUW"):
                continue
            ip._pos = (x, y, z)
            tx, _, tz = ip._target(b, b.words)
            if motion in (G0, G1):
                if abs(tx - x) > lg.EPS or abs(tz - z) > lg.EPS:
                    segs.append(
                        lg.Seg(
                            lg.RAPID if motion == G0 else lg.FEED, (x, z), (tx, tz), None, lineno
                        )
                    )
            else:
                c = _arc_centre(ip, b, (x, z), (tx, tz), motion == G2)
                segs.append(lg.Seg(lg.CW if motion == G2 else lg.CCW, (x, z), (tx, tz), c, lineno))
            x, z = tx, tz
    finally:
        ip._pos = saved
    assert ns is not None
    return tuple(segs), ns, ns_z


def _arc_centre(ip: Context, b: Block, s: tuple[float, float], e: tuple[float, float], cw: bool):
    """The arc's centre (x, z) in the ZX plane (I, K incremental from the start; or R)."""
    words = b.words
    if "R" in words:
        r = ip._dim(b, "R")
        # in the plane u = Z, v = X (as the interpreter's G18 arcs)
        su, sv, eu, ev = s[1], s[0], e[1], e[0]
        du, dv = eu - su, ev - sv
        chord = math.hypot(du, dv)
        if chord < lg.EPS:
            raise ip._err("PS0066 R arc with start point equal to end point", b, "R")
        half = chord / 2.0
        rr = abs(r)
        if rr < half - ip.arc_tolerance:  # type: ignore[attr-defined]
            raise ip._err(
                f"arc radius R{rr:.4f} mm is smaller than half the chord {half:.4f} mm", b, "R"
            )
        h = math.sqrt(max(rr * rr - half * half, 0.0))
        side = -1.0 if cw else 1.0
        if r < 0:
            side = -side
        cu = su + du / 2.0 - dv / chord * h * side
        cv = sv + dv / 2.0 + du / chord * h * side
        return (cv, cu)
    if "I" not in words and "K" not in words:
        raise ip._err("arc needs R or a centre (I/K)", b, "G")
    oi = ip._dim(b, "I") if "I" in words else 0.0
    ok = ip._dim(b, "K") if "K" in words else 0.0
    c = (s[0] + oi, s[1] + ok)
    r1 = math.hypot(s[0] - c[0], s[1] - c[1])
    r2 = math.hypot(e[0] - c[0], e[1] - c[1])
    tol = ip.arc_tolerance  # type: ignore[attr-defined]
    if r1 < lg.EPS or abs(r1 - r2) > tol:
        raise ip._err(
            f"arc start radius {r1:.4f} mm and end radius {r2:.4f} mm differ by "
            f"{abs(r1 - r2):.4f} mm (tolerance {tol:g} mm)",
            b,
            "I" if "I" in words else "K",
        )
    return c


def _profile(segs: tuple[lg.Seg, ...]) -> tuple[lg.Seg, ...]:
    """The contour from A' to B: without the approach (the ns block) and without trailing
    rapids (a retract programmed at the end of the contour is not part of the shape)."""
    prof = list(segs[1:]) if segs else []
    while prof and prof[-1].kind == lg.RAPID:
        prof.pop()
    return tuple(prof)


# --- emitting ---------------------------------------------------------------------------


def emit(
    ip: Context, blk: Block, moves: list[lg.Move], lead: float | None = None, exact: bool = True
) -> None:
    if len(moves) > MAX_CYCLE_MOVES:
        raise ip._err(f"cycle expands to more than {MAX_CYCLE_MOVES} moves", blk, "G")
    y = ip._pos[1]
    for kind, x, z, cx, cz in moves:
        p = (x, y, z)
        if kind == lg.RAPID:
            ip._line_to(p, None, blk, exact)
        elif kind == lg.FEED:
            ip._line_to(p, ip._feed(blk), blk, exact)
        elif kind == lg.THREAD:
            assert lead is not None
            thread_to(ip, blk, p, lead)
        else:
            _arc_to(ip, blk, p, (cx, y, cz), kind == lg.CW, ip._feed(blk), exact)


def _arc_to(ip: Context, blk: Block, p, c, cw: bool, feed: float, exact: bool) -> None:
    o = ip._off
    m = (p[0] + o[0], 0.0, p[2] + o[2])
    mc = (c[0] + o[0], 0.0, c[2] + o[2])
    ip._check(m, blk, blk.line)
    ip._check_arc_extent(ip._mach, m, mc, cw, 0, blk)  # type: ignore[attr-defined]
    ip._out.append(ArcFeed(blk.line, m, mc, Plane.ZX, cw, feed, 0, exact))
    ip._pos = p
    ip._mach = m
    ip._moved = True


def thread_to(ip: Context, blk: Block, p, lead: float) -> None:
    """One spindle-synchronised thread move: axis feed = lead x rpm along the long axis."""
    s = ip._pos
    dx, dz = abs(p[0] - s[0]), abs(p[2] - s[2])
    long = max(dx, dz)
    if long < lg.EPS:
        return
    rpm = ip._rpm_now_from(ip._s, ip._css)
    if rpm <= 0.0:
        raise ip._err("thread cutting with no spindle speed (S)", blk, "G")
    if ip._spindle not in (SpindleDirection.CW, SpindleDirection.CCW):
        raise ip._err("thread cutting with the spindle stopped (M3 or M4 first)", blk, "G")
    axis = "Z" if dz >= dx else "X"
    f_axis = lead * rpm
    vmax = ip.params.max_feed
    what = f"machine maximum feed {vmax:g} mm/min"
    for ax in ip.params.axes:
        if ax.name == axis and ax.max_velocity < vmax:
            vmax = ax.max_velocity
            what = f"{axis} axis maximum {vmax:g} mm/min"
    if f_axis > vmax + 1e-9:
        raise ip._err(
            f"thread lead {lead:g} mm at {rpm:g} rpm needs {f_axis:g} mm/min on {axis}, above the "
            f"{what} (lower S or the lead)",
            blk,
            "F" if "F" in blk.words else "G",
        )
    feed = f_axis * math.hypot(dx, dz) / long
    st = state(ip)
    if st.thread_end != ip._mach:
        # a new pass (not the continuation of the last thread move): start on the index
        ip._emit(SpindleSync(blk.line))
    ip._line_to(p, feed, blk, True)
    last = ip._out[-1]
    if type(last) is StraightFeed:  # the controller keeps the lead (cnc.canon.ThreadFeed)
        ip._out[-1] = ThreadFeed(last.line, last.end, last.feed, last.exact_stop, lead, rpm)
    st.thread_end = ip._mach


def _lead(ip: Context, blk: Block, code: str) -> float:
    st = state(ip)
    if "F" in blk.words:
        lead = blk.words["F"] * ip._scale
        st.single["lead"] = lead
    else:
        lead = st.single.get("lead")  # type: ignore[assignment]
        if lead is None:
            raise ip._err(f"{code} needs F (the thread lead)", blk, "G")
    if lead <= 0.0:
        raise _alarm(ip, blk, f"{code} thread lead must be greater than 0", "PS0062", "F")
    return float(lead)


def _start(ip: Context) -> tuple[float, float]:
    return (ip._pos[0], ip._pos[2])


def _no_comp(ip: Context, blk: Block, code: str) -> None:
    if ip._comp_engaged():
        raise ip._err(f"{code} with tool nose radius compensation active (G40 first)", blk, "G")


def _geometry(ip: Context, blk: Block, fn, *args):
    try:
        return fn(*args)
    except lg.CycleGeometryError as exc:
        raise _alarm(ip, blk, exc.message, exc.alarm, "G") from None


# --- G70 .. G73: contour cycles ---------------------------------------------------------


def finishing(ip: Context, run: BlockRun) -> None:
    """G70 P Q: the contour's blocks run as programmed (their F S T act), then back to A.

    Haas programs may give U/W on G70: the finishing path is then translated by them (the
    stock the finishing tool leaves), as on G71.
    """
    blk = run.blk
    p, q = _seq(ip, blk, "P", "G70"), _seq(ip, blk, "Q", "G70")
    _no_comp(ip, blk, "G70")
    lines = contour_lines(ip, blk, p, q, "G70", consume=False)
    read_contour(ip, lines, "G70")  # the same checks as the roughing cycles
    start = ip._pos
    motion = ip._motion
    du = _radius(ip, blk, "U") if "U" in blk.words else 0.0
    dw = ip._dim(blk, "W") if "W" in blk.words else 0.0
    g92 = ip._g92
    if du or dw:
        g92[0] += du
        g92[2] += dw
        ip._refresh_offsets(resync=False)
    fr = ip._frames[-1]  # type: ignore[attr-defined]
    try:
        for lineno, text in lines:
            b = parse_line(text, lineno, fr.file, ip._li)  # type: ignore[attr-defined]
            if b is not None:
                ip._block(b, fr)  # type: ignore[attr-defined]
    finally:
        if du or dw:
            g92[0] -= du
            g92[2] -= dw
            ip._refresh_offsets(resync=False)
    ip._line = blk.line  # type: ignore[attr-defined]
    if ip._comp_engaged():
        raise ip._err(
            "G70: the contour leaves tool nose compensation on (end it with G40)", blk, "G"
        )
    ip._line_to(start, None, blk, True)
    ip._motion = motion


def _contour_cycle(ip: Context, blk: Block, code: str, consume: bool = True):
    p, q = _seq(ip, blk, "P", code), _seq(ip, blk, "Q", code)
    _no_comp(ip, blk, code)
    lines = contour_lines(ip, blk, p, q, code, consume=consume)
    segs, ns, ns_z = read_contour(ip, lines, code)
    prof = _profile(segs)
    if not prof:
        raise _alarm(
            ip,
            blk,
            f"{code}: the contour N{p}..N{q} has no element after its first block",
            "PS0062",
            "P",
        )
    return segs, prof, ns, ns_z, lines


def _allowance(ip: Context, blk: Block) -> tuple[float, float]:
    du = _radius(ip, blk, "U") if "U" in blk.words else 0.0
    dw = ip._dim(blk, "W") if "W" in blk.words else 0.0
    return du, dw


def _fault_error(ip, lines, fault, prof, code, type2: bool, facing: bool):
    idx, axis = fault
    line = prof[idx].line
    text = next((t for n, t in lines if n == line), "")
    first = "Z" if facing else "X"
    alarm = "PS0064" if axis == first else "PS0329"
    kind = (
        "type II needs Z"
        if type2 and not facing
        else ("type II needs X" if type2 else "type I needs X and Z")
    )
    return _at_line(
        ip,
        line,
        text,
        f"{code}: the finishing shape is not monotonic in {axis} ({kind} to move one way only)",
        alarm,
    )


def stock_removal(ip: Context, run: BlockRun) -> None:
    """G71 (turning) / G72 (facing) stock removal, two-block or one-block format."""
    blk = run.blk
    words = blk.words
    code = run.rows["nonmodal"].name
    facing = code == "G72"
    st = state(ip)
    if "P" not in words and "Q" not in words:
        # first block: G71 U(depth) R(retract) / G72 W(depth) R(retract)
        dl = "W" if facing else "U"
        if dl not in words and "R" not in words:
            raise _alarm(
                ip, blk, f"{code} needs P and Q (or {dl} and R in a first block)", "PS0061", "G"
            )
        if dl in words:
            d = ip._dim(blk, dl)
            if d <= 0:
                raise _alarm(
                    ip, blk, f"{code} depth of cut {dl} must be greater than 0", "PS0062", dl
                )
            if facing:
                st.depth72 = d
            else:
                st.depth71 = d
        if "R" in words:
            e = ip._dim(blk, "R")
            if e < 0:
                raise _alarm(ip, blk, f"{code} retract R must not be negative", "PS0062", "R")
            if facing:
                st.retract72 = e
            else:
                st.retract71 = e
        return
    if "D" in words:
        depth = ip._dim(blk, "D")
        if depth <= 0:
            raise _alarm(ip, blk, f"{code} depth of cut D must be greater than 0", "PS0062", "D")
    else:
        depth = st.depth72 if facing else st.depth71
        if depth is None:
            raise _alarm(
                ip,
                blk,
                f"{code} needs the depth of cut (D, or {'W' if facing else 'U'} in a first {code} block)",
                "PS0062",
                "G",
            )
    retract = st.retract72 if facing else st.retract71
    explicit2 = "R" in words and words["R"] == 1
    if "R" in words and not explicit2:
        raise _alarm(ip, blk, f"{code} R in the P/Q block selects type II (R1)", "PS0062", "R")
    segs, prof, ns, ns_z, lines = _contour_cycle(ip, blk, code)
    ns_other = ("X" in ns.words or "U" in ns.words) if facing else ns_z
    check = lg.swap(prof) if facing else prof
    fault1 = lg.monotony_fault(check, True)
    type2 = explicit2 or (ns_other and fault1 is not None)
    fault = lg.monotony_fault(check, not type2)
    if fault is not None:
        # in the swapped frame "X" is Z
        idx, axis = fault
        if facing:
            axis = "Z" if axis == "X" else "X"
        raise _fault_error(ip, lines, (idx, axis), prof, code, type2, facing)
    start = _start(ip)
    allow = _allowance(ip, blk)
    fn = lg.rough_facing if facing else lg.rough_turning
    moves = _geometry(ip, blk, fn, start, prof, depth, retract, allow, type2)
    emit(ip, blk, moves)


def pattern_repeating(ip: Context, run: BlockRun) -> None:
    """G73: two-block (U Δi W Δk R d; P Q U W F) or Haas one-block (P Q I K U W D F)."""
    blk = run.blk
    words = blk.words
    st = state(ip)
    if "P" not in words and "Q" not in words:
        if not any(k in words for k in "UWR"):
            raise _alarm(
                ip, blk, "G73 needs P and Q (or U, W and R in a first block)", "PS0061", "G"
            )
        old = st.g73 or (0.0, 0.0, 1)
        di = ip._dim(blk, "U") if "U" in words else old[0]
        dk = ip._dim(blk, "W") if "W" in words else old[1]
        n = old[2]
        if "R" in words:
            r = words["R"]
            if r != int(r) or not 1 <= r <= lg.MAX_DIVISIONS:
                raise _alarm(
                    ip,
                    blk,
                    f"G73 R (divisions) must be a whole number 1..{lg.MAX_DIVISIONS}",
                    "PS0062",
                    "R",
                )
            n = int(r)
        st.g73 = (di, dk, n)
        return
    if "I" in words or "K" in words or "D" in words:  # Haas one-block format
        di = ip._dim(blk, "I") if "I" in words else 0.0
        dk = ip._dim(blk, "K") if "K" in words else 0.0
        d = words.get("D", 1)
        if d != int(d) or d < 1:
            raise _alarm(
                ip, blk, "G73 D (number of passes) must be a whole number 1 or more", "PS0062", "D"
            )
        n = int(d)
    elif st.g73 is not None:
        di, dk, n = st.g73
    else:
        raise _alarm(
            ip, blk, "G73 needs the relief and divisions (a first G73 U W R block)", "PS0062", "G"
        )
    segs, prof, ns, ns_z, lines = _contour_cycle(ip, blk, "G73")
    moves = _geometry(
        ip, blk, lg.pattern_repeat, _start(ip), prof, (di, dk), n, _allowance(ip, blk)
    )
    emit(ip, blk, moves)


# --- G74 / G75 ------------------------------------------------------------------------


def grooving(ip: Context, run: BlockRun) -> None:
    """G74 face grooving / peck drilling, G75 OD grooving (two-block or Haas one-block)."""
    blk = run.blk
    words = blk.words
    code = run.rows["nonmodal"].name
    face = code == "G74"
    st = state(ip)
    _no_comp(ip, blk, code)
    if not any(k in words for k in "XZUW"):
        if "R" not in words:
            raise _alarm(ip, blk, f"{code} needs X (U) or Z (W)", "PS0062", "G")
        e = ip._dim(blk, "R")
        if e < 0:
            raise _alarm(ip, blk, f"{code} retract R must not be negative", "PS0062", "R")
        if face:
            st.retract74 = e
        else:
            st.retract75 = e
        return
    start = _start(ip)
    tx, _, tz = ip._target(blk, words)
    end = (
        tx if any(k in words for k in "XU") else start[0],
        tz if any(k in words for k in "ZW") else start[1],
    )
    retract = st.retract74 if face else st.retract75
    relief = 0.0
    # the X step: Fanuc P (increments), Haas I (radius); the Z step: Fanuc Q, Haas K
    if "P" in words or "Q" in words:
        di = _increments(ip, blk, "P") if "P" in words else 0.0
        dk = _increments(ip, blk, "Q") if "Q" in words else 0.0
        if "R" in words:
            relief = ip._dim(blk, "R")
    else:
        di = ip._dim(blk, "I") if "I" in words else 0.0
        dk = ip._dim(blk, "K") if "K" in words else 0.0
        if "R" in words:
            relief = ip._dim(blk, "R")
    if di < 0 or dk < 0:
        raise _alarm(ip, blk, f"{code} peck and shift amounts must not be negative", "PS0062", "G")
    if face:
        moves = _geometry(ip, blk, lg.face_grooving, start, end, dk, di, retract, relief)
    else:
        moves = _geometry(ip, blk, lg.grooving, start, end, di, dk, retract, relief)
    emit(ip, blk, moves)


# --- G76 --------------------------------------------------------------------------------


def multi_threading(ip: Context, run: BlockRun) -> None:
    """G76 multi-pass threading: Fanuc two-block (P(m)(r)(a) Q R; X Z R P Q F) or Haas
    one-block (X Z K D F; I taper, A tool angle, P1..P4 cutting method)."""
    blk = run.blk
    words = blk.words
    st = state(ip)
    _no_comp(ip, blk, "G76")
    if not any(k in words for k in "XZUW"):
        if not any(k in words for k in "PQR"):
            raise _alarm(ip, blk, "G76 needs X (U) and Z (W)", "PS0062", "G")
        m, chamfer, angle, dmin, allow = st.g76
        if "P" in words:
            pv = words["P"]
            if pv != int(pv) or pv < 0:
                raise _alarm(ip, blk, "G76 P is six digits mmrraa", "PS0062", "P")
            pv = int(pv)
            m, rr, angle = pv // 10000, (pv // 100) % 100, float(pv % 100)
            if m < 1:
                raise _alarm(ip, blk, "G76 P: 1..99 finishing passes (mm)", "PS0062", "P")
            if angle not in (0.0, 29.0, 30.0, 55.0, 60.0, 80.0):
                raise _alarm(
                    ip,
                    blk,
                    f"G76 P: tool angle {angle:g} is not 80, 60, 55, 30, 29 or 0",
                    "PS0062",
                    "P",
                )
            chamfer = rr / 10.0
        if "Q" in words:
            dmin = _increments(ip, blk, "Q")
        if "R" in words:
            allow = ip._dim(blk, "R")
            if allow < 0:
                raise _alarm(
                    ip, blk, "G76 R finishing allowance must not be negative", "PS0062", "R"
                )
        st.g76 = (m, chamfer, angle, dmin, allow)
        return
    if not (("X" in words or "U" in words) and ("Z" in words or "W" in words)):
        raise _alarm(ip, blk, "G76 needs X (U) and Z (W)", "PS0062", "G")
    lead = _lead(ip, blk, "G76")
    start = _start(ip)
    tx, _, tz = ip._target(blk, words)
    m, chamfer, angle, dmin, allow = st.g76
    if "K" in words or "D" in words:  # Haas one-block
        if "K" not in words or "D" not in words:
            raise _alarm(
                ip, blk, "G76 (one-block) needs K (thread height) and D (first cut)", "PS0062", "G"
            )
        height = ip._dim(blk, "K")
        first = ip._dim(blk, "D")
        taper = ip._dim(blk, "I") if "I" in words else 0.0
        angle = ip._plain(blk, "A") if "A" in words else 0.0
        if not 0.0 <= angle <= 120.0:
            raise _alarm(ip, blk, "G76 A (tool angle) must be 0..120 degrees", "PS0062", "A")
        method = words.get("P", 1)
        if method not in (1, 2, 3, 4):
            raise _alarm(ip, blk, "G76 P (cutting method) must be 1, 2, 3 or 4", "PS0062", "P")
        if method in (1, 2):  # constant chip area: D sqrt(n)
            depths = _geometry(ip, blk, lg.thread_depths, height, first, 0.0, 0.0, 0)
        else:  # constant depth per pass
            depths = _geometry(ip, blk, lg.constant_depths, height, first)
        moves = _geometry(
            ip,
            blk,
            lg.thread_passes,
            start,
            (tx, tz),
            depths,
            height,
            taper,
            angle,
            0.0,
            method in (2, 4),
        )
    else:
        if "P" not in words or "Q" not in words:
            raise _alarm(
                ip, blk, "G76 needs P (thread height) and Q (first cut depth)", "PS0062", "G"
            )
        height = _increments(ip, blk, "P")
        first = _increments(ip, blk, "Q")
        taper = ip._dim(blk, "R") if "R" in words else 0.0
        depths = _geometry(ip, blk, lg.thread_depths, height, first, dmin, allow, m)
        moves = _geometry(
            ip, blk, lg.thread_passes, start, (tx, tz), depths, height, taper, angle, chamfer * lead
        )
    emit(ip, blk, moves, lead=lead)


# --- G32, G90, G92, G94: modal ------------------------------------------------------------


def modal_cycle(ip: Context, blk: Block, code: int | None) -> None:
    """A block under G32/G90/G92/G94 (or naming one): one pass of the single cycle."""
    words = blk.words
    st = state(ip)
    if code is not None:
        row = ip._gtab[code]  # type: ignore[attr-defined]
        if code != ip._cycle or not st.single.get("name"):
            st.single = {"lead": st.single.get("lead")}
        ip._cycle = code
        st.single["name"] = row.name
    name = st.single.get("name")
    if not any(k in words for k in "XZUW"):
        return
    if ip._comp_engaged():
        raise ip._err(f"{name} with tool nose radius compensation active (G40 first)", blk, "G")
    start = _start(ip)
    if name == "G32":
        lead = _lead(ip, blk, "G32")
        tx, _, tz = ip._target(blk, words)
        thread_to(ip, blk, (tx, ip._pos[1], tz), lead)
        return
    # the end point: words given now, else the cycle's last end point
    last = st.single.get("end")
    if last is None:
        if not (any(k in words for k in "XU") and any(k in words for k in "ZW")):
            raise _alarm(ip, blk, f"{name} needs X (U) and Z (W) in its first block", "", "G")
        last = start
    tx, _, tz = ip._target(blk, words)
    ex = tx if any(k in words for k in "XU") else last[0]  # type: ignore[index]
    ez = tz if any(k in words for k in "ZW") else last[1]  # type: ignore[index]
    st.single["end"] = (ex, ez)
    if "R" in words:
        st.single["taper"] = ip._dim(blk, "R")  # radius (G90/G92) or Z (G94) difference
    taper = float(st.single.get("taper") or 0.0)  # type: ignore[arg-type]
    if name == "G90":
        moves = lg.single_turning(start, (ex, ez), taper)
        emit(ip, blk, moves)
    elif name == "G94":
        moves = lg.single_facing(start, (ex, ez), taper)
        emit(ip, blk, moves)
    else:  # G92
        lead = _lead(ip, blk, "G92")
        moves = lg.single_thread(start, (ex, ez), taper)
        emit(ip, blk, moves, lead=lead)


def cancel_or_cycle(ip: Context, blk: Block, code: int | None, exact: bool) -> None:
    """The lathe's branch of cnc.interp.cycles.cycle_block (G80 cancels, as on the mill)."""
    if code == G80:
        ip._cycle = G80
        state(ip).single = {"lead": state(ip).single.get("lead")}
        ip._motion_block(blk, blk.words, exact, None)
        return
    modal_cycle(ip, blk, code)
