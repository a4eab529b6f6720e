"""Table tests for cutter radius compensation: every corner case with hand-computed points.

Conventions in the comments: G41 = tool on the left looking along the feed, G42 right.
"off" = offset; "perp" = the perpendicular offset point p + side*r*left_normal(tangent).
"""

from __future__ import annotations

import math

import pytest

from cnc.cutter_comp import CutterCompensation, Segment
from cnc.errors import NcError

S2 = math.sqrt(2.0)


def L(a, b, n=0, payload=None):  # noqa: N802 - reads like the G-code it stands for
    return Segment("line", a, b, None, False, n, 1, payload if payload is not None else n)


def A(a, b, c, ccw, n=0, payload=None):  # noqa: N802
    return Segment("arc", a, b, c, ccw, n, 1, payload if payload is not None else n)


def run(side, r, segs, cancel=None):
    """G41/G42 + start-up + contour (+ G40 and a cancel move) + end of program."""
    cc = CutterCompensation()
    cc.start(side, r)
    out = []
    for s in segs:
        out += cc.push(s)
    if cancel is not None:
        cc.cancel()
        out += cc.push(cancel)
    out += cc.flush()
    for prev, nxt in zip(out, out[1:], strict=False):
        assert nxt.start == prev.end, (prev, nxt)  # the compensated path is continuous
    return out


def close(p, q, tol=1e-12):
    return p is not None and q is not None and math.dist(p, q) <= tol


def shape(out):
    """(kind, start, end, center, ccw, role) of each output segment, for comparisons."""
    return [(s.kind, s.start, s.end, s.center, s.ccw, s.role) for s in out]


def assert_path(out, expected, tol=1e-12):
    assert len(out) == len(expected), shape(out)
    for got, (kind, start, end, center, ccw, role) in zip(out, expected, strict=True):
        assert got.kind == kind, shape(out)
        assert close(got.start, start, tol), (got, start)
        assert close(got.end, end, tol), (got, end)
        if kind == "arc":
            assert close(got.center, center, tol), (got, center)
            assert got.ccw is ccw, got
        assert got.role == role, got


UP = L((0, -5), (0, 0), 1)  # start-up move used by most cases: from below onto the origin


# --------------------------------------------------------------------------- start-up / cancel


def test_startup_type_a_goes_to_perpendicular_offset_of_next_start():
    # G41 r=2, next element along +X from (0,0): left normal (0,1) -> start-up ends at (0,2).
    out = run("left", 2.0, [L((-5, -5), (0, 0), 1), L((0, 0), (10, 0), 2)])
    assert_path(
        out,
        [
            ("line", (-5, -5), (0, 2), None, False, "startup"),
            ("line", (0, 2), (10, 2), None, False, "contour"),
        ],
    )


def test_g42_and_negative_radius_g41_are_the_same_side():
    # TV-INT-16: R=5 along +X: G41 -> Y=+5, G42 -> Y=-5; G41 with D=-5 behaves as G42.
    segs = [L((-5, 0), (0, 0), 1), L((0, 0), (10, 0), 2)]
    assert run("left", 5.0, segs)[1].start == (0.0, 5.0)
    right = run("right", 5.0, segs)
    assert right[1].start == (0.0, -5.0)
    assert shape(run("left", -5.0, segs)) == shape(right)


def test_startup_onto_an_arc_uses_the_arc_normal():
    # Next element: ccw arc from (10,0) about the origin (R=10); G41 = inside, off radius 9,
    # so the start-up ends at (9,0) and the arc runs on radius 9 to (0,9).
    out = run("left", 1.0, [L((20, 0), (10, 0), 1), A((10, 0), (0, 10), (0, 0), True, 2)])
    assert_path(
        out,
        [
            ("line", (20, 0), (9, 0), None, False, "startup"),
            ("arc", (9, 0), (0, 9), (0, 0), True, "contour"),
        ],
    )


def test_startup_arc_is_refused_like_fanuc_ps0034():
    cc = CutterCompensation()
    cc.start("left", 1.0)
    with pytest.raises(NcError) as e:
        cc.push(Segment("arc", (10, 0), (0, 10), (0, 0), True, 7, 3))
    assert (e.value.line, e.value.col) == (7, 3)
    assert "start-up" in e.value.message and "PS0034" in e.value.message


def test_startup_followed_by_sync_ends_perpendicular_to_itself():
    # No next element known: the start-up along +X to (10,0) ends at its own left normal.
    cc = CutterCompensation()
    cc.start("left", 1.0)
    assert cc.push(L((0, 0), (10, 0), 1)) == []
    assert_path(cc.flush(), [("line", (0, 0), (10, 1), None, False, "startup")])
    assert cc.active


def test_cancel_goes_from_last_perpendicular_offset_to_the_programmed_point():
    # A (0,0)->(10,0) G41 r=1 ends at its perp (10,1); G40 move to (15,5) ends uncompensated.
    out = run("left", 1.0, [UP, L((0, 0), (10, 0), 2)], cancel=L((10, 0), (15, 5), 3))
    assert_path(
        out,
        [
            ("line", (0, -5), (0, 1), None, False, "startup"),
            ("line", (0, 1), (10, 1), None, False, "contour"),
            ("line", (10, 1), (15, 5), None, False, "cancel"),
        ],
    )


