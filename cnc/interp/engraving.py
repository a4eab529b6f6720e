"""Haas G47 text engraving with the single-stroke font of cnc.interp.stroke_font.

    G47 P0 (TEXT) [X.. Y..] Z.. [R..] [I..] [J..] F.. [E..]
    G47 P1 (####) ...        sequential serial number (#599), 4 digits here
    G47 P1 (1234) ...        serial number 1234 (#599 := 1234 first)
    G47 P32..126 ...         the one ASCII character of that code

X Y: the start, the bottom left of the first character (G90 absolute, G91 from the tool;
omitted: where the tool is). Z: the engraving depth; R: the return plane between strokes
(both along the tool axis, absolute under G90; G91: from the tool's level; no R: the
level the tool is at). I: the angle of the text line (degrees, -360..360, about the
start); J: the cap height (default 1 inch, Haas; at least 0.001 inch). F: the engraving
feed, E: the plunge feed (default F).

The path: up to the return plane if the tool is below it, over to the start, to the
return plane; then for each stroke: rapid over its start, plunge at E to Z, engrave it
at F (lines and arcs as the font draws them), rapid back to R. The tool ends at R.

P1 engraves #599 (a common variable kept in the machine data, as on the Haas, where #599
holds the serial number) with as many digits as the comment has characters (leading
zeros; a longer number keeps its last digits), then adds 1 to #599. A comment of digits
sets #599 to that number first.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from cnc.gcode.lexer import Block
from cnc.interp import stroke_font as font
from cnc.interp.gnum import G17

if TYPE_CHECKING:
    from cnc.interp.context import BlockRun, Context

SERIAL_VARIABLE = 599  # Haas: the serial number of G47 P1
DEFAULT_HEIGHT_MM = 25.4  # J omitted: 1.0 inch (Haas)
MIN_HEIGHT_MM = 0.0254  # 0.001 inch
MAX_TEXT = 256  # characters of one G47
_AXIS = "XYZ"


def engrave(ip: Context, run: BlockRun) -> None:
    blk = run.blk
    words = run.words
    if ip._comp_engaged():
        raise ip._err(
            "G47 with cutter compensation active (G40 first)", blk, "G", run.gcol["nonmodal"]
        )
    if ip._plane != G17:
        raise ip._err("G47 engraves in the XY plane (G17)", blk, "G", run.gcol["nonmodal"])
    height = DEFAULT_HEIGHT_MM
    if "J" in words:
        height = ip._dim(blk, "J")
        if height < MIN_HEIGHT_MM - 1e-12:
            raise ip._err("G47 J (text height) must be at least 0.001 inch", blk, "J")
    angle = 0.0
    if "I" in words:
        angle = ip._plain(blk, "I")
        if not -360.0 <= angle <= 360.0:
            raise ip._err("G47 I (text angle) must be -360..360 degrees", blk, "I")
    feed = ip._feed(blk)
    plunge = feed
    if "E" in words:
        plunge = ip._dim(blk, "E")
        if plunge <= 0.0:
            raise ip._err("G47 E (plunge feed) must be > 0", blk, "E")
        plunge = min(plunge, ip.params.max_feed)
    u, v, w = ip._pu, ip._pv, ip._pw
    wn = _AXIS[w]
    level = ip._pos[w]
    depth = ip._dim(blk, wn)
    depth = depth if ip._abs else level + depth
    ret = level
    if "R" in words:
        r = ip._dim(blk, "R")
        ret = r if ip._abs else level + r
    if depth > ret - 1e-9:
        raise ip._err(f"G47 depth {wn} is not below the return plane R", blk, wn)
    text = _text(ip, blk)  # last: P1 counts the serial number up
    start = list(ip._pos)
    plane_words = {k: words[k] for k in (_AXIS[u], _AXIS[v]) if k in words}
    if plane_words:
        fake = Block(blk.line, blk.text)
        fake.words = plane_words
        fake.nopoint = blk.nopoint
        tgt = ip._target(fake, plane_words)
        start[u], start[v] = tgt[u], tgt[v]
    strokes = layout(text, start[u], start[v], height, angle)

    def point(pu: float, pv: float, pw: float) -> tuple[float, float, float]:
        p = [0.0, 0.0, 0.0]
        p[u], p[v], p[w] = pu, pv, pw
        return (p[0], p[1], p[2])

    if ip._pos[w] < ret:
        ip._line_to(point(ip._pos[u], ip._pos[v], ret), None, blk, True)
    ip._line_to(point(start[u], start[v], ip._pos[w]), None, blk, True)
    ip._line_to(point(start[u], start[v], ret), None, blk, True)
    for stroke in strokes:
        x0, y0 = stroke[0]
        ip._line_to(point(x0, y0, ret), None, blk, True)
        ip._line_to(point(x0, y0, depth), plunge, blk, True)
        for seg in stroke[1:]:
            if len(seg) == 2:
                ip._line_to(point(seg[0], seg[1], depth), feed, blk, False)
            else:
                x, y, cx, cy, ccw = seg
                ip._arc_to(point(x, y, depth), point(cx, cy, depth), not ccw, 0, feed, blk, False)
        ip._line_to(point(stroke[-1][0], stroke[-1][1], ret), None, blk, True)


def layout(text: str, x0: float, y0: float, height: float, angle_deg: float) -> list[tuple]:
    """The strokes of `text` in the plane: the font scaled to `height`, the characters side
    by side from (x0, y0) along the angle. Segments as in the font (points in the plane)."""
    k = height / font.HEIGHT
    a = math.radians(angle_deg)
    ca, sa = math.cos(a), math.sin(a)

    def place(gx: float, gy: float, cell: float) -> tuple[float, float]:
        x, y = (gx + cell) * k, gy * k
        return (x0 + x * ca - y * sa, y0 + x * sa + y * ca)

    out: list[tuple] = []
    for i, ch in enumerate(text):
        cell = i * font.ADVANCE
        for stroke in font.GLYPHS[ch]:
            placed: list[tuple] = [place(stroke[0][0], stroke[0][1], cell)]
            for seg in stroke[1:]:
                if len(seg) == 2:
                    placed.append(place(seg[0], seg[1], cell))
                else:
                    ex, ey = place(seg[0], seg[1], cell)
                    cx, cy = place(seg[2], seg[3], cell)
                    placed.append((ex, ey, cx, cy, seg[4]))
            out.append(tuple(placed))
    return out


def _text(ip: Context, blk: Block) -> str:
    """The characters to engrave: the comment (P0), the serial number (P1) or chr(P)."""
    p = blk.words["P"]
    if p != int(p) or not (p in (0, 1) or 32 <= p <= 126):
        raise ip._err(
            "G47 P must be 0 (text), 1 (serial number) or 32..126 (a character)", blk, "P"
        )
    p = int(p)
    col0 = 0  # column of the comment's first character (P0)
    if p >= 32:
        text = chr(p)
    else:
        comment, col0 = _comment(ip, blk)
        text = _serial(ip, blk, comment) if p == 1 else comment
    if not text:
        raise ip._err("G47 P0 needs the text as a comment in its block: G47 P0 (TEXT)", blk, "P")
    if len(text) > MAX_TEXT:
        raise ip._err(f"G47 text longer than {MAX_TEXT} characters", blk, "P")
    for i, ch in enumerate(text):
        if font.glyph(ch) is None:
            err = ip._err(
                f"G47: character {ch!r} has no glyph in the engraving font (A-Z, a-z, 0-9, "
                "space and "
                f"{_PUNCTUATION})",
                blk,
                "P",
            )
            if p == 0:
                err.col = col0 + i  # at the character in the comment
            raise err
    return text


_PUNCTUATION = "".join(c for c in font.GLYPHS if not c.isalnum() and c != " ")


def _raw_line(ip: Context, blk: Block) -> str:
    """The block's source line with its comments (the lexer blanks them in `blk.text`)."""
    fr = ip._frames[-1] if ip._frames else None
    last = getattr(fr.it, "last", None) if fr is not None else None
    if last is not None and last[0] == blk.line:
        return last[1]
    return blk.text


def _comment(ip: Context, blk: Block) -> tuple[str, int]:
    """The first comment of the block and the column of its first character."""
    raw = _raw_line(ip, blk)
    i = raw.find("(")
    j = raw.find(")", i + 1)
    if i < 0 or j < 0:
        return "", 0
    return raw[i + 1 : j], i + 2


def _serial(ip: Context, blk: Block, comment: str) -> str:
    fmt = comment.strip()
    if not fmt or not (set(fmt) <= set("#") or fmt.isdigit()):
        raise ip._err(
            "G47 P1 needs the serial number's format as its comment: (####) for "
            "4 digits, or (1234) to start at 1234",
            blk,
            "P",
        )
    if fmt.isdigit():
        ip.vars.set(SERIAL_VARIABLE, float(int(fmt)))
    value = ip.vars.get(SERIAL_VARIABLE)
    number = 0 if value is None else int(value)
    if number < 0:
        raise ip._err(f"G47 P1: the serial number #{SERIAL_VARIABLE} is negative", blk, "P")
    digits = len(fmt)
    text = str(number).zfill(digits)[-digits:]
    ip.vars.set(SERIAL_VARIABLE, float(number + 1))
    return text
