"""The APT processor against seed 004's candidate requirements A (1-9) and B (10-12)."""

from __future__ import annotations

import math

import pytest

from cam.apt import Processor
from cam.apt.geometry import Circle, Line, Plane, Point
from cam.errors import CamError


def run(src: str, warn=None) -> tuple[Processor, list]:
    p = Processor(src, "t.apt", warn or (lambda w: None))
    return p, list(p.run())


def env(src: str, warn=None) -> dict:
    p, _ = run(src, warn)
    return p.env


def error(src: str) -> CamError:
    with pytest.raises(CamError) as ei:
        run(src)
    return ei.value


def close(a, b, tol=1e-4) -> bool:
    return all(abs(x - y) <= tol for x, y in zip(a, b, strict=True))


def pt(p: Point) -> tuple[float, float, float]:
    return (p.x, p.y, p.z)


# --- A1 names ---------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("name", "col", "why"),
    [
        ("9786", 1, "must start with a letter"),
        ("EXAMPLE", 1, "at most 6 characters"),
        ("POINT", 1, "APT keyword"),
        ("A4.35", 1, "no '.'"),
    ],
)
def test_a1_invalid_names(name: str, col: int, why: str) -> None:
    e = error(f"P0 = POINT/1,2\n{name} = POINT/4,5,6\n")
    assert (e.file, e.line, e.col) == ("t.apt", 2, col)
    assert why in e.message
    assert str(e).startswith("t.apt:2:1: ")


@pytest.mark.parametrize("name", ["P1", "C1", "PL1", "L4", "EL1", "PP3"])
def test_a1_valid_names(name: str) -> None:
    assert pt(env(f"{name} = POINT/1,2,3")[name]) == (1, 2, 3)


def test_a1_long_name_used_as_a_value() -> None:
    e = error("X = LONGNAME + 1")
    assert "at most 6 characters" in e.message and e.col == 5


# --- A2 statement forms ---------------------------------------------------------------------------


def test_a2_statement_forms() -> None:
    e = env(
        "P1 = POINT/4,5,6\nX = 10.0\nC1 = CIRCLE/CENTER,P1,RADIUS,5\nY = 10/4\nZ = 2*(1+2)**2-1"
    )
    assert pt(e["P1"]) == (4, 5, 6)
    assert e["X"] == 10.0
    assert e["C1"] == Circle(4, 5, 5, 6)
    assert e["Y"] == 2.5
    assert e["Z"] == 17.0


def test_a2_macro_is_a_clean_unsupported_diagnostic() -> None:
    e = error("M1 = MACRO/X,Y,Z")
    assert (e.line, e.col) == (1, 6) and "MACRO is not supported" in e.message


def test_a2_use_before_definition() -> None:
    e = error("C1 = CIRCLE/CENTER,P9,RADIUS,1")
    assert (e.line, e.col) == (1, 20) and "undefined name 'P9'" in e.message


def test_a2_thesis_style_semicolons_and_continuation() -> None:
    e = env("P1 = POINT/ 1, $\n  2, 3 ; P2 = POINT/4,5 $$ a comment\n")
    assert pt(e["P1"]) == (1, 2, 3) and pt(e["P2"]) == (4, 5, 0)


def test_a2_functions_and_exponents() -> None:
    e = env("A = SQRTF(16) + COSF(60) + ATAN2F(1,1)\nB = 1.5E-3 * 2e2")
    assert e["A"] == pytest.approx(4 + 0.5 + 45)
    assert e["B"] == pytest.approx(0.3)


# --- A3 POINT defaults ----------------------------------------------------------------------------


def test_a3_point_defaults() -> None:
    e = env("PA = POINT/3,4\nZSURF/2\nPB = POINT/3,4\nP1 = POINT/3,4,3\nP2 = POINT/-2,-4,2")
    assert pt(e["PA"]) == (3, 4, 0)
    assert pt(e["PB"]) == (3, 4, 2)
    assert pt(e["P1"]) == (3, 4, 3) and pt(e["P2"]) == (-2, -4, 2)


