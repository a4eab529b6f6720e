"""The 5-axis post (kind mill5, B45/C table-table) against seed 002's vectors and properties."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from cam.apt import process
from cam.cl import ClRecord, read_cl
from cam.errors import CamError
from cam.machine5 import MILL5_FILE, load_mill5
from cam.post import Machine, PostOptions, load_machine, post
from cam.post.mill5 import Mill5Post
from cnc.kinematics import bc45_forward, bc45_inverse, bc45_rotary

TABLE1 = [
    (20, 0, -155, 0.6327447124, 0.465569252, 0.6187742456),
    (100, 0, -150, 0.628284235, 0.461387437, 0.62640867),
    (200, 0, -146, 0.623829809, 0.457180279, 0.634039219),
    (300, 0, -139, 0.618938519, 0.452948814, 0.6416794216),
]
BIG = 5000.0


def mill5(
    d: float = 0.0, branch: str = "positive", c: dict | None = None, travel: float = BIG
) -> Machine:
    data = yaml.safe_load(MILL5_FILE.read_text())
    data["kinematics"].update(d_mm=d, branch=branch)
    lim = {"min": -travel, "max": travel}
    b = {"min": -185.0, "max": 185.0}
    data["axes"] = {"X": lim, "Y": lim, "Z": lim, "B": b, "C": c or {"continuous": True}}
    return Machine("m5", "mill5", load_mill5(data))


def cl_of(points, feed: bool = True) -> str:
    head = "UNITS/MM\nMULTAX/ON\n" + ("FEDRAT/1000\n" if feed else "")
    return (
        head
        + "".join("GOTO/" + ",".join(repr(float(v)) for v in p) + "\n" for p in points)
        + "FINI\n"
    )


def run(text: str, machine: Machine | None = None, **opts):
    trace: list = []
    p, blocks = post(
        read_cl(text, "t.cl"), machine or mill5(), PostOptions(trace=trace, **opts), "t.cl"
    )
    nc = [b.text for b in blocks]
    return nc, p, trace


def ik_post(d: float = 0.0, branch: str = "positive") -> Mill5Post:
    p = Mill5Post(mill5(d, branch), PostOptions(), "t.cl")
    p.units = "MM"
    p._setup()
    return p


REC = ClRecord("GOTO", (), line=7)


# --- inverse kinematics test vectors (002 req 3, 4) ---------------------------------------------


@pytest.mark.parametrize(
    ("vec", "b", "c"),
    [
        ((-0.70710678, -0.5, 0.5), 90.0, 0.0),
        ((0.0, -1.0, 0.0), 180.0, 0.0),
        ((1.0, 0.0, 0.0), 180.0, -90.0),
        ((0.0, 1.0, 0.0), 180.0, 180.0),
        ((-1.0, 0.0, 0.0), 180.0, 90.0),
        (TABLE1[0][3:], 76.2582, 172.6859),
        (TABLE1[1][3:], 75.3560, 172.3460),
        (TABLE1[2][3:], 74.4570, 172.0119),
        (TABLE1[3][3:], 73.5392, 171.6547),
    ],
)
def test_ik_rotary_vectors(vec, b: float, c: float) -> None:
    j = ik_post().ik((0.0, 0.0, 0.0, *vec), None, REC)
    assert j[3] == pytest.approx(b, abs=1e-4) and j[4] == pytest.approx(c, abs=1e-4)
    rb, rc, _ = bc45_rotary(vec)  # the NC kernel's transform agrees
    assert (rb, rc) == pytest.approx((j[3], j[4]), abs=1e-9)


def test_ik_singular_keeps_c_and_reports_the_line() -> None:
    p = ik_post()
    j = p.ik((1.0, 2.0, 3.0, 0.0, 0.0, 1.0), 33.0, REC)
    assert j[3] == 0.0 and j[4] == 33.0
    assert p.summary.singular == [7] and "singular" in p.summary.warnings[0].message
    # k0 = 1: X/Y are the pure C rotation of (x0, y0), Z = z0
    cr = math.radians(33.0)
    assert j[0] == pytest.approx(math.cos(cr) - 2 * math.sin(cr))
    assert j[1] == pytest.approx(math.sin(cr) + 2 * math.cos(cr))
    assert j[2] == pytest.approx(3.0)


def test_ik_unreachable_is_refused_with_the_line() -> None:
    with pytest.raises(CamError) as ei:
        ik_post().ik((0.0, 0.0, 0.0, 0.0, 0.0, -1.0), None, REC)
    assert ei.value.line == 7 and "orientation unreachable" in ei.value.message


@pytest.mark.parametrize(
    ("d", "xyz"),
    [(0.0, (35.3553, -12.0711, -2.0711)), (100.0, (106.0660, -62.0711, -52.0711))],
)
def test_ik_linear_axes_eq_10_12(d: float, xyz) -> None:
    j = ik_post(d).ik((10.0, 20.0, 30.0, -0.70710678, -0.5, 0.5), None, REC)
    assert j[:3] == pytest.approx(xyz, abs=1e-4)


@pytest.mark.parametrize(
    ("point", "xyz"),
    [
        (TABLE1[0], (-109.428, 74.291, -83.255)),
        (TABLE1[1], (-118.564, 132.186, -31.133)),
        (TABLE1[2], (-133.600, 205.987, 32.193)),
        (TABLE1[3], (-148.840, 279.030, 96.488)),
    ],
)
def test_ik_table1_linear_axes(point, xyz) -> None:
    j = ik_post(0.0).ik(tuple(float(v) for v in point), None, REC)
    assert j[:3] == pytest.approx(xyz, abs=2e-3)


# --- linearisation (002 req 6) -------------------------------------------------------------------


@pytest.mark.parametrize("d", [0.0, 100.0])
@pytest.mark.parametrize(("tol", "points"), [(0.5, 4), (0.25, 6), (0.1, 7), (0.05, 13), (0.01, 25)])
def test_linearisation_counts_table1(d: float, tol: float, points: int) -> None:
    nc, p, trace = run(cl_of(TABLE1), mill5(d), tolerance_mm=tol)
    assert len(trace) == points
    assert p.summary.points_inserted == points - 4
    assert p.summary.peak_deviation <= tol


def test_linearisation_d500() -> None:
    # the digest's midpoint deviations at d = 500 are 0.252 / 0.313 / 0.317 mm: at T = 0.25
    # the first segment is bisected too (the "insensitive to d" note holds for the other T)
    counts = [
        len(run(cl_of(TABLE1), mill5(500.0), tolerance_mm=t)[2])
        for t in (0.5, 0.25, 0.1, 0.05, 0.01)
    ]
    assert counts == [4, 7, 7, 13, 25]


def test_unlinearised_deviation_table1() -> None:
    _, p, _ = run(cl_of(TABLE1), mill5(0.0), tolerance_mm=1.0)
    assert p.summary.peak_deviation == pytest.approx(0.306, abs=1e-3)
    _, p, _ = run(cl_of(TABLE1[:2]), mill5(0.0), tolerance_mm=1.0)
    assert p.summary.peak_deviation == pytest.approx(0.242, abs=1e-3)


def test_linearisation_structure_exact_midpoints_in_order() -> None:
    _, _, trace = run(cl_of(TABLE1), mill5(0.0), tolerance_mm=0.05)
    xs = [pose[0] for pose, _ in trace]
    assert xs == [20, 40, 60, 80, 100, 125, 150, 175, 200, 225, 250, 275, 300]
    zs = [pose[2] for pose, _ in trace]
    assert zs[1:4] == [-153.75, -152.5, -151.25] and zs[9:12] == [-144.25, -142.5, -140.75]
    for pose, _ in trace:  # inserted orientations are normalised
        assert math.sqrt(sum(v * v for v in pose[3:])) == pytest.approx(1.0, abs=1e-9)


def test_after_linearisation_the_sampled_deviation_is_small() -> None:
    _, p, trace = run(cl_of(TABLE1), mill5(0.0), tolerance_mm=0.1)
    worst = 0.0
    post5 = ik_post(0.0)
    for (pa, ja), (pb, jb) in zip(trace, trace[1:], strict=False):
        for s in range(1, 100):
            t = s / 100
            tip = post5.fk_tip(*(a + t * (b - a) for a, b in zip(ja, jb, strict=True)))
            worst = max(worst, _dist_to_segment(tip, pa, pb))
    assert worst <= 0.1  # the digest: 0.077 mm


def test_linearisation_is_idempotent() -> None:
    _, _, trace = run(cl_of(TABLE1), mill5(0.0), tolerance_mm=0.05)
    _, p, trace2 = run(cl_of([pose for pose, _ in trace]), mill5(0.0), tolerance_mm=0.05)
    assert p.summary.points_inserted == 0 and len(trace2) == len(trace)


def test_rapid_moves_are_not_linearised() -> None:
    text = cl_of(TABLE1).replace("GOTO/100.0", "RAPID\nGOTO/100.0")
    _, p, trace = run(text, mill5(0.0), tolerance_mm=0.25)
    assert [pose[0] for pose, _ in trace] == [20, 100, 150, 200, 250, 300]  # 1-2 is rapid


def test_posted_blocks() -> None:
    nc, p, _ = run("PARTNO P5 77\n" + cl_of(TABLE1[:2]), mill5(0.0), tolerance_mm=0.5)
    assert nc[:3] == ["%", "O0077 (P5 77)", "G21 G90 G94"]
    assert nc[3] == "G01 X-109.428 Y74.291 Z-83.255 B76.2582 C172.6859 F1000."
    assert nc[4].startswith("X-118.564 Y132.186 Z-31.133 B75.356 C172.346")
    assert nc[-2:] == ["M30", "%"]


def test_singular_records_are_reported_with_their_lines() -> None:
    pts = [(0, 0, 10, 0, 0, 1), (10, 0, 10, 0, 0, 1), (20, 0, 10, 0.6, 0, 0.8)]
    nc, p, _ = run(cl_of(pts), mill5(0.0))
    assert p.summary.singular == [4, 5] and p.summary.singular_count == 2
    assert [w.line for w in p.summary.warnings if "singular" in w.message] == [4]


def test_unreachable_record_is_refused_with_its_line() -> None:
    pts = [(0, 0, 10, 0, 0, 1), (10, 0, 10, 0.6, 0, -0.8)]
    with pytest.raises(CamError) as ei:
        run(cl_of(pts))
    assert (ei.value.file, ei.value.line) == ("t.cl", 5) and "unreachable" in ei.value.message


def test_travel_limits_after_posting() -> None:
    with pytest.raises(CamError) as ei:
        run(cl_of(TABLE1), mill5(0.0, travel=250.0), tolerance_mm=0.5)
    assert ei.value.line == 7 and "beyond the Y travel" in ei.value.message


def _circling(turns: float = 2.0, k: float = 0.7) -> list:
    s = math.sqrt(1 - k * k)
    n = int(turns * 12)
    return [
        (50.0, 0.0, 0.0, s * math.cos(a), s * math.sin(a), k)
        for a in (math.radians(30 * q) for q in range(n + 1))
    ]


def test_c_is_unwrapped_for_continuity() -> None:
    _, _, trace = run(cl_of(_circling()), mill5(0.0), tolerance_mm=1000.0)
    cs = [j[4] for _, j in trace]
    assert all(abs(b - a) <= 30.0 + 1e-9 for a, b in zip(cs, cs[1:], strict=False))
    assert abs(cs[-1] - cs[0]) == pytest.approx(720.0)


def test_c_limits_are_respected() -> None:
    path = _circling()  # the tool axis turns twice round: C travels 720 degrees
    free = run(cl_of(path), mill5(0.0), tolerance_mm=1000.0)[2]
    cs = [j[4] for _, j in free]
    lo, hi = min(cs), max(cs)
    assert hi - lo == pytest.approx(720.0)
    inside = mill5(0.0, c={"min": lo - 1.0, "max": hi + 1.0})
    assert [j[4] for _, j in run(cl_of(path), inside, tolerance_mm=1000.0)[2]] == cs
    # a table that turns less: a cutting move cannot unwind it (the tool axis would sweep
    # round), so the post refuses at the first record beyond the limit
    mid = (lo + hi) / 2
    limited = mill5(
        0.0, c={"min": lo - 1.0, "max": mid} if cs[-1] > cs[0] else {"min": mid, "max": hi + 1.0}
    )
    with pytest.raises(CamError) as ei:
        run(cl_of(path), limited, tolerance_mm=1000.0)
    first_out = next(
        i
        for i, c in enumerate(cs)
        if not (limited.config.axes.C.min <= c <= limited.config.axes.C.max)
    )
    assert "beyond the C limits" in ei.value.message and ei.value.line == 4 + first_out
    # a rapid may take the other way round, within the limits
    _, _, trace = run(cl_of(path).replace("GOTO/", "RAPID\nGOTO/"), limited)
    assert all(limited.config.axes.C.min <= j[4] <= limited.config.axes.C.max for _, j in trace)


def test_leaving_the_singular_orientation_turns_c_first() -> None:
    pts = [(0, 0, 10, 0, 0, 1), (10, 0, 10, 0, 0, 1), (20, 0, 10, 0.6, 0, 0.8)]
    nc, p, trace = run(cl_of(pts), mill5(0.0), tolerance_mm=0.01)
    assert p.summary.peak_deviation <= 0.01
    turn = [(pose, j) for pose, j in trace if pose[:3] == (10.0, 0.0, 10.0)]
    assert len(turn) > 2 and all(j[3] == 0.0 for _, j in turn)  # C turns at B = 0
    # C turns to its limit approaching B = 0 along the next segment (-180 here), and the
    # segment then brings it to the end point's C
    assert turn[-1][1][4] == pytest.approx(-180.0, abs=0.01)
    assert trace[-1][1][4] == pytest.approx(-160.5288, abs=1e-4)


def test_negative_branch_is_used_consistently() -> None:
    _, _, trace = run(cl_of(TABLE1), mill5(50.0, "negative"), tolerance_mm=0.01)
    assert all(j[3] < 0 for _, j in trace)
    for pose, j in trace:
        tip, axis = bc45_forward(j, 50.0)
        assert tip == pytest.approx(pose[:3], abs=1e-9) and axis == pytest.approx(
            pose[3:], abs=1e-9
        )


def test_merging_collinear_blocks_with_constant_orientation() -> None:
    v = (0.6, 0.0, 0.8)
    pts = [(float(x), 0.0, 0.0, *v) for x in range(0, 11)]
    nc, p, trace = run(cl_of(pts), mill5(0.0), merge=True)
    assert len(trace) == 2 and p.summary.blocks_merged == 9


def test_apt_source_with_tool_axes_posts_to_mill5() -> None:
    src = "UNITS/MM\nMULTAX/ON\nFEDRAT/500\nGOTO/20,0,-155,0.6327447124,0.465569252,0.6187742456\nGOTO/100,0,-150,0.628284235,0.461387437,0.62640867\nFINI\n"
    trace: list = []
    _, blocks = post(process(src, "t.apt"), mill5(0.0), PostOptions(tolerance_mm=0.25, trace=trace))
    assert list(blocks)[-2:][0].text == "M30" and len(trace) == 2


# --- properties ------------------------------------------------------------------------------------

_orient = st.tuples(st.floats(0.15, 0.97), st.floats(-math.pi, math.pi))
_pos = st.tuples(*[st.floats(-150, 150)] * 3)


def _vec(k: float, a: float) -> tuple[float, float, float]:
    s = math.sqrt(1 - k * k)
    return (s * math.cos(a), s * math.sin(a), k)


@settings(max_examples=40)
@given(
    start=st.tuples(_pos, _orient),
    steps=st.lists(
        st.tuples(_pos, st.floats(-0.15, 0.15), st.floats(-0.6, 0.6)), min_size=1, max_size=5
    ),
    d=st.floats(0, 300),
)
def test_property_posted_tool_tip_within_t_at_every_midpoint(start, steps, d: float) -> None:
    (p0, (k, a)) = start
    pts = [(*p0, *_vec(k, a))]
    for pos, dk, da in steps:
        k = min(max(k + dk, 0.15), 0.97)
        a += da
        pts.append((*pos, *_vec(k, a)))
    tol = 0.01
    nc, p, trace = run(cl_of(pts), mill5(d), tolerance_mm=tol)
    post5 = ik_post(d)
    segments = list(zip(pts, pts[1:], strict=False))
    seg = 0
    for (pa, ja), (pb, jb) in zip(trace, trace[1:], strict=False):
        # each sent point is exactly where the CL path is (forward kinematics)
        tip, axis = bc45_forward(jb, d)
        assert tip == pytest.approx(pb[:3], abs=1e-7) and axis == pytest.approx(pb[3:], abs=1e-9)
        while _dist_to_segment(pb[:3], segments[seg][0][:3], segments[seg][1][:3]) > 1e-6:
            seg += 1
        mid = post5.fk_tip(*((u + v) / 2 for u, v in zip(ja, jb, strict=True)))
        cl_mid = [(u + v) / 2 for u, v in zip(pa[:3], pb[:3], strict=True)]
        assert math.dist(mid, cl_mid) <= tol + 1e-12
        assert _dist_to_segment(mid, segments[seg][0][:3], segments[seg][1][:3]) <= tol + 1e-12
    assert p.summary.peak_deviation <= tol
    # the NC text carries those joints, rounded to 0.001 mm and 0.0001 degree (a point
    # that rounds to the block before it sends no block)
    sent: list[tuple[float, ...]] = []
    for _, j in trace:
        r = tuple(float(f"{v:.3f}") for v in j[:3]) + tuple(float(f"{v:.4f}") for v in j[3:])
        if not sent or sent[-1] != r:
            sent.append(r)
    assert _joints_of(nc) == sent


def _joints_of(nc: list[str]) -> list[tuple[float, ...]]:
    """The X Y Z B C of every motion block (modal words carried on)."""
    cur: dict[str, float] = {}
    out = []
    for line in nc:
        words = {w[0]: float(w[1:]) for w in line.split() if w[0] in "XYZBC"}
        if words:
            cur.update(words)
            out.append(tuple(cur[a] for a in "XYZBC"))
    return out


@given(
    xyz=_pos,
    b=st.floats(0.5, 179.5),
    c=st.floats(-179.5, 179.5),
    d=st.floats(0, 500),
    branch=st.sampled_from(["positive", "negative"]),
)
def test_property_ik_of_fk_is_the_identity(xyz, b: float, c: float, d: float, branch: str) -> None:
    post5 = ik_post(d, branch)
    b = b if branch == "positive" else -b
    joints = (*xyz, b, c)
    tip, axis = bc45_forward(joints, d)
    back = post5.ik((*tip, *axis), c, REC)
    assert back == pytest.approx(joints, abs=1e-7)
    assert post5.fk_tip(*back) == pytest.approx(tip, abs=1e-9)
    if branch == "positive":
        ref = bc45_inverse(tip, axis, d, previous_c=c)
        assert back == pytest.approx(tuple(ref[:5]), abs=1e-9)


@given(pos=_pos, o=_orient, d=st.floats(0, 500))
def test_property_fk_of_ik_is_the_identity(pos, o, d: float) -> None:
    vec = _vec(*o)
    j = ik_post(d).ik((*pos, *vec), None, REC)
    tip, axis = bc45_forward(j, d)
    assert tip == pytest.approx(pos, abs=1e-9) and axis == pytest.approx(vec, abs=1e-12)


def _dist_to_segment(p, a, b) -> float:
    ab = [v - u for u, v in zip(a, b, strict=True)]
    L2 = sum(v * v for v in ab)
    t = 0.0 if L2 == 0 else max(0.0, min(1.0, sum((p[q] - a[q]) * ab[q] for q in range(3)) / L2))
    return math.dist(p, [a[q] + t * ab[q] for q in range(3)])


# --- machine description and the command line -------------------------------------------------------


def test_shipped_mill5_loads_and_bad_descriptions_say_where(tmp_path: Path) -> None:
    m = load_machine("mill5")
    assert (m.kind, m.config.kinematics.type) == ("mill5", "table_table_bc45")
    data = yaml.safe_load(MILL5_FILE.read_text())
    data["axes"]["C"] = {"continuous": True, "min": 0.0}
    f = tmp_path / "m5.yaml"
    f.write_text(yaml.safe_dump(data))
    with pytest.raises(CamError) as ei:
        load_machine(f)
    assert "axes.C" in str(ei.value) and str(f) in str(ei.value)


def test_cli_post_mill5_json(tmp_path: Path) -> None:
    from server.cli import app

    src = tmp_path / "t1.cl"
    src.write_text(cl_of(TABLE1))
    out = tmp_path / "t1.nc"
    r = CliRunner().invoke(
        app,
        [
            "cam",
            "post",
            str(src),
            "--machine",
            "mill5",
            "--tolerance",
            "0.05",
            "--json",
            "-o",
            str(out),
        ],
    )
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["blocks_in"] == 8 and doc["points_inserted"] == 9 and doc["blocks_out"] == 14
    assert 0 < doc["peak_midpoint_deviation_mm"] <= 0.05 and doc["singular_records"] == []
    assert doc["tolerance_mm"] == 0.05 and doc["nc_check"] == "passed" and doc["travel_checked"]
    assert out.read_text().count("\n") == 18


def test_cli_unreachable_refused_nothing_written(tmp_path: Path) -> None:
    from server.cli import app

    src = tmp_path / "bad.cl"
    src.write_text(cl_of([(0, 0, 10, 0, 0, 1), (10, 0, 10, 0.6, 0, -0.8)]))
    out = tmp_path / "bad.nc"
    r = CliRunner().invoke(app, ["cam", "post", str(src), "--machine", "mill5", "-o", str(out)])
    assert r.exit_code == 1 and not out.exists()
    assert f"{src}:5:1: orientation unreachable" in r.stderr


def test_inch_cl_data_is_posted_with_the_machine_constants_in_inch() -> None:
    """The same Table 1 in inches (UNITS/INCHES, the APT default): T and d are mm in the
    machine file, so the counts are the millimetre ones and the axes come out in inch."""
    inch = [(x / 25.4, y / 25.4, z / 25.4, i, j, k) for x, y, z, i, j, k in TABLE1]
    text = cl_of(inch).replace("UNITS/MM\n", "").replace("FEDRAT/1000", "FEDRAT/40")
    for tol, points in ((0.25, 6), (0.05, 13), (0.01, 25)):
        nc, p, trace = run(text, mill5(100.0), tolerance_mm=tol)
        assert len(trace) == points
    assert nc[2] == "G20 G90 G94"
    mm = ik_post(100.0).ik(tuple(float(v) for v in TABLE1[0]), None, REC)
    assert trace[0][1][:3] == pytest.approx(tuple(v / 25.4 for v in mm[:3]), abs=1e-9)
    assert trace[0][1][3:] == pytest.approx(mm[3:], abs=1e-9)
    assert nc[3].startswith("G01 X") and nc[3].split()[1].count(".") == 1
    assert len(nc[3].split()[1].split(".")[1]) <= 4  # 4 decimals in inch


def test_cli_missing_file_and_bad_tolerance(tmp_path: Path) -> None:
    from server.cli import app

    runner = CliRunner()
    r = runner.invoke(app, ["cam", "post", str(tmp_path / "none.cl"), "--machine", "mill5"])
    assert r.exit_code == 2 and "cannot read" in r.stderr
    src = tmp_path / "t.cl"
    src.write_text(cl_of(TABLE1))
    r = runner.invoke(app, ["cam", "post", str(src), "--machine", "mill5", "--tolerance", "0"])
    assert r.exit_code == 2 and "--tolerance must be > 0" in r.stderr


def test_inverse_time_feed() -> None:
    data = yaml.safe_load(MILL5_FILE.read_text())
    data["post"]["feed"] = "inverse_time"
    data["axes"]["Y"] = {"min": -1000.0, "max": 1000.0}
    machine = Machine("m5", "mill5", load_mill5(data))
    nc, _, trace = run(cl_of(TABLE1), machine, tolerance_mm=0.25)
    motion = [ln for ln in nc if ln.startswith(("G01", "X", "Y", "Z"))]
    assert motion[0].endswith(" F1000.")  # the first move, from wherever the machine is: G94
    for ln, ((pa, _), (pb, _)) in zip(motion[1:], zip(trace, trace[1:], strict=False), strict=True):
        words = ln.split()
        assert words[-1].startswith("F")  # G93: F in every block
        minutes = math.dist(pa[:3], pb[:3]) / 1000.0
        assert float(words[-1][1:]) == pytest.approx(1 / minutes, abs=1e-3)
    assert " G93 " in motion[1] and all("G93" not in m for m in motion[2:])
