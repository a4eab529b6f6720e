"""Properties of the APT processor's closed-form geometry and contouring."""

from __future__ import annotations

import math

from hypothesis import assume, given
from hypothesis import strategies as st

from cam.apt import Processor

coord = st.floats(-100, 100)
radius = st.floats(0.5, 20)


def env(src: str) -> dict:
    p = Processor(src, "p.apt")
    list(p.run())
    return p.env


def cl(src: str) -> list:
    return list(Processor(src, "p.apt").run())


@given(
    x1=coord,
    y1=coord,
    r1=radius,
    x2=coord,
    y2=coord,
    r2=radius,
    s1=st.sampled_from(["LEFT", "RIGHT"]),
    s2=st.sampled_from(["LEFT", "RIGHT"]),
)
def test_tangent_lines_touch_both_circles_on_the_named_sides(
    x1, y1, r1, x2, y2, r2, s1, s2
) -> None:
    d = math.hypot(x2 - x1, y2 - y1)
    assume(d > r1 + r2 + 0.1)  # apart: all four tangents exist
    e = env(
        f"C1 = CIRCLE/{x1!r},{y1!r},{r1!r}\nC2 = CIRCLE/{x2!r},{y2!r},{r2!r}\n"
        f"L1 = LINE/{s1},TANTO,C1,{s2},TANTO,C2\n"
        f"L2 = LINE/{'RIGHT' if s2 == 'LEFT' else 'LEFT'},TANTO,C2,{'RIGHT' if s1 == 'LEFT' else 'LEFT'},TANTO,C1\n"
    )
    ln = e["L1"]
    for cx, cy, r, side in ((x1, y1, r1, s1), (x2, y2, r2, s2)):
        sd = ln.signed_distance(cx, cy)
        assert abs(abs(sd) - r) < 1e-9 * (1 + d)
        # touching a circle on its LEFT (looking from C1 to C2) puts its centre right of the line
        assert (sd < 0) == (side == "LEFT")
    assert ln.same_as(e["L2"], 1e-9 * (1 + d))  # swapping the circles swaps LEFT and RIGHT


@given(a=st.floats(-170, 170), b=st.floats(-170, 170), r=radius, px=coord, py=coord)
def test_fillet_touches_both_lines(a, b, r, px, py) -> None:
    assume(abs(math.sin(math.radians(a - b))) > 0.05)
    e = env(f"P1 = POINT/{px!r},{py!r}\nL1 = LINE/P1,ATANGL,{a!r}\nL2 = LINE/P1,ATANGL,{b!r}\n")
    l1, l2 = e["L1"], e["L2"]
    for m1 in ("XLARGE", "XSMALL", "YLARGE", "YSMALL"):
        for m2 in ("XLARGE", "XSMALL", "YLARGE", "YSMALL"):
            if min(abs(l1.normal[m1[0] == "Y"]), abs(l2.normal[m2[0] == "Y"])) < 1e-6:
                continue
            c = env(
                f"P1 = POINT/{px!r},{py!r}\nL1 = LINE/P1,ATANGL,{a!r}\nL2 = LINE/P1,ATANGL,{b!r}\n"
                f"C1 = CIRCLE/{m1},L1,{m2},L2,RADIUS,{r!r}"
            )["C1"]
            for ln, m in ((l1, m1), (l2, m2)):
                sd = ln.signed_distance(c.cx, c.cy)
                assert abs(abs(sd) - r) < 1e-7
                fx, fy = ln.foot(c.cx, c.cy)
                toward = (c.cx - fx, c.cy - fy)[m[0] == "Y"]
                assert (toward > 0) == m.endswith("LARGE")


@given(pts=st.lists(st.tuples(coord, coord), min_size=3, max_size=3))
def test_circle_through_three_points(pts) -> None:
    (ax, ay), (bx, by), (cx, cy) = pts
    area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
    assume(abs(area) > 1.0)
    c = env(
        f"PA = POINT/{ax!r},{ay!r}\nPB = POINT/{bx!r},{by!r}\nPC = POINT/{cx!r},{cy!r}\n"
        "C1 = CIRCLE/PA,PB,PC"
    )["C1"]
    for x, y in pts:
        assert abs(math.hypot(x - c.cx, y - c.cy) - c.r) < 1e-6 * (1 + c.r)