# --- A4 DELTA on a circle -------------------------------------------------------------------------


def test_a4_delta_on_circle() -> None:
    e = env(
        "C1 = CIRCLE/0,0,10\nP1 = POINT/10,0,0\n"
        "P2 = POINT/ P1, DELTA, CCLW, ON, C1, ATANGL, 45;\n"
        "P3 = POINT/ P1, DELTA, CLW, ON, C1, ATANGL, 60;\n"
    )
    assert close(pt(e["P2"]), (7.0711, 7.0711, 0))
    assert close(pt(e["P3"]), (5.0, -8.6603, 0))


def test_point_other_forms() -> None:
    e = env(
        "P1 = POINT/1,1\nC1 = CIRCLE/CENTER,P1,RADIUS,2\n"
        "PA = POINT/CENTER,C1\nPB = POINT/C1,ATANGL,90\nPC = POINT/P1,RADIUS,2,ATANGL,180\n"
        "PD = POINT/RTHETA,XYPLAN,2,90\nPE = POINT/YZPLAN,2,90\nPF = POINT/P1,DELTA,100,60\n"
        "L1 = LINE/XAXIS\nPG = POINT/XLARGE,INTOF,L1,C1\nPH = POINT/XSMALL,INTOF,C1,L1\n"
    )
    assert close(pt(e["PA"]), (1, 1, 0))
    assert close(pt(e["PB"]), (1, 3, 0))
    assert close(pt(e["PC"]), (-1, 1, 0))
    assert close(pt(e["PD"]), (0, 2, 0))
    assert close(pt(e["PE"]), (0, 0, 2))  # YZPLAN: the angle from Y+
    assert close(pt(e["PF"]), (101, 61, 0))
    assert close(pt(e["PG"]), (1 + math.sqrt(3), 0, 0))
    assert close(pt(e["PH"]), (1 - math.sqrt(3), 0, 0))


def test_two_intersections_need_a_modifier() -> None:
    e = error("C1 = CIRCLE/0,0,1\nL1 = LINE/XAXIS\nP1 = POINT/INTOF,L1,C1")
    assert e.line == 3 and "give XLARGE" in e.message


# --- A5 intersections and circles ----------------------------------------------------------------


def test_a5_intersections_and_circles() -> None:
    e = env(
        "L1 = LINE/0,0,10,10\nL2 = LINE/0,10,10,0\nP1 = POINT/INTOF,L1,L2\n"
        "PA = POINT/0,0\nPB = POINT/2,0\nPC = POINT/0,2\nC1 = CIRCLE/PA,PB,PC\n"
        "PD = POINT/1,1\nPE = POINT/4,5\nC2 = CIRCLE/CENTER,PD,PE\n"
    )
    assert close(pt(e["P1"]), (5, 5, 0))
    c1 = e["C1"]
    assert close((c1.cx, c1.cy, c1.r), (1, 1, 1.41421))
    assert e["C2"].r == pytest.approx(5)


def test_a5_collinear_points_are_an_error() -> None:
    e = error("PA = POINT/0,0\nPB = POINT/1,1\nPC = POINT/2,2\nC1 = CIRCLE/PA,PB,PC")
    assert (e.line, e.col) == (4, 6) and "collinear" in e.message


def test_parallel_lines_have_no_intersection() -> None:
    e = error("L1 = LINE/0,0,1,0\nL2 = LINE/0,1,1,1\nP1 = POINT/INTOF,L1,L2")
    assert e.line == 3 and "parallel" in e.message


# --- A6 modifier symmetry of tangent lines ---------------------------------------------------------


