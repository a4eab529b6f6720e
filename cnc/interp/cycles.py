"""Canned cycles G73 G74 G76 G81-G89 (G80 cancel), expanded into canonical moves.

Functions of the interpreter context (cnc.interp.context.Context): the cycle keeps its
modal data (R, Z, Q, P, initial level) in a `CycleData` held by the interpreter (`ip.cyc`)
and emits every move through the interpreter's `_line_to`, so transforms, offsets and soft
limits apply exactly as to programmed moves. Cycle moves are exact stop (as LinuxCNC and
Fanuc run them, even under G64).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from cnc.canon import Dwell, ProgramStop, Spindle, SpindleDirection, StopKind
from cnc.gcode.lexer import Block
from cnc.interp import lathe_cycles
from cnc.interp.gnum import G73, G74, G76, G80, G82, G83, G84, G85, G86, G87, G88, G89, G98

if TYPE_CHECKING:
    from cnc.interp.context import Context

MAX_REPEAT = 9999  # K / L repeat counts
MAX_PECKS = 10000  # per hole, so a tiny Q cannot flood the planner
MAX_CYCLE_STEPS = 100_000  # holes x pecks from one cycle block
PECK_CLEARANCE_MM = 0.5  # G83: stop this far above the previous depth (Fanuc param 5115)
PECK_RETRACT_MM = 0.5  # G73: retract after each peck (Fanuc param 5114)
_EPS = 1e-9
_AXIS_NAME = "XYZ"


class CycleData:
    """The modal cycle data: R level (None: never programmed, the initial level is used),
    hole bottom, peck Q, dwell P (s), initial level."""

    __slots__ = ("r", "z", "q", "p", "init")

    def __init__(self) -> None:
        self.r: float | None = None
        self.z: float | None = None
        self.q = 0.0
        self.p = 0.0
        self.init: float | None = None


def cancel(ip: Context) -> None:
    """G80, or G0..G3: the cycle mode ends (its R, Z, Q, P stay for the next cycle)."""
    ip._cycle = G80
    ip.cyc.init = None


def cycle_block(ip: Context, blk: Block, code: int | None, exact: bool) -> None:
    """A block in the cycle group or under a modal cycle: set the cycle data, drill."""
    if ip._lathe:  # G80 and the lathe's modal cycles G32 G90 G92 G94
        lathe_cycles.cancel_or_cycle(ip, blk, code, exact)
        return
    words = blk.words
    cd: CycleData = ip.cyc
    if code == G80:
        cancel(ip)
        ip._motion_block(blk, words, exact, None)
        return
    if ip._comp_engaged():
        raise ip._err("canned cycle with cutter compensation active", blk, "G")
    w = ip._pw
    if code is not None:
        if ip._cycle == G80 or cd.init is None:
            cd.init = ip._pos[w]
        ip._cycle = code
    wn = _AXIS_NAME[w]
    init = cd.init if cd.init is not None else ip._pos[w]
    if "R" in words:
        r = ip._dim(blk, "R")
        cd.r = r if ip._abs else init + r
    if wn in words:
        z = ip._dim(blk, wn)
        if ip._abs:
            cd.z = z
        else:
            base = cd.r if cd.r is not None else init
            cd.z = base + z
    if "Q" in words:
        cd.q = ip._dim(blk, "Q")
    if "P" in words:
        cd.p = words["P"] / 1000.0
    reps = 1
    for letter in "KL":
        if letter in words:
            k = words[letter]
            if k != int(k) or not 0 <= k <= MAX_REPEAT:
                raise ip._err(f"{letter} repeat count must be 0..{MAX_REPEAT}", blk, letter)
            reps = int(k)
    u, v = ip._pu, ip._pv
    names = _AXIS_NAME
    has_pos = names[u] in words or names[v] in words
    if not (has_pos or wn in words or "R" in words):
        return
    if cd.z is None:
        raise ip._err(f"canned cycle needs the hole bottom {wn}", blk, "G")
    cyc = ip._cycle
    # R never programmed: the R level is the initial level (Fanuc: R is the distance from
    # the initial level, 0 when omitted; Haas the same), so the cycle feeds from where the
    # tool stands. A programmed R stays modal (the last R).
    rr = cd.r if cd.r is not None else init
    zz = cd.z
    if cyc != G87 and rr < zz - _EPS:
        # The hole bottom above R: run as a Fanuc defines the cycle, feeding from R to Z
        # (Z is the position of the hole bottom, G91 Z the signed distance from R; no
        # Fanuc alarm relating the two is known to us), where RS274NGC refuses "R less
        # than Z". Almost always a sign slip (z64-stdbc-o0010.nc taps Z+.5 over R.1, in
        # the air), so `nc check` warns.
        ip.upward_holes[(ip._frames[-1].file if ip._frames else ip.file, blk.line)] = None
    if cyc == G87 and rr > zz + _EPS:
        raise ip._err(f"G87 back boring needs R below the bore top {wn}", blk, "R")
    if init < rr:
        init = rr  # LinuxCNC: from below R the cycle starts at R
    if cyc in (G73, G83) and cd.q <= 0:
        raise ip._err("peck drilling needs Q > 0 (peck depth)", blk, "Q")
    pecks = abs(zz - rr) / cd.q if cyc in (G73, G83) else 1.0
    if pecks > MAX_PECKS:
        raise ip._err(f"more than {MAX_PECKS} pecks per hole", blk, "Q")
    if reps * pecks > MAX_CYCLE_STEPS:
        raise ip._err(f"cycle block expands to more than {MAX_CYCLE_STEPS} holes x pecks", blk, "K")
    pos_words = {k: words[k] for k in (names[u], names[v]) if k in words}
    for _ in range(reps):
        if ip._pos[w] < rr - _EPS:  # below R: climb to R before moving sideways
            ip._line_to(_at_w(ip, rr), None, blk, True)
        # position in the plane at the current level
        if pos_words:
            fake = Block(blk.line, blk.text)
            fake.words = pos_words
            fake.nopoint = blk.nopoint
            tgt = ip._target(fake, pos_words)
            p = list(ip._pos)
            p[u], p[v] = tgt[u], tgt[v]
            ip._line_to((p[0], p[1], p[2]), None, blk, True)
        _drill(ip, blk, cyc, init, rr, zz)


def _at_w(ip: Context, level: float) -> tuple[float, float, float]:
    p = list(ip._pos)
    p[ip._pw] = level
    return (p[0], p[1], p[2])


def _drill(ip: Context, blk: Block, cyc: int, init: float, r: float, z: float) -> None:
    cd: CycleData = ip.cyc
    line = blk.line
    w = ip._pw
    feed = ip._feed(blk)
    back = init if ip._retract == G98 or cyc == G87 else r
    rapid, lin = ip._line_to, ip._line_to
    # direction into the hole from R (tool axis points up): down, up for back boring and
    # for a hole bottom programmed above R (pecks then go up too)
    d = 1.0 if cyc == G87 or z > r else -1.0
    if cyc == G87:  # back boring: orient, shift, go below the part, cut upwards
        q = cd.q
        _orient_shift(ip, blk, q)
        rapid(_at_w(ip, r), None, blk, True)
        rapid(_shifted(ip, _at_w(ip, r), -q), None, blk, True)
        _spin(ip, line, SpindleDirection.CW)
        lin(_at_w(ip, z), feed, blk, True)
        _orient_shift(ip, blk, q)
        rapid(_at_w(ip, init), None, blk, True)
        rapid(_shifted(ip, _at_w(ip, init), -q), None, blk, True)
        _spin(ip, line, SpindleDirection.CW)
        return
    if abs(ip._pos[w] - r) > _EPS:
        rapid(_at_w(ip, r), None, blk, True)
    if cyc in (G73, G83):
        q = cd.q
        depth = r
        while True:
            nxt = depth + d * q
            if (nxt - z) * d > 0:
                nxt = z
            if cyc == G83 and depth != r:
                rapid(_at_w(ip, depth - d * PECK_CLEARANCE_MM), None, blk, True)
            lin(_at_w(ip, nxt), feed, blk, True)
            depth = nxt
            if abs(depth - z) < _EPS:
                break
            if cyc == G73:
                rapid(_at_w(ip, depth - d * PECK_RETRACT_MM), None, blk, True)
            else:
                rapid(_at_w(ip, r), None, blk, True)
        rapid(_at_w(ip, back), None, blk, True)
        return
    if cyc in (G74, G84):
        fwd = SpindleDirection.CW if cyc == G84 else SpindleDirection.CCW
        rev = SpindleDirection.CCW if cyc == G84 else SpindleDirection.CW
        _spin(ip, line, fwd)
        lin(_at_w(ip, z), feed, blk, True)
        if cd.p > 0:
            ip._emit(Dwell(line, cd.p))
        _spin(ip, line, rev)
        lin(_at_w(ip, r), feed, blk, True)
        _spin(ip, line, fwd)
        if back != r:
            rapid(_at_w(ip, back), None, blk, True)
        return
    lin(_at_w(ip, z), feed, blk, True)
    if cyc in (G82, G88, G89, G76) and cd.p > 0:
        ip._emit(Dwell(line, cd.p))
    if cyc == G76:
        q = cd.q
        _orient_shift(ip, blk, q)
        rapid(_at_w(ip, back), None, blk, True)
        rapid(_shifted(ip, _at_w(ip, back), -q), None, blk, True)
        _spin(ip, line, SpindleDirection.CW)
    elif cyc in (G85, G89):
        lin(_at_w(ip, r), feed, blk, True)
        if back != r:
            rapid(_at_w(ip, back), None, blk, True)
    elif cyc == G86:
        _spin(ip, line, SpindleDirection.STOP)
        rapid(_at_w(ip, back), None, blk, True)
        _spin(ip, line, SpindleDirection.CW)
    elif cyc == G88:
        _spin(ip, line, SpindleDirection.STOP)
        ip._emit(ProgramStop(line, StopKind.PROGRAM_STOP))  # manual retract
        rapid(_at_w(ip, back), None, blk, True)
        _spin(ip, line, SpindleDirection.CW)
    else:  # G81, G82
        rapid(_at_w(ip, back), None, blk, True)


def _shifted(ip: Context, p: tuple[float, float, float], q: float) -> tuple[float, float, float]:
    lst = list(p)
    lst[ip._pu] += q  # shift along +u (G17: +X), Fanuc parameter RD default
    return (lst[0], lst[1], lst[2])


def _orient_shift(ip: Context, blk: Block, q: float) -> None:
    ip._emit(Spindle(blk.line, SpindleDirection.ORIENT, ip._s))
    ip._line_to(_shifted(ip, ip._pos, q), None, blk, True)


def _spin(ip: Context, line: int, direction: SpindleDirection) -> None:
    ip._spindle = direction
    ip._emit_spindle(line)
