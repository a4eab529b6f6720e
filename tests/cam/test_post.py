"""The 3-axis mill and lathe posts: seed 004 requirements C13-C15, `nc check`, refusals, CLI."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cam.apt import process
from cam.cl import read_cl
from cam.errors import CamError
from cam.post import POSTS, PostOptions, load_machine, post
from cnc.config import MACHINES_DIR
from cnc.interp import check

SEED15 = """PARTNO TEST1
MACHIN/MILL,1
CUTTER/0.5
LOADTL/1
SPINDL/1000,CLW
COOLNT/FLOOD
FROM/-1,-5,3
RAPID
GOTO/2,3,4
FEDRAT/10,IPM
GOTO/4,8,7
GODLTA/-1
COOLNT/OFF
SPINDL/OFF
FINI
"""

SEED15_NC = """G20 G90 G94
T1 M06
S1000 M03
M08
G00 X2. Y3. Z4.
G01 X4. Y8. Z7. F10.
Z6.
M09
M05
M30"""

MILL_G54 = {1: (-300.0, -300.0, -300.0)}  # the seed part sits inside the mill3 travel


def post_text(src: str, machine: str = "mill3", fmt: str = "apt", **opts) -> tuple[str, object]:
    recs = process(src, "t.apt") if fmt == "apt" else read_cl(src, "t.cl")
    p, blocks = post(recs, load_machine(machine), PostOptions(**opts), "t.apt")
    return "\n".join(b.text for b in blocks), p


def body(nc: str) -> str:
    lines = nc.splitlines()
    assert lines[0] == "%" and lines[-1] == "%" and lines[1].startswith("O")
    return "\n".join(lines[2:-1])


def test_c15_seed_program_exact_output() -> None:
    nc, p = post_text(SEED15)
    assert nc.splitlines()[:2] == ["%", "O0001 (TEST1)"]
    assert body(nc) == SEED15_NC
    assert p.summary.blocks_in == 15 and p.summary.blocks_out == 9


def test_c15_passes_nc_check_for_mill3() -> None:
    nc, _ = post_text(SEED15)
    params = load_machine("mill3").config.params
    assert [str(e) for e in check(nc, params, work_offsets=MILL_G54)] == []


def test_c13_rapid_is_for_the_next_motion_only() -> None:
    nc, _ = post_text(
        "FEDRAT/5\nFROM/0,0,0\nRAPID\nGOTO/1,0,0\nGOTO/2,0,0\nRAPID\nGOTO/3,0,0\nGOTO/4,0,0\nFINI"
    )
    assert body(nc).splitlines()[1:] == [
        "G00 X1. Y0. Z0.", "G01 X2. F5.", "G00 X3.", "G01 X4.", "M30",
    ]  # fmt: skip


@pytest.mark.parametrize("feed", ["FEDRAT/10", "FEDRAT/10,IPM"])
def test_c13_fedrat_ipm_is_the_default(feed: str) -> None:
    nc, _ = post_text(f"{feed}\nGOTO/1,2,3\nFINI")
    assert body(nc).splitlines() == ["G20 G90 G94", "G01 X1. Y2. Z3. F10.", "M30"]


def test_c13_words() -> None:
    nc, _ = post_text(
        "UNITS/MM\nLOADTL/7\nSPINDL/800,CCLW\nCOOLNT/MIST\nCOOLNT/ON\nCOOLNT/OFF\nSPINDL/OFF\n"
        "SPINDL/ON\nDELAY/1.5\nFEDRAT/0.1,MMPR\nCUTCOM/LEFT\nGOTO/1,1,0\nCUTCOM/OFF\nGOTO/0,0,0\n"
        "STOP\nOPSTOP\nFINI"
    )
    assert body(nc).splitlines() == [
        "G21 G90 G94", "T7 M06", "S800 M04", "M07", "M08", "M09", "M05", "S800 M04",
        "G04 X1.5", "G41 D7 G01 X1. Y1. Z0. G95 F0.1", "G40 X0. Y0.", "M00", "M01", "M30",
    ]  # fmt: skip


def test_c14_units_block_before_any_motion_and_units_after_motion_refused() -> None:
    nc, _ = post_text("UNITS/MM\nFEDRAT/100\nGOTO/1,2,3\nFINI")
    assert body(nc).splitlines()[0] == "G21 G90 G94"
    nc, _ = post_text("FEDRAT/10\nGOTO/1,2,3\nFINI")
    assert body(nc).splitlines()[0] == "G20 G90 G94"
    with pytest.raises(CamError) as ei:
        post_text("FEDRAT/10\nGOTO/1,2,3\nUNITS/MM\nFINI", fmt="cl")
    assert ei.value.line == 3 and "UNITS changed after motion" in ei.value.message


def test_program_number_from_partno_or_option() -> None:
    nc, _ = post_text("PARTNO BRACKET 4711\nFINI")
    assert nc.splitlines()[1] == "O4711 (BRACKET 4711)"
    nc, _ = post_text("PARTNO BRACKET 4711\nFINI", program_number=12)
    assert nc.splitlines()[1] == "O0012 (BRACKET 4711)"


def test_arcs_become_g02_g03_with_centre_offsets() -> None:
    cl = (
        "UNITS/MM\nFEDRAT/100\nGOTO/10,0,0\nCIRCLE/0,0,0,0,0,1,10\nGOTO/0,10,0\n"
        "CIRCLE/0,0,0,0,0,-1,10\nGOTO/10,0,0\nFINI"
    )
    nc, _ = post_text(cl, fmt="cl")
    assert body(nc).splitlines()[2:4] == ["G17 G03 X0. Y10. I-10. J0.", "G02 X10. Y0. I0. J-10."]
    params = load_machine("mill3").config.params
    assert check(nc, params, work_offsets=MILL_G54) == []


def test_the_processor_s_contour_posts_and_checks() -> None:
    src = """UNITS/MM