def test_a6_tangent_lines_two_circles() -> None:
    e = env(
        "C1 = CIRCLE/0,0,1\nC2 = CIRCLE/10,0,1\n"
        "LA = LINE / RIGHT, TANTO, C1, RIGHT, TANTO, C2;\n"
        "LB = LINE / LEFT, TANTO, C2, LEFT, TANTO, C1;\n"
        "LC = LINE / LEFT, TANTO, C1, LEFT, TANTO, C2;\n"
        "LD = LINE / RIGHT, TANTO, C2, RIGHT, TANTO, C1;\n"
        "LE = LINE / LEFT, TANTO, C1, RIGHT, TANTO, C2;\n"
    )
    la, lb, lc, ld = e["LA"], e["LB"], e["LC"], e["LD"]
    assert la.same_as(lb) and lc.same_as(ld)
    assert la.same_as(Line(0, -1, 1, 0))  # RIGHT/RIGHT from C1 to C2: y = -1
    assert lc.same_as(Line(0, 1, 1, 0))
    le = e["LE"]  # a cross tangent: touches both circles, passes between them
    for cx in (0, 10):
        assert abs(le.signed_distance(cx, 0)) == pytest.approx(1)
    assert le.signed_distance(0, 0) * le.signed_distance(10, 0) < 0


def test_a6_same_circle_twice_is_an_error() -> None:
    e = error("C1 = CIRCLE/0,0,1\nL3 = LINE / RIGHT, TANTO, C1, RIGHT, TANTO, C1;")
    assert e.line == 2 and "same circle" in e.message


def test_line_forms() -> None:
    e = env(
        "C1 = CIRCLE/0,0,2\nL1 = LINE/XAXIS\n"
        "L2 = LINE/ATANGL, -60, L1, TANTO, C1, YSMALL;\nL3 = LINE/ATANGL, -60, L1, TANTO, C1, YLARGE;\n"
        "P1 = POINT/5,0\nL4 = LINE/P1,LEFT,TANTO,C1\nL5 = LINE/PARLEL,L1,YLARGE,3\n"
        "L6 = LINE/P1,ATANGL,90\nL7 = LINE/P1,PERPTO,L1\n"
    )
    l2, l3 = e["L2"], e["L3"]
    for ln in (l2, l3):
        assert abs(ln.signed_distance(0, 0)) == pytest.approx(2)
        assert math.degrees(math.atan2(ln.uy, ln.ux)) == pytest.approx(-60)
    assert l2.foot(0, 0)[1] < l3.foot(0, 0)[1]
    l4 = e["L4"]
    assert abs(l4.signed_distance(0, 0)) == pytest.approx(2) and l4.signed_distance(0, 0) < 0
    assert e["L5"].same_as(Line(0, 3, 1, 0))
    assert e["L6"].same_as(e["L7"])


# --- A7 multi-solution modifiers --------------------------------------------------------------------


def test_a7_two_point_radius() -> None:
    e = env(
        "P1 = POINT/0,0\nP2 = POINT/6,0\n"
        "C1 = CIRCLE/YLARGE,P1,P2,RADIUS,5\nC2 = CIRCLE/YSMALL,P1,P2,RADIUS,5"
    )
    assert close((e["C1"].cx, e["C1"].cy), (3, 4)) and close((e["C2"].cx, e["C2"].cy), (3, -4))


def test_a7_modifier_that_does_not_disambiguate() -> None:
    e = error("P1 = POINT/0,0\nP2 = POINT/6,0\nC1 = CIRCLE/XLARGE,P1,P2,RADIUS,5")
    assert (e.line, e.col) == (3, 13) and "ambiguous modifier XLARGE" in e.message


def test_a7_fillet_one_of_four() -> None:
    base = "L1 = LINE/XAXIS\nL2 = LINE/YAXIS\n"
    centres = set()
    for m1 in ("YLARGE", "YSMALL"):
        for m2 in ("XLARGE", "XSMALL"):
            c = env(base + f"C1 = CIRCLE/{m1},L1,{m2},L2,RADIUS,1")["C1"]
            assert c.r == 1
            assert c.cy == (1 if m1 == "YLARGE" else -1) and c.cx == (1 if m2 == "XLARGE" else -1)
            centres.add((c.cx, c.cy))
    assert len(centres) == 4
    e = error(base + "C1 = CIRCLE/XLARGE,L1,XSMALL,L2,RADIUS,1")
    assert "ambiguous modifier XLARGE" in e.message and e.col == 13