def test_cancel_arc_is_refused():
    cc = CutterCompensation()
    cc.start("left", 1.0)
    cc.push(UP)
    cc.push(L((0, 0), (10, 0), 2))
    cc.cancel()
    with pytest.raises(NcError) as e:
        cc.push(A((10, 0), (20, 0), (15, 0), True, 9))
    assert e.value.line == 9 and "cancel" in e.value.message


def test_state_and_inactive_passthrough():
    cc = CutterCompensation()
    seg = L((0, 0), (1, 1), 1)
    assert not cc.active and cc.push(seg)[0] is seg
    cc.start("left", 1.0)
    assert cc.active
    cc.cancel()  # G40 before any move: nothing to undo
    assert not cc.active and cc.push(seg)[0] is seg
    cc.start("right", 1.0)
    cc.push(UP)
    cc.push(L((0, 0), (10, 0), 2))
    cc.start("right", 1.0)  # repeated modal G42 with the same D: no-op
    with pytest.raises(NcError, match="already on"):
        cc.start("left", 1.0, line=4, col=1)
    cc.cancel()
    assert cc.active  # until the cancel move is made
    cc.push(L((10, 0), (10, -5), 3))
    assert not cc.active


def test_startup_then_cancel_without_contour():
    # Start-up (0,0)->(10,0) G42 r=1 ends perp right (10,-1); cancel back to (0,0).
    out = run("right", 1.0, [L((0, 0), (10, 0), 1)], cancel=L((10, 0), (0, 0), 2))
    assert_path(
        out,
        [
            ("line", (0, 0), (10, -1), None, False, "startup"),
            ("line", (10, -1), (0, 0), None, False, "cancel"),
        ],
    )


def test_radius_zero_reproduces_the_program():
    segs = [UP, L((0, 0), (10, 0), 2), A((10, 0), (20, 0), (15, 0), False, 3), L((20, 0), (20, 9))]
    out = run("left", 0.0, segs, cancel=L((20, 9), (0, 0), 5))
    assert [(s.kind, s.start, s.end, s.center) for s in out] == [
        (s.kind, s.start, s.end, s.center) for s in [*segs, L((20, 9), (0, 0))]
    ]


# --------------------------------------------------------------------------------- line / line


def test_line_line_inside_90():
    # G41 r=1, +X then +Y (left turn = inside). Offsets y=1 and x=9 meet at (9,1).
    out = run("left", 1.0, [UP, L((0, 0), (10, 0), 2), L((10, 0), (10, 10), 3)])
    assert_path(
        out,
        [
            ("line", (0, -5), (0, 1), None, False, "startup"),
            ("line", (0, 1), (9, 1), None, False, "contour"),
            ("line", (9, 1), (9, 10), None, False, "contour"),
        ],
    )


def test_line_line_inside_135():
    # G41 r=1, +X then towards (0,10): direction (-1,1)/sqrt2, left turn of 135 deg.
    # B's offset: x + y = 10 - sqrt2; with y = 1 -> x = 9 - sqrt2 (trim r*tan(67.5) = 1+sqrt2).
    out = run("left", 1.0, [UP, L((0, 0), (10, 0), 2), L((10, 0), (0, 10), 3)])
    x = (9 - S2, 1.0)
    assert_path(
        out,
        [
            ("line", (0, -5), (0, 1), None, False, "startup"),
            ("line", (0, 1), x, None, False, "contour"),
            ("line", x, (-S2 / 2, 10 - S2 / 2), None, False, "contour"),
        ],
    )


def test_line_line_outside_90_inserts_tool_radius_arc():
    # G41 r=1, +X then -Y (right turn = outside). A ends perp (10,1); B starts perp (11,0);
    # a clockwise arc of radius 1 about the corner (10,0) joins them.
    out = run("left", 1.0, [UP, L((0, 0), (10, 0), 2), L((10, 0), (10, -10), 3, "B")])
    assert_path(
        out,
        [
            ("line", (0, -5), (0, 1), None, False, "startup"),
            ("line", (0, 1), (10, 1), None, False, "contour"),
            ("arc", (10, 1), (11, 0), (10, 0), False, "corner"),
            ("line", (11, 0), (11, -10), None, False, "contour"),
        ],
    )
    corner = out[2]
    assert (corner.line, corner.payload) == (3, "B")  # the corner belongs to the next block


def test_line_line_outside_45_g42_is_counterclockwise():
    # G42 r=1, +X then direction (1,1)/sqrt2 (left turn = outside for G42).
    # A ends at (10,-1); B's right normal (1,-1)/sqrt2 -> starts at (10+sqrt2/2, -sqrt2/2).
    out = run("right", 1.0, [L((0, 5), (0, 0), 1), L((0, 0), (10, 0), 2), L((10, 0), (20, 10))])
    b0 = (10 + S2 / 2, -S2 / 2)
    assert_path(
        out,
        [
            ("line", (0, 5), (0, -1), None, False, "startup"),
            ("line", (0, -1), (10, -1), None, False, "contour"),
            ("arc", (10, -1), b0, (10, 0), True, "corner"),
            ("line", b0, (20 + S2 / 2, 10 - S2 / 2), None, False, "contour"),
        ],
    )


