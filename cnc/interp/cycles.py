"""Canned cycles G73 G74 G76 G81-G89 (G80 cancel), expanded into canonical moves.

A mixin of the Interpreter: the cycle keeps its data (R, Z, Q, P, initial level) in the
interpreter's modal state and emits every move through the interpreter's `_line_to`, so
transforms, offsets and soft limits apply exactly as to programmed moves. Cycle moves are
exact stop (as LinuxCNC and Fanuc run them, even under G64).
"""

from __future__ import annotations

from cnc.canon import Dwell, ProgramStop, Spindle, SpindleDirection, StopKind
from cnc.gcode.lexer import Block

MAX_REPEAT = 9999  # K / L repeat counts
MAX_PECKS = 10000  # per hole, so a tiny Q cannot flood the planner
MAX_CYCLE_STEPS = 100_000  # holes x pecks from one cycle block
PECK_CLEARANCE_MM = 0.5  # G83: stop this far above the previous depth (Fanuc param 5115)
PECK_RETRACT_MM = 0.5  # G73: retract after each peck (Fanuc param 5114)
_EPS = 1e-9
_AXIS_NAME = "XYZ"


class CannedCycles:
    """Cycle expansion; mixed into `Interpreter`, whose state and emitters it uses."""

    # --- canned cycles ----------------------------------------------------------------

    def _cycle_block(self, blk: Block, code: int | None, exact: bool) -> None:
        words = blk.words
        if code == 800:
            self._cycle = 800
            self._cyc_init = None
            self._motion_block(blk, words, exact, None)
            return
        if self._comp_engaged():
            raise self._err("canned cycle with cutter compensation active", blk, "G")
        w = self._pw
        if code is not None:
            if self._cycle == 800 or self._cyc_init is None:
                self._cyc_init = self._pos[w]
            self._cycle = code
        wn = _AXIS_NAME[w]
        init = self._cyc_init if self._cyc_init is not None else self._pos[w]
        if "R" in words:
            r = self._dim(blk, "R")
            self._cyc_r = r if self._abs else init + r
        if wn in words:
            z = self._dim(blk, wn)
            if self._abs:
                self._cyc_z = z
            else:
                base = self._cyc_r if self._cyc_r is not None else init
                self._cyc_z = base + z
        if "Q" in words:
            self._cyc_q = self._dim(blk, "Q")
        if "P" in words:
            self._cyc_p = words["P"] / 1000.0
        reps = 1
        for letter in "KL":
            if letter in words:
                k = words[letter]
                if k != int(k) or not 0 <= k <= MAX_REPEAT:
                    raise self._err(f"{letter} repeat count must be 0..{MAX_REPEAT}", blk, letter)
                reps = int(k)
        u, v = self._pu, self._pv
        names = _AXIS_NAME
        has_pos = names[u] in words or names[v] in words
        if not (has_pos or wn in words or "R" in words):
            return
        if self._cyc_z is None:
            raise self._err(f"canned cycle needs the hole bottom {wn}", blk, "G")
        if self._cyc_r is None:
            raise self._err("canned cycle needs the R level", blk, "G")
        cyc = self._cycle
        rr, zz = self._cyc_r, self._cyc_z
        if cyc != 870 and rr < zz - _EPS:
            raise self._err(f"R level below the hole bottom {wn}", blk, "R")
        if cyc == 870 and rr > zz + _EPS:
            raise self._err(f"G87 back boring needs R below the bore top {wn}", blk, "R")
        if init < rr:
            init = rr  # LinuxCNC: from below R the cycle starts at R
        if cyc in (730, 830) and self._cyc_q <= 0:
            raise self._err("peck drilling needs Q > 0 (peck depth)", blk, "Q")
        pecks = abs(zz - rr) / self._cyc_q if cyc in (730, 830) else 1.0
        if pecks > MAX_PECKS:
            raise self._err(f"more than {MAX_PECKS} pecks per hole", blk, "Q")
        if reps * pecks > MAX_CYCLE_STEPS:
            raise self._err(
                f"cycle block expands to more than {MAX_CYCLE_STEPS} holes x pecks", blk, "K"
            )
        pos_words = {k: words[k] for k in (names[u], names[v]) if k in words}
        for _ in range(reps):
            if self._pos[w] < rr - _EPS:  # below R: climb to R before moving sideways
                self._line_to(self._at_w(rr), None, blk, True)
            # position in the plane at the current level
            if pos_words:
                fake = Block(blk.line, blk.text)
                fake.words = pos_words
                fake.nopoint = blk.nopoint
                tgt = self._target(fake, pos_words)
                p = list(self._pos)
                p[u], p[v] = tgt[u], tgt[v]
                self._line_to((p[0], p[1], p[2]), None, blk, True)
            self._drill(blk, cyc, init, rr, zz)

    def _at_w(self, level: float) -> tuple[float, float, float]:
        p = list(self._pos)
        p[self._pw] = level
        return (p[0], p[1], p[2])

    def _drill(self, blk: Block, cyc: int, init: float, r: float, z: float) -> None:
        line = blk.line
        w = self._pw
        feed = self._feed(blk)
        back = init if self._retract == 980 or cyc == 870 else r
        rapid, lin = self._line_to, self._line_to
        d = 1.0 if cyc == 870 else -1.0  # direction into the hole (tool axis points up)
        if cyc == 870:  # back boring: orient, shift, go below the part, cut upwards
            q = self._cyc_q
            self._orient_shift(blk, q)
            rapid(self._at_w(r), None, blk, True)
            rapid(self._shifted(self._at_w(r), -q), None, blk, True)
            self._spin(line, SpindleDirection.CW)
            lin(self._at_w(z), feed, blk, True)
            self._orient_shift(blk, q)
            rapid(self._at_w(init), None, blk, True)
            rapid(self._shifted(self._at_w(init), -q), None, blk, True)
            self._spin(line, SpindleDirection.CW)
            return
        if abs(self._pos[w] - r) > _EPS:
            rapid(self._at_w(r), None, blk, True)
        if cyc in (730, 830):
            q = self._cyc_q
            depth = r
            while True:
                nxt = depth + d * q
                if (nxt - z) * d > 0:
                    nxt = z
                if cyc == 830 and depth != r:
                    rapid(self._at_w(depth - d * PECK_CLEARANCE_MM), None, blk, True)
                lin(self._at_w(nxt), feed, blk, True)
                depth = nxt
                if abs(depth - z) < _EPS:
                    break
                if cyc == 730:
                    rapid(self._at_w(depth - d * PECK_RETRACT_MM), None, blk, True)
                else:
                    rapid(self._at_w(r), None, blk, True)
            rapid(self._at_w(back), None, blk, True)
            return
        if cyc in (740, 840):
            fwd = SpindleDirection.CW if cyc == 840 else SpindleDirection.CCW
            rev = SpindleDirection.CCW if cyc == 840 else SpindleDirection.CW
            self._spin(line, fwd)
            lin(self._at_w(z), feed, blk, True)
            if self._cyc_p > 0:
                self._emit(Dwell(line, self._cyc_p))
            self._spin(line, rev)
            lin(self._at_w(r), feed, blk, True)
            self._spin(line, fwd)
            if back != r:
                rapid(self._at_w(back), None, blk, True)
            return
        lin(self._at_w(z), feed, blk, True)
        if cyc in (820, 880, 890, 760) and self._cyc_p > 0:
            self._emit(Dwell(line, self._cyc_p))
        if cyc == 760:
            q = self._cyc_q
            self._orient_shift(blk, q)
            rapid(self._at_w(back), None, blk, True)
            rapid(self._shifted(self._at_w(back), -q), None, blk, True)
            self._spin(line, SpindleDirection.CW)
        elif cyc in (850, 890):
            lin(self._at_w(r), feed, blk, True)
            if back != r:
                rapid(self._at_w(back), None, blk, True)
        elif cyc == 860:
            self._spin(line, SpindleDirection.STOP)
            rapid(self._at_w(back), None, blk, True)
            self._spin(line, SpindleDirection.CW)
        elif cyc == 880:
            self._spin(line, SpindleDirection.STOP)
            self._emit(ProgramStop(line, StopKind.PROGRAM_STOP))  # manual retract
            rapid(self._at_w(back), None, blk, True)
            self._spin(line, SpindleDirection.CW)
        else:  # 810, 820
            rapid(self._at_w(back), None, blk, True)

    def _shifted(self, p: tuple[float, float, float], q: float) -> tuple[float, float, float]:
        lst = list(p)
        lst[self._pu] += q  # shift along +u (G17: +X), Fanuc parameter RD default
        return (lst[0], lst[1], lst[2])

    def _orient_shift(self, blk: Block, q: float) -> None:
        self._emit(Spindle(blk.line, SpindleDirection.ORIENT, self._s))
        self._line_to(self._shifted(self._pos, q), None, blk, True)

    def _spin(self, line: int, direction: SpindleDirection) -> None:
        self._spindle = direction
        self._emit_spindle(line)