@given(
    cx=coord, cy=coord, w=st.floats(2, 80), h=st.floats(2, 80), angle=st.floats(-180, 180),
    dia=st.floats(0.1, 1.5), outside=st.booleans(),
)  # fmt: skip
def test_contour_of_a_rotated_rectangle_is_offset_by_the_radius(
    cx, cy, w, h, angle, dia, outside
) -> None:
    """Around any rectangle, the tool centre runs on the outline offset by D/2, corner to
    corner (lines meeting at right angles: the centre path's corners are the offset
    rectangle's)."""
    t = math.radians(angle)
    ux, uy = math.cos(t), math.sin(t)
    vx, vy = -uy, ux
    corners = [
        (cx + sx * w / 2 * ux + sy * h / 2 * vx, cy + sx * w / 2 * uy + sy * h / 2 * vy)
        for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))
    ]  # counter-clockwise
    lines = "".join(
        f"S{i + 1} = LINE/{corners[i][0]!r},{corners[i][1]!r},{corners[(i + 1) % 4][0]!r},{corners[(i + 1) % 4][1]!r}\n"
        for i in range(4)
    )
    R = dia / 2
    if outside:
        start = (cx - (w / 2 + 5) * ux - (h / 2 + 5) * vx, cy - (w / 2 + 5) * uy - (h / 2 + 5) * vy)
        motion = "TLRGT,GORGT/S1,PAST,S2\nGOLFT/S2,PAST,S3\nGOLFT/S3,PAST,S4\nGOLFT/S4,PAST,S1\n"
        check, off = "TO", R
    else:
        assume(dia < min(w, h) / 2)
        start = (cx, cy)
        motion = "TLLFT,GOLFT/S1,TO,S2\nGOLFT/S2,TO,S3\nGOLFT/S3,TO,S4\nGOLFT/S4,TO,S1\n"
        check, off = "TO", -R
    src = (
        f"CUTTER/{dia!r}\n{lines}PS = PLANE/0,0,1,-1\nFROM/{start[0]!r},{start[1]!r},2\n"
        f"GO/TO,S1,TO,PS,{check},S4\n{motion}"
    )
    pts = [r.args[:2] for r in cl(src) if r.word == "GOTO"]
    assert len(pts) == 5
    want = [
        (
            cx + sx * (w / 2 + off) * ux + sy * (h / 2 + off) * vx,
            cy + sx * (w / 2 + off) * uy + sy * (h / 2 + off) * vy,
        )
        for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1), (-1, -1))
    ]
    for (x, y), (wx, wy) in zip(pts, want, strict=True):
        assert math.hypot(x - wx, y - wy) < 1e-7 * (1 + abs(cx) + abs(cy) + w + h)


_TOKENS = [
    "P1", "P2", "L1", "C1", "PL1", "X", "=", "/", ",", "(", ")", "+", "-", "*", "**", "1", "2.5",
    "0", "-3", "POINT", "LINE", "CIRCLE", "PLANE", "VECTOR", "CENTER", "RADIUS", "TANTO",
    "INTOF", "ATANGL", "XLARGE", "YSMALL", "LEFT", "RIGHT", "PARLEL", "DELTA", "CLW", "ON",
    "TO", "PAST", "GO", "GOLFT", "GOFWD", "TLRGT", "FROM", "GOTO", "GODLTA", "CUTTER", "FEDRAT",
    "SQRTF", "$", "$$", ";", "\n", "IN", "OUT", "THRU", "ZSURF", "UNITS", "MM", "INDIRV",
]  # fmt: skip

_PRELUDE = (
    "P1 = POINT/1,2\nP2 = POINT/5,-1\nL1 = LINE/P1,P2\nC1 = CIRCLE/0,0,3\n"
    "PL1 = PLANE/0,0,1,0\nX = 2\nCUTTER/0.5\nFROM/-9,-9,1\n"
)


@given(st.lists(st.sampled_from(_TOKENS), max_size=25))
def test_fuzz_the_processor_fails_only_with_located_errors(tokens) -> None:
    """Any statement soup: CL records or a CamError with file, line and column, never
    another exception."""
    from cam.errors import CamError

    src = _PRELUDE + " ".join(tokens)
    try:
        list(Processor(src, "fuzz.apt").run())
    except CamError as e:
        assert e.file == "fuzz.apt" and e.line >= 1 and e.col >= 1, str(e)