def test_line_line_shallow_outside_uses_intersection_not_micro_arc():
    # Right turn of atan(1e-6) (< SHALLOW_ANGLE = 1e-4) with G41: offsets extended to meet at
    # (10 + r*tan(a/2), 1) with tan(a/2) ~ 5e-7.
    a = math.atan2(1e-5, 10.0)
    out = run("left", 1.0, [UP, L((0, 0), (10, 0), 2), L((10, 0), (20, -1e-5), 3)])
    assert [s.role for s in out] == ["startup", "contour", "contour"]
    assert close(out[1].end, (10 + math.tan(a / 2), 1.0), 1e-12)


def test_line_line_tangent_no_insertion():
    # Collinear continuation: offsets coincide, nothing inserted.
    out = run("left", 1.0, [UP, L((0, 0), (5, 0), 2), L((5, 0), (10, 0), 3)])
    assert [s.role for s in out] == ["startup", "contour", "contour"]
    assert out[1].end == (5.0, 1.0) == out[2].start


def test_line_line_reversal_goes_around_the_end():
    # +X then straight back -X with G41: tool above on the way out, below on the way back;
    # a half circle clockwise about (10,0) from (10,1) to (10,-1).
    out = run("left", 1.0, [UP, L((0, 0), (10, 0), 2), L((10, 0), (0, 0), 3)])
    assert_path(
        out,
        [
            ("line", (0, -5), (0, 1), None, False, "startup"),
            ("line", (0, 1), (10, 1), None, False, "contour"),
            ("arc", (10, 1), (10, -1), (10, 0), False, "corner"),
            ("line", (10, -1), (0, -1), None, False, "contour"),
        ],
    )


# ---------------------------------------------------------------------------------- line / arc


def test_line_arc_inside():
    # G41 r=1: +X to (10,0), then ccw arc about the origin (R=10) to (0,10): tangent (0,1),
    # left turn = inside. Offset circle R=9 meets y=1 at x=sqrt(80).
    out = run("left", 1.0, [UP, L((0, 0), (10, 0), 2), A((10, 0), (0, 10), (0, 0), True, 3)])
    x = (math.sqrt(80.0), 1.0)
    assert_path(
        out,
        [
            ("line", (0, -5), (0, 1), None, False, "startup"),
            ("line", (0, 1), x, None, False, "contour"),
            ("arc", x, (0, 9), (0, 0), True, "contour"),
        ],
    )


def test_line_arc_outside_g42():
    # Same contour with G42: A at y=-1 ends (10,-1); arc offset R=11 starts (11,0);
    # ccw corner arc about (10,0).
    up = L((0, 5), (0, 0), 1)
    out = run("right", 1.0, [up, L((0, 0), (10, 0), 2), A((10, 0), (0, 10), (0, 0), True, 3)])
    assert_path(
        out,
        [
            ("line", (0, 5), (0, -1), None, False, "startup"),
            ("line", (0, -1), (10, -1), None, False, "contour"),
            ("arc", (10, -1), (11, 0), (10, 0), True, "corner"),
            ("arc", (11, 0), (0, 11), (0, 0), True, "contour"),
        ],
    )


@pytest.mark.parametrize(("side", "r_off", "y"), [("left", 9.0, 1.0), ("right", 11.0, -1.0)])
def test_line_arc_tangent(side, r_off, y):
    # +X into a ccw arc about (10,10) starting at (10,0) with tangent (1,0): offsets meet at
    # (10, y); G41 runs inside (R 10-1), G42 outside (R 10+1).
    out = run(
        side,
        1.0,
        [L((0, -y * 5), (0, 0), 1), L((0, 0), (10, 0)), A((10, 0), (20, 10), (10, 10), True)],
    )
    assert_path(
        out,
        [
            ("line", (0, -y * 5), (0, y), None, False, "startup"),
            ("line", (0, y), (10, y), None, False, "contour"),
            ("arc", (10, y), (10 + r_off, 10), (10, 10), True, "contour"),
        ],
    )


# ---------------------------------------------------------------------------------- arc / line

QUARTER = A((10, 0), (0, 10), (0, 0), True, 2)  # ccw quarter circle R=10, ends heading -X
START_Q = L((20, 0), (10, 0), 1)


def test_arc_line_inside():
    # G41 r=1: arc offset R=9 (start (9,0)); then -Y from (0,10) (left turn, inside):
    # line offset x=1 meets the circle at (1, sqrt(80)).
    out = run("left", 1.0, [START_Q, QUARTER, L((0, 10), (0, 0), 3)])
    x = (1.0, math.sqrt(80.0))
    assert_path(
        out,
        [
            ("line", (20, 0), (9, 0), None, False, "startup"),
            ("arc", (9, 0), x, (0, 0), True, "contour"),
            ("line", x, (1, 0), None, False, "contour"),
        ],
    )


