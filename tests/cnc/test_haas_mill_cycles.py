"""Haas G12/G13 circular pocket and G47 text engraving: generated paths against hand lists."""

from __future__ import annotations

import math

import pytest

from cnc.canon import ArcFeed, StraightFeed, StraightTraverse
from cnc.errors import NcError
from cnc.interp import Interpreter
from cnc.interp import stroke_font as font
from cnc.interp.state import ToolOffset
from cnc.params import AxisParams, MachineParams

AXES = tuple(AxisParams(a, -1000, 1000, 30000, 3000, 5e4) for a in "XYZ")
MILL = MachineParams(axes=AXES)
TOOLS = {1: ToolOffset(radius=2.0), 2: ToolOffset(radius=0.0)}


def run(text: str, **kw) -> list:
    return list(Interpreter(MILL, start=(0.0, 0.0, 0.0), tools=TOOLS, **kw).run(text))


def moves(cmds: list) -> list[tuple]:
    """('T', x, y, z) rapid, ('F', x, y, z, feed) line, ('CW'|'CCW', x, y, z, cx, cy) arc."""
    out: list[tuple] = []
    for c in cmds:
        e = tuple(round(v, 6) for v in c.end)
        if isinstance(c, StraightTraverse):
            out.append(("T", *e))
        elif isinstance(c, StraightFeed):
            out.append(("F", *e, c.feed))
        elif isinstance(c, ArcFeed):
            cen = tuple(round(v, 6) for v in c.center[:2])
            out.append(("CW" if c.clockwise else "CCW", *e, *cen))
    return out


# --- G12 / G13 ----------------------------------------------------------------------------


def test_g12_single_circle_with_tool_radius() -> None:
    # I10 with a 2 mm tool radius: the centre path runs on radius 8
    got = moves(run("G0 X10 Y10 Z5\nG12 I10 Z-3 D1 F100\n"))[1:]
    assert got == [
        ("F", 10, 10, -3, 100.0),
        ("CW", 18, 10, -3, 14, 10),  # lead-in half circle from the centre
        ("CW", 18, 10, -3, 10, 10),  # the full circle
        ("CW", 10, 10, -3, 14, 10),  # lead-out half circle back to the centre
    ]


def test_g13_rough_and_finish_steps_out_to_k() -> None:
    # radii I6, 9, K12 less the tool radius 2: 4, 7, 10
    got = moves(run("G0 X10 Y10 Z5\nG13 I6 K12 Q3 Z-3 D1 F100\n"))[1:]
    assert got == [
        ("F", 10, 10, -3, 100.0),
        ("CCW", 14, 10, -3, 12, 10),
        ("CCW", 14, 10, -3, 10, 10),
        ("F", 17, 10, -3, 100.0),
        ("CCW", 17, 10, -3, 10, 10),
        ("F", 20, 10, -3, 100.0),
        ("CCW", 20, 10, -3, 10, 10),
        ("CCW", 10, 10, -3, 15, 10),
    ]


def test_g12_incremental_z_loops_and_centre_words() -> None:
    # D0 (offset 2, radius 0): the tool centre on I; G91: Z per loop from the start level
    got = moves(run("G0 Z1\nG91 G12 X4 Y2 I3 Z-2 L2 D2 F50\n"))
    assert got == [
        ("T", 0, 0, 1),
        ("T", 4, 2, 1),
        ("F", 4, 2, -1, 50.0),
        ("CW", 7, 2, -1, 5.5, 2),
        ("CW", 7, 2, -1, 4, 2),
        ("CW", 4, 2, -1, 5.5, 2),
        ("F", 4, 2, -3, 50.0),
        ("CW", 7, 2, -3, 5.5, 2),
        ("CW", 7, 2, -3, 4, 2),
        ("CW", 4, 2, -3, 5.5, 2),
    ]


def test_g12_path_is_tangent_at_every_arc_joint() -> None:
    cmds = [c for c in run("G12 I6 K12 Q3 Z-3 D1 F100\n") if isinstance(c, ArcFeed)]
    for a in cmds:
        # every arc starts and ends on the +X side of the centre line: tangents are +-Y
        assert a.end[1] == pytest.approx(a.center[1])