def test_a7_line_and_circle_one_of_eight() -> None:
    base = "L1 = LINE/0,-1,1,-1\nC0 = CIRCLE/0,0,5\n"  # the line cuts the circle: 8 fit
    found = set()
    for m1 in ("YLARGE", "YSMALL"):
        for io in ("IN", "OUT"):
            for m2 in ("XLARGE", "XSMALL"):
                c = env(base + f"C1 = CIRCLE/{m1},L1,{m2},{io},C0,RADIUS,1.5")["C1"]
                assert abs(abs(c.cy + 1) - 1.5) < 1e-9  # tangent to the line
                assert (c.cy > -1) == (m1 == "YLARGE")
                assert (c.cx > 0) == (m2 == "XLARGE")
                assert math.hypot(c.cx, c.cy) == pytest.approx(5 - 1.5 if io == "IN" else 5 + 1.5)
                found.add((round(c.cx, 9), round(c.cy, 9)))
    assert len(found) == 8


def test_three_lines_and_tanto_thru() -> None:
    e = env(
        "L1 = LINE/XAXIS\nL2 = LINE/YAXIS\nL3 = LINE/0,4,4,0\n"
        "C1 = CIRCLE/YLARGE,L1,XLARGE,L2,YSMALL,L3\n"
        "P1 = POINT/0,3\nC2 = CIRCLE/XLARGE,TANTO,L1,THRU,P1,RADIUS,1.5\n"
        "C3 = CIRCLE/XSMALL,TANTO,L1,THRU,P1,RADIUS,1.5\n"
    )
    c = e["C1"]  # the inscribed circle of the 4-4-4sqrt2 triangle
    r = 4 * 4 / (4 + 4 + 4 * math.sqrt(2))
    assert close((c.cx, c.cy, c.r), (r, r, r), 1e-9)
    assert e["C2"].cx == pytest.approx(0) and e["C2"].cy == pytest.approx(1.5)
    assert e["C3"].cx == pytest.approx(0)  # tangent at the top: one circle only


def test_circle_center_tangent_forms() -> None:
    e = env(
        "P1 = POINT/0,0\nL1 = LINE/0,3,1,3\nC1 = CIRCLE/CENTER,P1,TANTO,L1\n"
        "C0 = CIRCLE/10,0,2\nC2 = CIRCLE/CENTER,P1,SMALL,TANTO,C0\nC3 = CIRCLE/CENTER,P1,LARGE,TANTO,C0\n"
    )
    assert e["C1"].r == 3 and e["C2"].r == 8 and e["C3"].r == 12


# --- A8 planes ------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("args", "plane"),
    [
        ("0,0,1,5", (0, 0, 1, 5)),
        ("0,0,1,-3", (0, 0, 1, -3)),
        ("1,0,0,3", (1, 0, 0, 3)),
        ("1,0,0,-4", (1, 0, 0, -4)),
        ("0,1,0,6", (0, 1, 0, 6)),
        ("0,1,0,-3", (0, 1, 0, -3)),
    ],
)
def test_a8_coordinate_planes(args: str, plane: tuple) -> None:
    pl = env(f"PL1 = PLANE/{args}")["PL1"]
    assert (pl.a, pl.b, pl.c, pl.d) == plane


def test_a8_direction_cosines_are_normalised_with_a_warning() -> None:
    warnings: list = []
    pl = env("PL1 = PLANE/COSF(65),COSF(56),COSF(45),7.07", warnings.append)["PL1"]
    assert len(warnings) == 1 and "not a unit vector" in warnings[0].message
    assert warnings[0].line == 1
    n = math.sqrt(0.4226**2 + 0.5592**2 + 0.7071**2)
    assert close((pl.a, pl.b, pl.c, pl.d), (0.4226 / n, 0.5592 / n, 0.7071 / n, 7.07 / n), 2e-4)