def test_arc_line_outside():
    # G41 r=1: arc ends perp (0,9); then +Y (right turn, outside): line starts (-1,10);
    # clockwise corner arc about (0,10).
    out = run("left", 1.0, [START_Q, QUARTER, L((0, 10), (0, 20), 3)])
    assert_path(
        out,
        [
            ("line", (20, 0), (9, 0), None, False, "startup"),
            ("arc", (9, 0), (0, 9), (0, 0), True, "contour"),
            ("arc", (0, 9), (-1, 10), (0, 10), False, "corner"),
            ("line", (-1, 10), (-1, 20), None, False, "contour"),
        ],
    )


def test_arc_line_tangent():
    # Arc ends heading -X; line continues -X: offsets meet at (0,9), nothing inserted.
    out = run("left", 1.0, [START_Q, QUARTER, L((0, 10), (-10, 10), 3)])
    assert [s.role for s in out] == ["startup", "contour", "contour"]
    assert out[1].end == (0.0, 9.0) == out[2].start and out[2].end == (-10.0, 9.0)


# ----------------------------------------------------------------------------------- arc / arc


def test_arc_arc_tangent_s_curve():
    # ccw quarter (R10 about 0) then cw arc about (0,20) (R10) from (0,10): both tangent -X.
    # G41: first inside (R9), second outside (R11): offsets meet at (0,9).
    second = A((0, 10), (-10, 20), (0, 20), False, 3)
    out = run("left", 1.0, [START_Q, QUARTER, second])
    assert_path(
        out,
        [
            ("line", (20, 0), (9, 0), None, False, "startup"),
            ("arc", (9, 0), (0, 9), (0, 0), True, "contour"),
            ("arc", (0, 9), (-11, 20), (0, 20), False, "contour"),
        ],
    )


def test_arc_arc_outside():
    # Second arc ccw about (-10,10) from (0,10): tangent (0,1), right turn, G41 outside.
    # Both offsets R=9: first ends (0,9), second starts (-1,10); cw corner arc about (0,10).
    second = A((0, 10), (-10, 20), (-10, 10), True, 3)
    out = run("left", 1.0, [START_Q, QUARTER, second])
    assert_path(
        out,
        [
            ("line", (20, 0), (9, 0), None, False, "startup"),
            ("arc", (9, 0), (0, 9), (0, 0), True, "contour"),
            ("arc", (0, 9), (-1, 10), (0, 10), False, "corner"),
            ("arc", (-1, 10), (-10, 19), (-10, 10), True, "contour"),
        ],
    )


def test_arc_arc_inside_g42():
    # Same arcs with G42 (right turn = inside): both offsets R=11 about (0,0) and (-10,10).
    # They meet on the bisector through (-5,5) along (1,1)/sqrt2 at distance
    # h = sqrt(11^2 - 50) = sqrt(71): X = (-5 + sqrt(35.5), 5 + sqrt(35.5)).
    second = A((0, 10), (-10, 20), (-10, 10), True, 3)
    out = run("right", 1.0, [L((30, 0), (10, 0), 1), QUARTER, second])
    k = math.sqrt(35.5)
    x = (-5 + k, 5 + k)
    assert_path(
        out,
        [
            ("line", (30, 0), (11, 0), None, False, "startup"),
            ("arc", (11, 0), x, (0, 0), True, "contour"),
            ("arc", x, (-10, 21), (-10, 10), True, "contour"),
        ],
    )


def test_full_circle_stays_a_full_circle():
    # Full circle (start == end) about the origin, G42 cw... here ccw with G41: inside R=9.
    circle = A((10, 0), (10, 0), (0, 0), True, 2)
    out = run("left", 1.0, [START_Q, circle], cancel=L((10, 0), (20, 0), 3))
    assert_path(
        out,
        [
            ("line", (20, 0), (9, 0), None, False, "startup"),
            ("arc", (9, 0), (9, 0), (0, 0), True, "contour"),
            ("line", (9, 0), (20, 0), None, False, "cancel"),
        ],
    )
    assert out[1].start == out[1].end


# ------------------------------------------------------------------------- zero-length segments


def test_zero_length_segments_pass_in_order_at_the_tool_position():
    # Inside corner at (10,0): the Z plunge between A and B comes out at the trim point (9,1).
    plunge = L((10, 0), (10, 0), 3, "Z-5")
    out = run("left", 1.0, [UP, L((0, 0), (10, 0), 2), plunge, L((10, 0), (10, 10), 4)])
    assert [(s.role, s.start, s.end, s.payload) for s in out] == [
        ("startup", (0, -5), (0.0, 1.0), 1),
        ("contour", (0.0, 1.0), (9.0, 1.0), 2),
        ("contour", (9.0, 1.0), (9.0, 1.0), "Z-5"),
        ("contour", (9.0, 1.0), (9.0, 10.0), 4),
    ]


def test_zero_length_before_outside_corner_arc():
    # Outside corner: plunge at A's perpendicular end (10,1), before the corner arc.
    plunge = L((10, 0), (10, 0), 3, "Z")
    out = run("left", 1.0, [UP, L((0, 0), (10, 0), 2), plunge, L((10, 0), (10, -10), 4)])
    assert [(s.role, s.payload) for s in out] == [
        ("startup", 1),
        ("contour", 2),
        ("contour", "Z"),
        ("corner", 4),
        ("contour", 4),
    ]
    assert out[2].start == out[2].end == (10.0, 1.0)