@pytest.mark.parametrize(
    ("text", "col", "message"),
    [
        ("G12 I2 Z-1 D1 F100\n", 5, "G12 I2 is not larger than the tool radius 2 .offset D1."),
        ("G12 I1.5 Z-1 D1 F100\n", 5, "not larger than the tool radius"),
        ("G12 I5 K8 Z-1 F100\n", 8, "K .finished radius. and Q .step. go together"),
        ("G13 I5 K4 Q1 Z-1 F100\n", 8, "K .finished radius. is smaller than I"),
        ("G12 I5 K8 Q0 Z-1 F100\n", 11, "Q .radius step. must be > 0"),
        ("G12 I5 K8 Q0.0001 Z-1 F100\n", 11, "more than 10000 circles"),
        ("G12 I5 Z-1 L0 F100\n", 12, "L .loops. must be 1..9999"),
        ("G12 Z-1 F100\n", 1, "G12 needs I"),
        ("G12 I5 Z-1\n", 1, "feed move without F"),
        ("G41 D1 G1 X20 F100\nG12 I5 Z-1\n", 1, "G12 with cutter compensation active"),
    ],
)
def test_g12_bad_input(text: str, col: int, message: str) -> None:
    with pytest.raises(NcError, match=message) as exc:
        run(text)
    assert exc.value.col == col
    assert exc.value.line == text.count("\n")


# --- G47 ----------------------------------------------------------------------------------

ENGRAVE = "G0 X0 Y0 Z5\nG47 P0 ({}) X10 Y20 Z-1 R2 J6 F100 E50 {}\n"


def engrave(text: str, extra: str = "") -> list[tuple]:
    return moves(run(ENGRAVE.format(text, extra)))[1:]


def test_g47_letter_l_at_scale_one() -> None:
    # J6 = the font's grid: 1 unit = 1 mm; L is (0,6) -> (0,0) -> (4,0)
    assert engrave("L") == [
        ("T", 10, 20, 5),  # over to the start at the tool's level
        ("T", 10, 20, 2),  # down to the return plane
        ("T", 10, 26, 2),
        ("F", 10, 26, -1, 50.0),  # plunge at E
        ("F", 10, 20, -1, 100.0),  # engrave at F
        ("F", 14, 20, -1, 100.0),
        ("T", 14, 20, 2),  # back to R
    ]


def test_g47_two_characters_and_a_dot() -> None:
    # "-" is (1,3)-(3,3); "." a plunge at (2,0) of the second cell, 6 units on
    assert engrave("-.") == [
        ("T", 10, 20, 5),
        ("T", 10, 20, 2),
        ("T", 11, 23, 2),
        ("F", 11, 23, -1, 50.0),
        ("F", 13, 23, -1, 100.0),
        ("T", 13, 23, 2),
        ("T", 18, 20, 2),
        ("F", 18, 20, -1, 50.0),
        ("T", 18, 20, 2),
    ]


def test_g47_arc_in_a_glyph_and_the_angle() -> None:
    # J: (4,6) -> (4,2), then a clockwise half circle about (2,2) to (0,2)
    assert engrave("J", "I0")[2:6] == [
        ("T", 14, 26, 2),
        ("F", 14, 26, -1, 50.0),
        ("F", 14, 22, -1, 100.0),
        ("CW", 10, 22, -1, 12, 22),
    ]
    # I90: the text runs up; grid (x, y) lands at (10 - y, 20 + x)
    assert engrave("L", "I90")[2:6] == [
        ("T", 4, 20, 2),
        ("F", 4, 20, -1, 50.0),
        ("F", 10, 20, -1, 100.0),
        ("F", 10, 24, -1, 100.0),
    ]