def test_a8_normal_4_minus5_7() -> None:
    e = env(
        "PL1 = PLANE/4,-5,7,90.1249\nPL2 = PLANE/4,-5,7,142.3025\n"
        "PL3 = PLANE/0.42164,-0.52705,0.73786,9.5\n"
    )
    for name, d in (("PL1", 9.5), ("PL2", 15.0), ("PL3", 9.5)):
        pl = e[name]
        assert close((pl.a, pl.b, pl.c), (0.42164, -0.52705, 0.73786), 1e-5)
        assert pl.d == pytest.approx(d, abs=1e-4)


def test_a8_parlel_side_modifiers() -> None:
    e = env(
        "PL1 = PLANE/0,0,1,5\nPL2 = PLANE/PARLEL,PL1,ZLARGE,4\nPL3 = PLANE/PARLEL,PL1,ZSMALL,4\n"
        "PL4 = PLANE/1,-1,0,0\nPL5 = PLANE/PARLEL,PL4,XLARGE,4\nPL6 = PLANE/PARLEL,PL4,YSMALL,4\n"
        "P1 = POINT/1,2,3\nPL7 = PLANE/P1,PARLEL,PL1\n"
    )
    assert e["PL2"].d == 9 and e["PL3"].d == 1
    assert e["PL5"] == e["PL6"]  # Ex 2.41: XLARGE and YSMALL name the same side
    assert e["PL7"] == Plane(0, 0, 1, 3)
    err = error("PL1 = PLANE/0,0,1,5\nPL2 = PLANE/PARLEL,PL1,XLARGE,4")
    assert "ambiguous modifier XLARGE" in err.message and err.line == 2


def test_plane_three_points_and_perpto() -> None:
    e = env(
        "PP1 = POINT/0,0,1\nPP2 = POINT/1,0,1\nPP3 = POINT/0,1,1\nPL1 = PLANE / PP1, PP2, PP3;\n"
        "V1 = VECTOR/0,0,2\nPL2 = PLANE/PP1,PERPTO,V1\nPL3 = PLANE/PERPTO,PL1,PP1,PP2\n"
    )
    assert e["PL1"] == Plane(0, 0, 1, 1) and e["PL2"] == Plane(0, 0, 1, 1)
    assert abs(e["PL3"].b) == pytest.approx(1)
    err = error("PP1 = POINT/0,0\nPP2 = POINT/1,1\nPP3 = POINT/2,2\nPL1 = PLANE/PP1,PP2,PP3")
    assert "collinear" in err.message and err.line == 4


# --- A9 conics ------------------------------------------------------------------------------------


def test_a9_ellipse_coefficients() -> None:
    e = env("P1 = POINT/3,2\nEL1 = ELLIPS/CENTER,P1,1.5,1")
    a, b, c, d, ee, f = e["EL1"].coefficients
    assert close((a, c, d, ee, f), (1, 2.25, -6, -9, 15.75), 1e-12) and b == 0


def test_a9_hyperbola_matches_the_seed_general_form() -> None:
    a, b, m, n = 1.5, 2.0, 5.0, 4.0
    co = env(f"P1 = POINT/{m},{n}\nH1 = HYPERB/CENTER,P1,{a},{b}")["H1"].coefficients
    want = (
        b * b,
        0,
        -a * a,
        -2 * b * b * m,
        2 * a * a * n,
        b * b * m * m - a * a * n * n - a * a * b * b,
    )
    assert close(co, want, 1e-12)


# --- B10 point-to-point ---------------------------------------------------------------------------