CUTTER/4
L1 = LINE/0,0,20,0
C1 = CIRCLE/20,10,10
L2 = LINE/20,20,0,20
L0 = LINE/0,-10,0,30
PS = PLANE/0,0,1,-2
FEDRAT/300
FROM/-10,-10,5
GO/TO,L1,TO,PS,ON,L0
TLRGT,GORGT/L1,TANTO,C1
GOFWD/C1,TANTO,L2
GOFWD/L2,ON,L0
FINI
"""
    nc, _ = post_text(src)
    assert body(nc).splitlines()[1:] == [
        "G01 X0. Y-2. Z-2. F300.", "X20.", "G17 G03 Y22. I0. J12.", "G01 X0.", "M30",
    ]  # fmt: skip
    assert check(nc, load_machine("mill3").config.params, work_offsets=MILL_G54) == []


def test_arc_with_a_wrong_radius_is_refused() -> None:
    with pytest.raises(CamError) as ei:
        post_text("FEDRAT/1\nGOTO/10,0,0\nCIRCLE/0,0,0,0,0,1,10\nGOTO/0,11,0\nFINI", fmt="cl")
    assert ei.value.line == 4 and "not on the circle" in ei.value.message


@pytest.mark.parametrize("machine", ["mill3", "lathe2"])
def test_five_axis_data_to_a_three_axis_kind_is_refused(machine: str) -> None:
    cl = "UNITS/MM\nFEDRAT/100\nGOTO/0,0,0,0,0,1\nGOTO/1,0,0,0.6,0,0.8\nFINI"
    with pytest.raises(CamError) as ei:
        post_text(cl, machine, fmt="cl")
    e = ei.value
    assert (e.file, e.line) == ("t.apt", 4)
    assert "5-axis CL data" in e.message and "cannot be posted to a 3-axis machine" in e.message


def test_a_cutting_move_needs_a_feed() -> None:
    with pytest.raises(CamError) as ei:
        post_text("GOTO/1,2,3\nFINI", fmt="cl")
    assert ei.value.line == 1 and "without a feed rate" in ei.value.message


def test_unknown_cl_word_is_refused() -> None:
    with pytest.raises(CamError) as ei:
        post_text("FEDRAT/1\nGOTO/1,2,3\nCLAMP/ON\nFINI", fmt="cl")
    assert ei.value.line == 3 and "cannot execute CL word CLAMP" in ei.value.message


LATHE_CL = """PARTNO SHAFT 1234
UNITS/MM
LOADTL/3
SPINDL/1200.0,CLW
COOLNT/FLOOD
FROM/60.0,0.0,20.0
RAPID
GOTO/20.0,0.0,2.0
FEDRAT/0.2,MMPR
GOTO/20.0,0.0,-30.0
CIRCLE/25.0,0.0,-30.0,0.0,-1.0,0.0,5.0
GOTO/25.0,0.0,-35.0
FEDRAT/150.0,MMPM
GOTO/45.0,0.0,-35.0
RAPID
GOTO/60.0,0.0,20.0
COOLNT/OFF
SPINDL/OFF
FINI
"""


def test_lathe_post_diameters_turret_and_feed_modes() -> None:
    nc, _ = post_text(LATHE_CL, "lathe2", fmt="cl")
    assert body(nc).splitlines() == [
        "G21 G18", "T0303", "G97 S1200 M03", "M08", "G00 X40. Z2.", "G01 Z-30. G99 F0.2",
        "G02 X50. Z-35. I5. K0.", "G01 X90. G98 F150.", "G00 X120. Z20.", "M09", "M05", "M30",
    ]  # fmt: skip
    params = load_machine("lathe2").config.params
    assert check(nc, params, work_offsets={1: (-200.0, 0.0, -300.0)}) == []


def test_lathe_refuses_y() -> None:
    with pytest.raises(CamError) as ei:
        post_text("UNITS/MM\nFEDRAT/1\nGOTO/1,0,1\nGOTO/1,2,1\nFINI", "lathe2", fmt="cl")
    assert ei.value.line == 4 and "no Y axis" in ei.value.message


def test_the_post_is_chosen_by_kind_not_by_name(tmp_path: Path) -> None:
    f = tmp_path / "vmc_big.yaml"
    shutil.copy(MACHINES_DIR / "mill3.yaml", f)
    m = load_machine(f)
    assert (m.name, m.kind) == ("vmc_big", "mill")
    nc, _ = post_text(SEED15, str(f))
    assert body(nc) == SEED15_NC
    assert set(POSTS) >= {"mill", "lathe", "mill5"}


def test_merging_collinear_blocks() -> None:
    cl = "UNITS/MM\nFEDRAT/100\nGOTO/0,0,0\n" + "".join(f"GOTO/{i},0,0\n" for i in range(1, 11))
    cl += "GOTO/10,5,0\nFINI\n"
    nc, p = post_text(cl, fmt="cl", merge=True)
    assert body(nc).splitlines()[1:] == ["G01 X0. Y0. Z0. F100.", "X10.", "Y5.", "M30"]
    assert p.summary.blocks_merged == 9


# --- the command line ---------------------------------------------------------------------------


@pytest.fixture
def cli():
    from server.cli import app

    runner = CliRunner()
    return lambda *args: runner.invoke(app, list(args))


def test_cli_cl_prints_the_cl_data(cli, tmp_path: Path) -> None:
    src = tmp_path / "seed.apt"
    src.write_text(SEED15)
    r = cli("cam", "cl", str(src))
    assert r.exit_code == 0
    assert r.stdout.splitlines()[:3] == ["PARTNO TEST1", "MACHIN/MILL,1.0", "CUTTER/0.5"]
    bad = tmp_path / "bad.apt"
    bad.write_text("P1 = POINT/1,2\nC1 = CIRCLE/CENTER,P9,RADIUS,1\n")
    r = cli("cam", "cl", str(bad))
    assert r.exit_code == 1 and f"{bad}:2:20: undefined name 'P9'" in r.stderr


def test_cli_post_json_and_output_only_on_success(cli, tmp_path: Path) -> None:
    src = tmp_path / "seed.apt"
    src.write_text(SEED15)
    out = tmp_path / "seed.nc"
    # the part (4 x 8 x 6 in above its zero) placed near a table corner: the shipped G54
    # (table centre) would put its Y 8 in past the travel, as the default check says
    r = cli("cam", "post", str(src), "--machine", "mill3", "-o", str(out), "--json")
    assert r.exit_code == 1 and "beyond the soft limit" in r.stderr and not out.exists()
    r = cli(
        "cam", "post", str(src), "--machine", "mill3", "--g54", "-500,-300,-300",
        "-o", str(out), "--json",
    )  # fmt: skip
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["blocks_in"] == 15 and doc["blocks_out"] == 9 and doc["nc_check"] == "passed"
    assert doc["points_inserted"] == 0 and doc["singular_records"] == []
    assert body(out.read_text().rstrip("\n")) == SEED15_NC
    # travel beyond the machine's limits: refused, traced to the APT line, nothing written
    out2 = tmp_path / "far.nc"
    r = cli("cam", "post", str(src), "--machine", "mill3", "--g54", "0,0,0", "-o", str(out2))
    assert r.exit_code == 1 and not out2.exists()
    assert f"{src}:9:0: posted block" in r.stderr and "soft limit" in r.stderr
    # 5-axis CL to the 3-axis mill: refused with file and line, nothing written
    cl = tmp_path / "five.cl"
    cl.write_text("UNITS/MM\nFEDRAT/100\nGOTO/0,0,0,0.6,0,0.8\nFINI\n")
    r = cli("cam", "post", str(cl), "--machine", "mill3", "-o", str(out2))
    assert r.exit_code == 1 and not out2.exists()
    assert f"{cl}:3:1: 5-axis CL data" in r.stderr
    assert not list(tmp_path.glob(".cam-*"))


def test_cli_post_bad_machine(cli, tmp_path: Path) -> None:
    src = tmp_path / "seed.apt"
    src.write_text(SEED15)
    r = cli("cam", "post", str(src), "--machine", str(tmp_path / "nope.yaml"))
    assert r.exit_code == 2 and "cannot read the machine file" in r.stderr


def test_readme_example_posts_for_two_machines(cli, tmp_path: Path) -> None:
    """The README's "post an APT program for two machines" stays true."""
    example = Path(__file__).resolve().parents[2] / "cam" / "examples" / "plate.apt"
    out3, out5 = tmp_path / "plate_mill3.nc", tmp_path / "plate_mill5.nc"
    r = cli(
        "cam",
        "post",
        str(example),
        "--machine",
        "mill3",
        "--g54",
        "-300,-300,-300",
        "-o",
        str(out3),
        "--json",
    )
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert (doc["nc_check"], doc["travel_checked"], doc["blocks_out"]) == ("passed", True, 24)
    assert out3.read_text().splitlines()[1] == "O2001 (PLATE 2001)"
    assert "G17 G03 Y45. I0. J25." in out3.read_text()
    r = cli("cam", "post", str(example), "--machine", "mill5", "-o", str(out5), "--json")
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["kind"] == "mill5" and doc["singular_count"] == 16 and len(doc["warnings"]) == 1
    text = out5.read_text()
    assert "G00 X-20. Y-20. Z2. B0. C0." in text and " B" not in text.split("B0. C0.", 1)[1]


def test_post_without_g54_checks_travel_on_the_machines_own_setup(cli, tmp_path: Path) -> None:
    """With no --g54 the posted program is placed by the machine's own machine data (the
    shipped mill3's G54 is the table centre, X-300 Y-200): a path 400 mm right of the part
    zero runs off the X travel (0 at the right end), and the refusal names the CL line."""
    src = tmp_path / "long.cl"
    src.write_text(
        "PARTNO LONG\nUNITS/MM\nLOADTL/1\nSPINDL/3000,CLW\nRAPID\nGOTO/0,0,10\n"
        "FEDRAT/500\nGOTO/0,0,-1\nGOTO/400,0,-1\nRAPID\nGOTO/400,0,10\nEND\nFINI\n"
    )
    r = cli("cam", "post", str(src), "--machine", "mill3", "--json")
    assert r.exit_code != 0
    assert f"{src}:9:0:" in r.output and "X" in r.output, r.output
    ok = tmp_path / "short.cl"
    ok.write_text(src.read_text().replace("GOTO/400,", "GOTO/200,"))
    r = cli("cam", "post", str(ok), "--machine", "mill3", "--json")
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert (doc["nc_check"], doc["travel_checked"]) == ("passed", True)