def test_zero_length_before_startup_and_after_cancel_are_uncompensated():
    cc = CutterCompensation(lookahead=0)  # release as soon as the corner is known
    cc.start("left", 1.0)
    z = L((0, -5), (0, -5), 1, "Z")
    assert cc.push(z) == [z]
    cc.push(UP)
    cc.push(L((0, 0), (10, 0), 2))
    cc.cancel()
    out = cc.push(L((10, 0), (10, 0), 3, "Z up"))  # G40 known: A ends perp, plunge there
    assert [(s.role, s.end) for s in out] == [("contour", (10.0, 1.0)), ("contour", (10.0, 1.0))]
    out = cc.push(L((10, 0), (20, 0), 4))
    assert [(s.role, s.start, s.end) for s in out] == [("cancel", (10.0, 1.0), (20, 0))]
    z2 = L((20, 0), (20, 0), 5)
    assert cc.push(z2) == [z2]


def test_flush_mid_contour_then_outside_corner_is_joined_by_arc():
    cc = CutterCompensation()
    cc.start("left", 1.0)
    out = cc.push(UP) + cc.push(L((0, 0), (10, 0), 2))
    out += cc.flush()  # M0: A is released up to its perp end (10,1)
    assert out[-1].end == (10.0, 1.0)
    out += cc.push(L((10, 0), (10, 0), 3, "Z"))  # placed at once at the tool position
    out += cc.push(L((10, 0), (10, -10), 4))
    out += cc.flush()
    assert [(s.role, s.start, s.end) for s in out[-3:]] == [
        ("contour", (10.0, 1.0), (10.0, 1.0)),
        ("corner", (10.0, 1.0), (11.0, 0.0)),
        ("contour", (11.0, 0.0), (11.0, -10.0)),
    ]


# --------------------------------------------------------------------------------- gouges


def test_gouge_inside_arc_smaller_than_tool():
    cc = CutterCompensation()
    cc.start("left", 1.0)
    cc.push(UP)
    with pytest.raises(NcError) as e:
        # ccw arc R=0.5 with G41: the tool is inside it, R - r < 0.
        cc.push(A((0, 0), (1, 0), (0.5, 0), True, 5))
    assert e.value.line == 5 and e.value.message.startswith("cutter compensation gouge:")


def test_arc_equal_to_tool_radius_on_inside_is_a_gouge_but_outside_is_fine():
    arc = A((0, 0), (2, 0), (1, 0), True, 5)  # R = 1
    with pytest.raises(NcError, match="gouge"):
        run("left", 1.0, [UP, arc])
    out = run("right", 1.0, [L((0, 5), (0, 0), 1), arc])
    assert out[1].start == (-1.0, 0.0) and out[1].end == (3.0, 0.0)  # R+r = 2 about (1,0)


@pytest.mark.parametrize(("width", "verb"), [(1.0, "reverses"), (2.0, "vanishes")])
def test_gouge_slot_narrower_than_the_tool(width, verb):
    # Down, across the bottom (width), up, with G41 r=1: both bottom corners are inside and
    # each trims 1 from the bottom: width 1 reverses, width 2 vanishes.
    segs = [
        L((-5, 10), (0, 10), 1),
        L((0, 10), (0, 0), 2),
        L((0, 0), (width, 0), 3),
        L((width, 0), (width, 10), 4),
        L((width, 10), (width + 5, 10), 5),
    ]
    with pytest.raises(NcError) as e:
        run("left", 1.0, segs)
    assert e.value.line == 3 and verb in e.value.message


def test_slot_wide_enough_is_trimmed():
    # Width 2.5, r=1: bottom offset y=1 from x=1 to x=1.5.
    segs = [
        L((-5, 10), (0, 10), 1),
        L((0, 10), (0, 0), 2),
        L((0, 0), (2.5, 0), 3),
        L((2.5, 0), (2.5, 10), 4),
    ]
    out = run("left", 1.0, segs)
    assert out[2].start == (1.0, 1.0) and out[2].end == (1.5, 1.0)


def test_gouge_offsets_do_not_intersect():
    # +X to the origin, then a ccw half circle about (-1.5,0) (R=1.5) starting upwards: G41
    # inside corner, offset circle R=0.5 never reaches the offset line y=1.
    segs = [
        L((-10, -5), (-10, 0), 1),
        L((-10, 0), (0, 0), 2),
        A((0, 0), (-3, 0), (-1.5, 0), True, 3),
    ]
    with pytest.raises(NcError) as e:
        run("left", 1.0, segs)
    assert e.value.line == 3 and "does not meet" in e.value.message


def test_gouge_inside_corner_after_sync_point():
    cc = CutterCompensation()
    cc.start("left", 1.0)
    cc.push(UP)
    cc.push(L((0, 0), (10, 0), 2))
    cc.flush()
    with pytest.raises(NcError) as e:
        cc.push(L((10, 0), (10, 10), 6))  # left turn = inside, but A is already final
    assert e.value.line == 6 and "synchronisation" in e.value.message


def test_discontinuous_contour_is_refused():
    cc = CutterCompensation(file="part.nc")
    cc.start("left", 1.0)
    cc.push(UP)
    cc.push(L((0, 0), (10, 0), 2))
    with pytest.raises(NcError) as e:
        cc.push(L((11, 0), (20, 0), 3))
    assert str(e.value).startswith("part.nc:3:1: cutter compensation")