def test_b10_from_goto_godlta() -> None:
    _, recs = run("FROM/-1,-5,3\nGOTO/2,3,4\nGOTO/4,8,7\nGODLTA/-1")
    assert [(r.word, r.args, r.line) for r in recs] == [
        ("FROM", (-1.0, -5.0, 3.0), 1),
        ("GOTO", (2.0, 3.0, 4.0), 2),
        ("GOTO", (4.0, 8.0, 7.0), 3),
        ("GOTO", (4.0, 8.0, 6.0), 4),
    ]
    legs = [math.dist(a.args, b.args) for a, b in zip(recs, recs[1:], strict=False)]
    assert legs[0] == pytest.approx(8.6023, abs=1e-4) and legs[1] == pytest.approx(6.1644, abs=1e-4)


def test_b10_godlta_three_values_and_omitted_z() -> None:
    _, recs = run("FROM/0,0,0\nGODLTA/1,2,3\nGOTO/5,6\nZSURF/9\nGOTO/7,8")
    assert [r.args for r in recs[1:]] == [(1.0, 2.0, 3.0), (5.0, 6.0, 0.0), (7.0, 8.0, 0.0)]


def test_b10_godlta_without_a_position() -> None:
    e = error("CUTTER/1\nGODLTA/1")
    assert (e.line, e.col) == (2, 1) and "known tool position" in e.message


# --- B11 continuous path --------------------------------------------------------------------------

SQUARE = """CUTTER/0.5
S1 = LINE/0,0,10,0
S2 = LINE/10,0,10,6
S3 = LINE/10,6,0,6
S4 = LINE/0,6,0,0
S5 = PLANE/0,0,1,-0.5
FROM/-3,-3,1
GO/TO,S1,TO,S5,TO,S4
TLRGT,GORGT/S1,PAST,S2
GOLFT/S2,PAST,S3
GOLFT/S3,PAST,S4
GOLFT/S4,PAST,S1
"""


def test_b11_four_sided_contour_offset_by_the_cutter_radius() -> None:
    _, recs = run(SQUARE)
    pts = [r.args for r in recs if r.word == "GOTO"]
    assert pts == [
        (-0.25, -0.25, -0.5),
        (10.25, -0.25, -0.5),
        (10.25, 6.25, -0.5),
        (-0.25, 6.25, -0.5),
        (-0.25, -0.25, -0.5),
    ]


def test_b11_inside_pocket_and_to_modifiers() -> None:
    src = SQUARE.replace("FROM/-3,-3,1", "FROM/3,3,1").replace(
        "TLRGT,GORGT/S1,PAST,S2", "TLLFT,GOLFT/S1,TO,S2"
    )
    src = src.replace("GOLFT/S2,PAST,S3", "GOLFT/S2,TO,S3").replace(
        "GOLFT/S3,PAST,S4", "GOLFT/S3,TO,S4"
    )
    src = src.replace("GOLFT/S4,PAST,S1", "GOLFT/S4,TO,S1")
    _, recs = run(src)
    pts = [r.args[:2] for r in recs if r.word == "GOTO"]
    assert pts == [(0.25, 0.25), (9.75, 0.25), (9.75, 5.75), (0.25, 5.75), (0.25, 0.25)]


def test_b11_arc_drive_surface_exact_tangent_points() -> None:
    # a slot end: along L1, round the circle (tangent), back along L2
    src = """UNITS/MM
CUTTER/4
L1 = LINE/0,0,20,0
C1 = CIRCLE/20,10,10
L2 = LINE/20,20,0,20
L0 = LINE/0,-10,0,30
PS = PLANE/0,0,1,0
FROM/-10,-10,5
GO/TO,L1,TO,PS,ON,L0
TLRGT,GORGT/L1,TANTO,C1
GOFWD/C1,TANTO,L2
GOFWD/L2,ON,L0
"""
    _, recs = run(src)
    words = [
        (r.word, tuple(round(a, 9) for a in r.args)) for r in recs if r.word in ("GOTO", "CIRCLE")
    ]
    assert words == [
        ("GOTO", (0.0, -2.0, 0.0)),
        ("GOTO", (20.0, -2.0, 0.0)),
        ("CIRCLE", (20.0, 10.0, 0.0, 0.0, 0.0, 1.0, 12.0)),
        ("GOTO", (20.0, 22.0, 0.0)),
        ("GOTO", (0.0, 22.0, 0.0)),
    ]