def test_g47_height_scales_and_inch() -> None:
    got = moves(run("G20\nG0 X0 Y0 Z0.2\nG47 P76 X1 Y1 Z-0.01 R0.05 J0.6 F10\n"))
    # P76 = "L"; J0.6 inch = 15.24 mm cap height: 1 grid unit = 2.54 mm; E omitted: F
    assert got[3:6] == [
        ("T", 25.4, 40.64, 1.27),
        ("F", 25.4, 40.64, -0.254, 254.0),
        ("F", 25.4, 25.4, -0.254, 254.0),
    ]


def test_g47_serial_number_counts_up_in_599() -> None:
    store: dict[int, float] = {599: 41.0}
    cmds = run("G0 Z5\nG47 P1 (####) X0 Y0 Z-1 R2 J6 F100\n", macro_variables=store)
    assert store[599] == 42.0
    # "0041": 0 (2 strokes), 0 (2), 4 (1), 1 (2): one plunge at E (= F here) per stroke
    strokes = sum(len(font.GLYPHS[c]) for c in "0041")
    assert strokes == 7
    got = moves(cmds)
    plunges = [
        b
        for a, b in zip(got, got[1:], strict=False)
        if a[0] == "T" and b[0] == "F" and b[3] == -1 and a[1:3] == b[1:3]
    ]
    assert len(plunges) == strokes
    # the first stroke is the outline of the first "0": it starts at grid (4, 4)
    assert plunges[0][1:3] == (4.0, 4.0)
    store2: dict[int, float] = {}
    run("G47 P1 (1234) Z-1 R2 F100\n", macro_variables=store2)
    assert store2[599] == 1235.0


@pytest.mark.parametrize(
    ("text", "col", "message"),
    [
        (
            "G47 P0 (A\u00e9) Z-1 R2 F100\n",
            10,
            "G47: character '\u00e9' has no glyph in the engraving font .A-Z, a-z",
        ),
        ("G47 P0 (A\u00c4) Z-1 R2 F100\n", 10, "character '\u00c4' has no glyph"),
        ("G47 P0 Z-1 R2 F100\n", 5, "G47 P0 needs the text as a comment"),
        ("G47 P2 (A) Z-1 R2 F100\n", 5, "G47 P must be 0 .text., 1 .serial number. or 32..126"),
        ("G47 P1 (AB) Z-1 R2 F100\n", 5, "G47 P1 needs the serial number's format"),
        ("G47 P0 (A) Z3 R2 F100\n", 12, "G47 depth Z is not below the return plane R"),
        ("G47 P0 (A) Z-1 R2 J0.001 F100\n", 19, "J .text height. must be at least 0.001 inch"),
        ("G47 P0 (A) Z-1 R2 I400 F100\n", 19, "I .text angle. must be -360..360"),
        ("G47 P0 (A) R2 F100\n", 1, "G47 needs Z"),
        ("G18 G47 P0 (A) Z-1 R2 F100\n", 5, "G47 engraves in the XY plane"),
    ],
)
def test_g47_bad_input(text: str, col: int, message: str) -> None:
    with pytest.raises(NcError, match=message) as exc:
        run("G0 Z5\n" + text)
    assert (exc.value.line, exc.value.col) == (2, col)


def test_font_covers_the_haas_set_and_its_arcs_are_circles() -> None:
    assert set(font.GLYPHS) == {chr(c) for c in range(32, 127)}  # Haas G47 P32..126
    for ch, strokes in font.GLYPHS.items():
        for stroke in strokes:
            x, y = stroke[0]
            for seg in stroke[1:]:
                if len(seg) == 5:
                    ex, ey, cx, cy, _ = seg
                    r0, r1 = math.hypot(x - cx, y - cy), math.hypot(ex - cx, ey - cy)
                    assert r0 == pytest.approx(r1, abs=1e-3), ch
                x, y = seg[0], seg[1]


def test_every_glyph_engraves() -> None:
    text = "".join(c for c in font.GLYPHS if c not in "()")
    cmds = run(f"G0 Z5\nG47 P0 ({text}) Z-1 R2 J6 F100\n")
    assert any(isinstance(c, ArcFeed) for c in cmds)
    for p in (40, 41):  # the parentheses only by their code (they end a comment)
        assert run(f"G0 Z5\nG47 P{p} Z-1 R2 J6 F100\n")