def test_bad_segments_are_refused_with_their_position():
    for bad in [
        Segment("line", (0, 0), (math.inf, 0), None, False, 4, 2),
        Segment("spline", (0, 0), (1, 0), None, False, 4, 2),  # type: ignore[arg-type]
        Segment("arc", (0, 0), (1, 0), None, True, 4, 2),
    ]:
        cc = CutterCompensation()
        cc.start("left", 1.0)
        cc.push(UP)
        with pytest.raises(NcError) as e:
            cc.push(bad)
        assert (e.value.line, e.value.col) == (4, 2)


def test_bad_side_and_radius():
    cc = CutterCompensation()
    with pytest.raises(NcError):
        cc.start("up", 1.0)  # type: ignore[arg-type]
    with pytest.raises(NcError):
        cc.start("left", math.nan)


def test_release_waits_for_the_interference_lookahead():
    # Push p=0 is the start-up, push p=k the contour element k (source line k+1). Element k's
    # path is computed at push k+1 (its end corner needs element k+1) and handed over once
    # `lookahead` = n further elements are known: at push max(k+1, k+n). A corner arc
    # belongs to the element after the corner (j) and the start-up to element 1.
    contour = [L((0, 0), (10, 0), 2), L((10, 0), (10, 10), 3), L((10, 10), (20, 10), 4)]
    contour += [L((20, 10), (20, 20), 5), L((20, 20), (30, 20), 6)]
    for n in (0, 1, 3):
        cc = CutterCompensation(lookahead=n)
        cc.start("left", 1.0)
        released = [(p, s) for p, seg in enumerate([UP, *contour]) for s in cc.push(seg)]
        released += [(99, s) for s in cc.flush()]
        roles = [s.role for _, s in released]
        assert roles == ["startup", "contour", "contour", "corner", "contour", "contour"] + [
            "corner",
            "contour",
        ]
        for p, s in released:
            k = s.line - 1
            want = {"startup": 1 + n, "corner": k + n, "contour": max(k + 1, k + n)}[s.role]
            assert p == (want if want <= 5 else 99), (n, p, s)


def test_interference_check_finds_a_neck_no_single_element_shows():
    # A (0,0)->(10,0), B ->(13,-3) (right turn, outside: arc), C ->(13,1.5) (inside),
    # D ->(5,1.5) (inside). G41 r=1: no element reverses (B' 1.83 long, C' from y=-0.586 to
    # 0.5), but D's offset y=0.5 runs 0.5 above A (y=0) for x in [5,10]: the tool cuts into A.
    segs = [
        L((0, -5), (0, 0), 1),
        L((0, 0), (10, 0), 2),
        L((10, 0), (13, -3), 3),
        L((13, -3), (13, 1.5), 4),
        L((13, 1.5), (5, 1.5), 5),
    ]
    with pytest.raises(NcError) as e:
        run("left", 1.0, segs)
    # A's path is the first one checked against D: it passes 0.5 from D's contour.
    assert e.value.line == 2 and "line 5" in e.value.message and "0.5 from" in e.value.message
    cc = CutterCompensation(lookahead=0)  # without the window only local checks remain
    cc.start("left", 1.0)
    out = [o for s in segs for o in cc.push(s)] + cc.flush()
    assert out[-1].start == (12.0, 0.5) and out[-1].end == (5.0, 0.5)


def _bore(lead_out_then=None):
    """G41 r=1.5 in a bore of radius 5.5 about the origin (a thread-mill pass): start-up to
    (2.75,-2.75), lead-in arc about (2.75,0) to (5.5,0), the full circle, lead-out arc about
    (2.75,0) to (2.75,2.75), then `lead_out_then` (more contour) and the cancel to (0,0)."""
    segs = [L((0, 0), (2.75, -2.75), 1), A((2.75, -2.75), (5.5, 0), (2.75, 0), True, 2)]
    segs += [A((5.5, 0), (5.5, 0), (0, 0), True, 3), A((5.5, 0), (2.75, 2.75), (2.75, 0), True, 4)]
    end = (2.75, 2.75)
    if lead_out_then is not None:
        segs.append(lead_out_then)
        end = lead_out_then.end
    return run("left", 1.5, segs, cancel=L(end, (0, 0), 9))


def test_a_lead_out_arc_inside_the_bore_is_no_wall():
    # The circle's tool path (R 4) crosses the lead-out arc (from R 5.5 down to R 3.89 about
    # the origin): distance 0, but the lead-out runs in the cleared bore, tangent to the
    # circle and curving to the tool side, right before G40 (Fanuc runs it: its
    # interference check compares directions, and none reverses).
    out = _bore()
    assert_path(
        out,
        [
            ("line", (0, 0), (2.75, -1.25), None, False, "startup"),
            ("arc", (2.75, -1.25), (4.0, 0), (2.75, 0), True, "contour"),
            ("arc", (4.0, 0), (4.0, 0), (0, 0), True, "contour"),
            ("arc", (4.0, 0), (2.75, 1.25), (2.75, 0), True, "contour"),
            ("line", (2.75, 1.25), (0, 0), None, False, "cancel"),
        ],
        tol=1e-12,
    )