def test_b11_part_surface_persists_and_check_becomes_drive() -> None:
    _, recs = run(SQUARE.replace("GOLFT/S3,PAST,S4", "S6 = PLANE/0,0,1,-1\nGOLFT/S3,PAST,S4"))
    assert {r.args[2] for r in recs if r.word == "GOTO"} == {-0.5}


def test_b11_unreachable_check_surface() -> None:
    src = SQUARE.replace("GOLFT/S2,PAST,S3", "S7 = LINE/20,0,20,6\nGOLFT/S2,PAST,S7")
    e = error(src)
    assert "unreachable check surface" in e.message and (e.line, e.col) == (11, 15)


def test_b11_tool_on_the_wrong_side() -> None:
    e = error(SQUARE.replace("TLRGT,GORGT/S1", "TLLFT,GORGT/S1"))
    assert e.line == 9 and "off the drive surface" in e.message


def test_b11_contour_needs_a_cutter() -> None:
    e = error(SQUARE.replace("CUTTER/0.5", "$$ no cutter"))
    assert e.line == 8 and "CUTTER" in e.message


def test_b11_gofwd_ambiguous_direction() -> None:
    e = error(SQUARE.replace("TLRGT,GORGT/S1,PAST,S2", "INDIRV/0,1,0\nTLRGT,GOFWD/S1,PAST,S2"))
    assert "perpendicular" in e.message and e.line == 10


# --- B12 cutter ------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("stmt", "why"),
    [
        ("CUTTER/0", "diameter must be > 0"),
        ("CUTTER/-1", "diameter must be > 0"),
        ("CUTTER/1,-0.1", "corner radius must be >= 0"),
        ("CUTTER/1,0,0,0,90,0", "A must be in [0, 90)"),
        ("CUTTER/1,0,0,0,-1,0", "A must be in [0, 90)"),
        ("CUTTER/1,0,0,0,0,90", "B must be in (-90, 90)"),
        ("CUTTER/1,0.6", "cutter undefined"),
        ("CUTTER/1,0.2,0.1,0.1,0,0", "cutter undefined"),
        ("CUTTER/1,2,3", "CUTTER/d"),
    ],
)
def test_b12_cutter_validation(stmt: str, why: str) -> None:
    e = error("UNITS/MM\n" + stmt)
    assert e.line == 2 and why in e.message


def test_b12_cutter_defaults_and_auto_corner() -> None:
    _, recs = run("CUTTER/1,0.2,0,0,0,0\nUNITS/MM\nCUTTER/10,2,0,0,10,5")
    cutters = [r.args for r in recs if r.word == "CUTTER"]
    assert cutters[0][6] == 5.0 and cutters[1][6] == 127.0
    _, recs = run("CUTTER/1,0.2,0.3,0.2,0,0")  # E, F consistent with the tangent corner
    assert recs[0].args[:2] == (1.0, 0.2)


# --- post-processor statements pass through --------------------------------------------------------


def test_machin_names_the_post_with_any_word() -> None:
    _, recs = run("MACHIN/UNCX01,1\nMACHIN/FANUC")
    assert [r.args for r in recs] == [("UNCX01", 1.0), ("FANUC",)]