def _bbox(strokes) -> tuple[float, float, float, float]:
    """(x min, y min, x max, y max) of a glyph, its arcs sampled every degree."""
    xs, ys = [], []
    for stroke in strokes:
        x, y = stroke[0]
        xs.append(x)
        ys.append(y)
        for seg in stroke[1:]:
            if len(seg) == 5:
                ex, ey, cx, cy, ccw = seg
                r = math.hypot(x - cx, y - cy)
                a0, a1 = math.atan2(y - cy, x - cx), math.atan2(ey - cy, ex - cx)
                sweep = (a1 - a0) % (2 * math.pi) if ccw else -((a0 - a1) % (2 * math.pi))
                if abs(sweep) < 1e-12:
                    sweep = 2 * math.pi if ccw else -2 * math.pi  # ends where it starts
                for k in range(361):
                    a = a0 + sweep * k / 360
                    xs.append(cx + r * math.cos(a))
                    ys.append(cy + r * math.sin(a))
            x, y = seg[0], seg[1]
            xs.append(x)
            ys.append(y)
    return (round(min(xs), 3), round(min(ys), 3), round(max(xs), 3), round(max(ys), 3))


@pytest.mark.parametrize(
    ("letters", "y_min", "y_max"),
    [
        ("acemnorsuvwxz", 0.0, 4.0),  # the x-height: 4 of the cap height's 6
        ("bdhkl", 0.0, 6.0),  # ascenders: up to the cap height
        ("gpqy", -2.0, 4.0),  # descenders: 2 below the base line
        ("f", 0.0, 6.0),
        ("t", 0.0, 6.0),
        ("i", 0.0, 5.5),  # the dot above the x-height
        ("j", -2.0, 5.5),
    ],
)
def test_lower_case_glyphs_sit_on_the_base_line(letters, y_min, y_max) -> None:
    for ch in letters:
        x0, y0, x1, y1 = _bbox(font.GLYPHS[ch])
        assert (y0, y1) == (y_min, y_max), ch
        assert x0 >= 0.0 and x1 <= font.WIDTH, ch  # inside the cell's width


def test_lower_case_stroke_counts() -> None:
    # strokes = plunges of the cutter per letter
    counts = {ch: len(font.GLYPHS[ch]) for ch in "abcdefghijklmnopqrstuvwxyz"}
    assert counts == {"a": 2, "b": 2, "c": 1, "d": 2, "e": 1, "f": 2, "g": 2, "h": 2, "i": 2,
                      "j": 2, "k": 3, "l": 1, "m": 3, "n": 2, "o": 1, "p": 2, "q": 2, "r": 2,
                      "s": 1, "t": 2, "u": 2, "v": 1, "w": 1, "x": 2, "y": 2, "z": 1}  # fmt: skip
    # each lower-case letter differs from its capital
    for ch in counts:
        assert font.GLYPHS[ch] != font.GLYPHS[ch.upper()], ch


def test_g47_engraves_a_word_in_lower_case_as_written() -> None:
    # "Haas": the comment's case is kept; at J6 one grid unit is 1 mm, cells 6 mm apart
    got = engrave("Haas")
    plunges = [v for a, b in zip(got, got[1:], strict=False)
               if a[0] == "T" and b[0] == "F" and b[4] == 50.0 for v in b[1:3]]  # fmt: skip
    # H: 3 strokes; a (cells at X16, X22): the bowl from (4, 2), then the stem from (4, 4);
    # s (X28): from (2.866, 3.5)
    assert plunges == pytest.approx([10, 20, 14, 20, 10, 23,
                                     20, 22, 20, 24, 26, 22, 26, 24,
                                     28 + 2 + 3**0.5 / 2, 23.5])  # fmt: skip
    arcs = [m for m in got if m[0] in ("CW", "CCW")]
    assert [m[0] for m in arcs] == ["CCW", "CCW", "CCW", "CW"]  # a's bowls, s's two arcs
    assert engrave("l") != engrave("L")  # the lower-case l is not the capital