def test_a_z_retract_between_the_lead_out_and_g40_keeps_it_a_lead_out():
    # lead-out arc, a zero-length segment (G0 Z5: no in-plane motion), then the cancel move
    segs = [L((0, 0), (2.75, -2.75), 1), A((2.75, -2.75), (5.5, 0), (2.75, 0), True, 2)]
    segs += [A((5.5, 0), (5.5, 0), (0, 0), True, 3), A((5.5, 0), (2.75, 2.75), (2.75, 0), True, 4)]
    segs += [L((2.75, 2.75), (2.75, 2.75), 5)]
    out = run("left", 1.5, segs, cancel=L((2.75, 2.75), (0, 0), 9))
    assert [o.line for o in out] == [1, 2, 3, 4, 5, 9] and out[4].end == (2.75, 1.25)


def test_the_same_arc_followed_by_more_contour_is_a_wall():
    # With one more element before G40 the arc is part of the contour: the circle's path
    # crossing it is a gouge, named at the circle (line 3) against the arc (line 4).
    with pytest.raises(NcError) as e:
        _bore(lead_out_then=L((2.75, 2.75), (0, 2.75), 5))
    assert e.value.line == 3 and "line 4" in e.value.message and "passes 0 from" in e.value.message


def test_widen_slack_accepts_the_callers_own_correction_only():
    # Two laps of a circle from (10,0), the second about (0.002,0) (R 9.998): with r = 1 the
    # first lap's path (R 9 about the origin) passes 9.998 - 9.002 = 0.996 from the second
    # lap's contour, on the far side. A caller that
    # moved each element by up to 0.003 (an arc centre put on its bisector) cannot tell that
    # from rounding (2 x 0.003 >= 0.004); by 0.001 it can.
    laps = [L((0, 0), (10, 0), 1), A((10, 0), (10, 0), (0, 0), True, 2)]
    laps += [A((10, 0), (10, 0), (0.002, 0), True, 3)]
    for moved, refused in ((0.0, True), (0.001, True), (0.003, False)):
        cc = CutterCompensation()
        cc.start("left", 1.0)
        cc.widen_slack(moved)
        try:
            for s in laps:
                cc.push(s)
            cc.flush()
        except NcError as e:
            assert refused and e.line == 2 and "0.996 from" in e.message, (moved, e)
        else:
            assert not refused, moved


def test_a_rapid_is_no_wall_but_the_same_feed_move_is():
    # A roughing zig-zag left under G41 r=1 (as lathe programs leave G42 on): pass 1 (0,0)->
    # (10,0), up, back, then down across the start of pass 1 to (0,-3) and pass 2. Pass 1's
    # path starts at (0,1), on the programmed line x=0 of the move down: distance 0 from it.
    # As a G00 that move is air (no wall); as a G01 it is a wall and pass 1 is refused.
    def zigzag(down_rapid):
        segs = [UP, L((0, 0), (10, 0), 2)]
        segs += [Segment("line", (10, 0), (10, 5), None, False, 3, 1, 3, rapid=True)]
        segs += [Segment("line", (10, 5), (0, 5), None, False, 4, 1, 4, rapid=True)]
        segs += [Segment("line", (0, 5), (0, -3), None, False, 5, 1, 5, rapid=down_rapid)]
        return run("left", 1.0, [*segs, L((0, -3), (10, -3), 6)])

    ends = [o.end for o in zigzag(down_rapid=True)]
    assert ends == [(0, 1), (9, 1), (9, 4), (1, 4), (1, -2), (10, -2)]
    with pytest.raises(NcError) as e:
        zigzag(down_rapid=False)
    assert e.value.line == 2 and "line 5" in e.value.message and "passes 0 from" in e.value.message


def test_closed_pocket_started_at_a_corner_is_a_gouge():
    # Type A start-up at an inside corner puts the tool centre on the neighbouring wall:
    # (0,1) is at distance 0 from the last edge x=0. A real overcut, refused.
    pocket = [L((5, 5), (0, 0), 1), L((0, 0), (10, 0), 2), L((10, 0), (10, 10), 3)]
    pocket += [L((10, 10), (0, 10), 4), L((0, 10), (0, 0), 5)]
    with pytest.raises(NcError, match="gouge"):
        run("left", 1.0, pocket, cancel=L((0, 0), (5, 5), 6))
    # Entering mid-edge (a lead-in onto the middle of the first wall) is clean.
    pocket = [L((5, 5), (5, 0), 1), L((5, 0), (10, 0), 2), L((10, 0), (10, 10), 3)]
    pocket += [L((10, 10), (0, 10), 4), L((0, 10), (0, 0), 5), L((0, 0), (5, 0), 6)]
    out = run("left", 1.0, pocket, cancel=L((5, 0), (5, 5), 7))
    assert [o.end for o in out] == [
        (5.0, 1.0),
        (9.0, 1.0),
        (9.0, 9.0),
        (1.0, 9.0),
        (1.0, 1.0),
        (5.0, 1.0),
        (5, 5),
    ]