def test_post_statements_pass_through() -> None:
    src = (
        "PARTNO TEST1\nMACHIN/MILL,1\nUNITS/MM\nLOADTL/1\nSPINDL/1000,CLW\nFEDRAT/10,MMPM\nRAPID\n"
        "COOLNT/FLOOD\nCUTCOM/LEFT,1\nDELAY/2.5\nSTOP\nOPSTOP\nEND\nFINI\nGOTO/1,2,3\n"
    )
    warnings: list = []
    _, recs = run(src, warnings.append)
    assert [r.word for r in recs] == [
        "PARTNO", "MACHIN", "UNITS", "LOADTL", "SPINDL", "FEDRAT", "RAPID", "COOLNT",
        "CUTCOM", "DELAY", "STOP", "OPSTOP", "END", "FINI",
    ]  # fmt: skip
    assert recs[0].text == "TEST1"
    assert recs[4].args == (1000.0, "CLW")
    assert warnings and "after FINI" in warnings[0].message and warnings[0].line == 15


@pytest.mark.parametrize(
    ("src", "line", "col", "why"),
    [
        ("FEDRAT/0", 1, 1, "feed rate > 0"),
        ("COOLNT/WATER", 1, 8, "undefined name 'WATER'"),
        ("GOTO/1,2,3\nUNITS/MM", 2, 1, "UNITS changed after motion"),
        ("LOADTL/1.5", 1, 1, "tool number"),
        ("POINT/1,2", 1, 1, "give it a name"),
        ("P1 = POINT/1,2,3,4,5", 1, 6, "not a POINT form"),
        ("FOO/1", 1, 1, "unknown statement word 'FOO'"),
        ("P1 = POINT/1,,2", 1, 14, "empty argument"),
        ("P1 = POINT/1,2 #", 1, 16, "invalid character"),
        ("P1 = POINT/1,2 $\n", 1, 14, "past the end of the file"),
        ("X = 1/0", 1, 6, "division by zero"),
        ("P1 = POINT/1,2\nX = P1 + 1", 2, 5, "expected a number"),
        ("L1 = LINE/1,1,1,1", 1, 6, "coincide"),
    ],
)
def test_error_classes_say_where_and_why(src: str, line: int, col: int, why: str) -> None:
    e = error(src)
    assert (e.file, e.line, e.col) == ("t.apt", line, col)
    assert why in e.message


def test_boss_round_a_circle_and_vertical_moves() -> None:
    """A round boss: down onto the part surface, start-up to the circle, once round it
    (the check surface is a line through the centre), up again."""
    src = """UNITS/MM
CUTTER/10
C1 = CIRCLE/0,0,20
L1 = LINE/0,0,1,0
TOP = PLANE/0,0,1,0
BOT = PLANE/0,0,1,-5
FROM/-40,0,10
GODOWN/C1,TO,BOT
GO/TO,C1
INDIRV/0,-1,0
TLRGT,GOFWD/C1,ON,L1
GOUP/C1,ON,TOP
"""
    _, recs = run(src)
    got = [
        (r.word, tuple(round(a, 9) for a in r.args)) for r in recs if r.word in ("GOTO", "CIRCLE")
    ]
    assert got == [
        ("GOTO", (-40.0, 0.0, -5.0)),
        ("GOTO", (-25.0, 0.0, -5.0)),
        ("CIRCLE", (0.0, 0.0, -5.0, 0.0, 0.0, 1.0, 25.0)),  # outside, counter-clockwise
        ("GOTO", (25.0, 0.0, -5.0)),
        ("GOTO", (25.0, 0.0, 0.0)),
    ]


def test_vertical_move_to_a_plane_that_is_not_there() -> None:
    e = error("CUTTER/1\nC1 = CIRCLE/0,0,2\nPL = PLANE/0,0,1,5\nFROM/0,-5,0\nGODOWN/C1,TO,PL")
    assert e.line == 5 and "not below the tool" in e.message


def test_cutter_too_big_for_an_inside_circle() -> None:
    e = error("CUTTER/10\nC1 = CIRCLE/0,0,4\nFROM/0,0,0\nINDIRV/1,0,0\nGO/TO,C1")
    assert e.line == 5 and "does not fit inside" in e.message
