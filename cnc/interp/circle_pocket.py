"""Haas G12 / G13 circular pocket milling (CW / CCW), expanded into lines and arcs.

    G12 I.. [K.. Q..] [L..] [Z..] [D..] [X.. Y..] F..

The tool stands at the pocket centre (or goes there first at its height: X Y). Per loop
(L, default 1): feed to Z (G90: the depth; G91: one more Z deeper each loop), a half-circle
lead-in from the centre onto the first circle, the full circle, and with K and Q a straight
step out by Q and the full circle again up to the finished radius K, then a half-circle
lead-out back to the centre. The circles are the programmed radii less the radius of tool
offset D (D0: the tool centre on the radius; no D: the offset last selected), so the tool's
edge cuts I (or K): the cycle compensates itself, and refuses G41/G42 active. G12 cuts
clockwise (conventional milling in a pocket with an M3 spindle), G13 counter-clockwise
(climb milling); the lead-in and lead-out arcs turn the same way, so each joint is
tangent. The moves go through the interpreter's emitters (`_line_to`, `_arc_to`): the
active plane's first axis is the step direction, and transforms, offsets and soft limits
apply as to programmed moves.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from cnc.gcode.lexer import Block
from cnc.interp.cycles import MAX_REPEAT
from cnc.interp.gnum import G12

if TYPE_CHECKING:
    from cnc.interp.context import BlockRun, Context

MAX_CIRCLES = 10_000  # circles per loop: (K - I) / Q, so a tiny Q cannot flood the planner
_AXIS = "XYZ"
_EPS = 1e-9


def circle_pocket(ip: Context, run: BlockRun) -> None:
    blk = run.blk
    words = run.words
    cw = run.rows["nonmodal"].number == G12
    name = run.rows["nonmodal"].name
    if ip._comp_engaged():
        raise ip._err(
            f"{name} with cutter compensation active (the cycle offsets the tool"
            " by D itself: G40 first)",
            blk,
            "G",
            run.gcol["nonmodal"],
        )
    radius = ip._dim(blk, "I")
    if radius <= 0.0:
        raise ip._err(f"{name} I (pocket radius) must be > 0", blk, "I")
    final = radius
    step = 0.0
    if ("K" in words) != ("Q" in words):
        letter = "K" if "K" in words else "Q"
        raise ip._err(f"{name} K (finished radius) and Q (step) go together", blk, letter)
    if "K" in words:
        final = ip._dim(blk, "K")
        step = ip._dim(blk, "Q")
        if final < radius - _EPS:
            raise ip._err(f"{name} K (finished radius) is smaller than I (first radius)", blk, "K")
        if step <= 0.0:
            raise ip._err(f"{name} Q (radius step) must be > 0", blk, "Q")
        if (final - radius) / step > MAX_CIRCLES:
            raise ip._err(f"{name} K/Q make more than {MAX_CIRCLES} circles", blk, "Q")
    loops = 1
    if "L" in words:
        n = words["L"]
        if n != int(n) or not 1 <= n <= MAX_REPEAT:
            raise ip._err(f"{name} L (loops) must be 1..{MAX_REPEAT}", blk, "L")
        loops = int(n)
    tool = ip._offset_entry(blk, "D", ip._d).radius if ip._d else 0.0
    first = radius - tool
    if first <= _EPS:
        raise ip._err(
            f"{name} I{radius / ip._scale:g} is not larger than the tool radius "
            f"{tool / ip._scale:g} (offset D{ip._d})",
            blk,
            "I",
        )
    radii = [first]
    r = radius + step
    while step > 0.0 and r < final - _EPS:
        radii.append(r - tool)
        r += step
    if final - tool > radii[-1] + _EPS:
        radii.append(final - tool)
    u, v, w = ip._pu, ip._pv, ip._pw
    names = _AXIS
    centre_words = {k: words[k] for k in (names[u], names[v]) if k in words}
    if centre_words:
        fake = Block(blk.line, blk.text)
        fake.words = centre_words
        fake.nopoint = blk.nopoint
        p = list(ip._pos)
        tgt = ip._target(fake, centre_words)
        p[u], p[v] = tgt[u], tgt[v]
        ip._line_to((p[0], p[1], p[2]), None, blk, False)
    feed = ip._feed(blk)
    centre = ip._pos
    depth_letter = names[w]
    for loop in range(loops):
        if depth_letter in words:
            z = ip._dim(blk, depth_letter)
            p = list(ip._pos)
            p[w] = z if ip._abs else p[w] + z
            ip._line_to((p[0], p[1], p[2]), feed, blk, False)
            centre = ip._pos
        elif loop == 0:
            centre = ip._pos
        _loop(ip, blk, centre, radii, cw, feed)


def _loop(ip: Context, blk: Block, c, radii: list[float], cw: bool, feed: float) -> None:
    """Lead-in half circle, the circles (a straight step out between them), lead-out."""
    u = ip._pu

    def at(du: float) -> tuple[float, float, float]:
        p = list(c)
        p[u] += du
        return (p[0], p[1], p[2])

    ip._arc_to(at(radii[0]), at(radii[0] / 2.0), cw, 0, feed, blk, False)
    for i, r in enumerate(radii):
        if i:
            ip._line_to(at(r), feed, blk, False)
        ip._arc_to(at(r), c, cw, 0, feed, blk, False)
    ip._arc_to(c, at(radii[-1] / 2.0), cw, 0, feed, blk, False)