def test_arc_trimmed_at_both_ends():
    # +X to (10,0), ccw quarter about the origin to (0,10), then -Y: two inside corners for
    # G41 r=1. Offset circle R=9 meets y=1 at (sqrt80, 1) and x=1 at (1, sqrt80).
    s80 = math.sqrt(80.0)
    segs = [UP, L((0, 0), (10, 0), 2), QUARTER, L((0, 10), (0, 3), 4)]
    out = run("left", 1.0, segs)
    assert_path(
        out,
        [
            ("line", (0, -5), (0, 1), None, False, "startup"),
            ("line", (0, 1), (s80, 1), None, False, "contour"),
            ("arc", (s80, 1), (1, s80), (0, 0), True, "contour"),
            ("line", (1, s80), (1, 3), None, False, "contour"),
        ],
    )


def test_gouge_short_arc_between_two_inside_corners():
    # +X to the origin, a 10 deg ccw arc about (-5,0) (R=5, starting upwards: left turn),
    # then a left turn of 90 deg. With G41 r=1 each corner trims asin(1/4) = 14.5 deg from
    # the offset arc (R=4): more than its 10 deg, so the compensated arc would run backwards.
    t = math.radians(10.0)
    e = (-5 + 5 * math.cos(t), 5 * math.sin(t))
    c_dir = (-math.cos(t), -math.sin(t))
    segs = [
        L((-10, -5), (-10, 0), 1),
        L((-10, 0), (0, 0), 2),
        A((0, 0), e, (-5, 0), True, 3),
        L(e, (e[0] + 10 * c_dir[0], e[1] + 10 * c_dir[1]), 4),
    ]
    with pytest.raises(NcError) as err:
        run("left", 1.0, segs)
    assert err.value.line == 3 and "reverses" in err.value.message


def test_g42_runs_inside_a_clockwise_arc():
    # cw arc about the origin from (0,10) to (10,0), R=10: G42 (right of a cw arc = towards
    # the centre) offsets to R=9. Start-up from (0,20) ends at (0,9); the tangent line on
    # -Y from (10,0) continues at x=9.
    segs = [L((0, 20), (0, 10), 1), A((0, 10), (10, 0), (0, 0), False, 2), L((10, 0), (10, -10))]
    out = run("right", 1.0, segs)
    assert_path(
        out,
        [
            ("line", (0, 20), (0, 9), None, False, "startup"),
            ("arc", (0, 9), (9, 0), (0, 0), False, "contour"),
            ("line", (9, 0), (9, -10), None, False, "contour"),
        ],
    )


def test_g40_then_same_g41_before_any_move_keeps_the_contour():
    # The inside corner at (10,0) is still trimmed to (9,1): the G40 was taken back.
    cc = CutterCompensation()
    cc.start("left", 1.0)
    out = cc.push(UP) + cc.push(L((0, 0), (10, 0), 2))
    cc.cancel()
    cc.start("left", 1.0)
    out += cc.push(L((10, 0), (10, 10), 3)) + cc.flush()
    assert [o.end for o in out] == [(0.0, 1.0), (9.0, 1.0), (9.0, 10.0)]


def test_corner_arc_checked_against_a_curling_arc_after_it():
    # Found by the sampled-oracle soak: a ccw arc about (3,1) from the origin, then a cw arc
    # (R=2) that turns almost all the way round (-6 rad). With G42 r=1 the outside corner arc
    # about their junction passes 0.008 from the second arc itself: a gouge.
    c1 = (3.0, 1.0)
    r1 = math.dist((0, 0), c1)
    a = math.atan2(-1.0, -3.0) + 4.5
    p1 = (c1[0] + r1 * math.cos(a), c1[1] + r1 * math.sin(a))
    c2 = (p1[0], p1[1] - 2.0)
    b = math.atan2(p1[1] - c2[1], p1[0] - c2[0]) - 6.0
    p2 = (c2[0] + 2 * math.cos(b), c2[1] + 2 * math.sin(b))
    segs = [L((-20, -20), (0, 0), 1), A((0, 0), p1, c1, True, 2), A(p1, p2, c2, False, 3)]
    with pytest.raises(NcError) as e:
        run("right", 1.0, segs, cancel=L(p2, (-20, -20), 4))
    assert e.value.line == 3 and "line 3" in e.value.message


def test_finish_ends_a_pending_g40_without_a_cancel_move() -> None:
    # G40 then G28/G53/a plane change before any in-plane move: the held element ends at its
    # perpendicular offset and compensation is off; the next segment passes uncompensated.
    cc = CutterCompensation()
    cc.start("left", 1.0)
    out = cc.push(UP) + cc.push(L((0, 0), (10, 0), 2))
    cc.cancel()
    assert cc.active and cc.cancelling
    out += cc.finish()
    assert not cc.active and not cc.cancelling
    assert [(s.role, s.end) for s in out][-1] == ("contour", (10.0, 1.0))
    nxt = L((10, 0), (20, 0), 3)
    assert cc.push(nxt) == [nxt]


def test_finish_with_compensation_on_is_a_flush() -> None:
    cc = CutterCompensation()
    cc.start("left", 1.0)
    cc.push(UP)
    cc.push(L((0, 0), (10, 0), 2))
    assert cc.finish()[-1].end == (10.0, 1.0)
    assert cc.active and not cc.cancelling
