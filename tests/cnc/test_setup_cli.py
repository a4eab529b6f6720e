"""`nc check` / `nc plan` / `nc simulate` with the machine's setup, --tools, --offsets and
--units; an ordinary corpus program plans without options."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from cnc.cli import nc_app
from tests.reference import GCODE_CORPUS, MISSING

runner = CliRunner()

TOOL_PROG = "G21 G90 G54 G0 X0 Y0\nG43 H7 Z10\nM30\n"


def _plan(*args):
    res = runner.invoke(nc_app, ["plan", *map(str, args), "--json"])
    return res


def test_plan_takes_tools_and_offsets_files(tmp_path) -> None:
    p = tmp_path / "p.nc"
    p.write_text(TOOL_PROG)
    tools = tmp_path / "tools.csv"
    tools.write_text("number,length,length_wear,radius\n7,-40,-0.5,3\n")
    offsets = tmp_path / "ofs.csv"
    offsets.write_text("offset,x,y,z\nG54,-250,-150,-200\n")
    res = _plan(p, "--tools", tools, "--offsets", offsets)
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["final_position"] == {"X": -250.0, "Y": -150.0, "Z": -230.5}


def test_a_bad_tool_file_names_file_line_column(tmp_path) -> None:
    p = tmp_path / "p.nc"
    p.write_text(TOOL_PROG)
    tools = tmp_path / "tools.csv"
    tools.write_text("number,length\n7,-40\n8,long\n1000,1\n")
    for cmd in ("check", "plan"):
        res = runner.invoke(nc_app, [cmd, str(p), "--tools", str(tools)])
        assert res.exit_code == 2, res.output
        assert f"{tools}:3:3: length: 'long' is not a number" in res.stderr
        assert f"{tools}:4:1: number: must be within 1 .. 999" in res.stderr


def test_h_number_out_of_range_is_an_error(tmp_path) -> None:
    p = tmp_path / "p.nc"
    p.write_text("G21 G90 G43 H1000 Z10\nM30\n")
    res = runner.invoke(nc_app, ["check", str(p)])
    assert res.exit_code == 1 and ":1:" in res.stdout and "out of range" in res.stdout


@pytest.mark.parametrize(
    "units,x,warning", [(None, -299.0, "read in mm"), ("inch", -274.6, "read in inch")]
)
def test_power_on_unit_and_the_warning(tmp_path, units, x, warning) -> None:
    p = tmp_path / "p.nc"
    p.write_text("G90 G0 X1\nM30\n")
    args = ["--units", units] if units else []
    res = _plan(p, *args)
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["final_position"]["X"] == pytest.approx(x)
    assert "no G20/G21 in the program" in res.stderr and warning in res.stderr
    res = runner.invoke(nc_app, ["check", str(p), *args])
    assert res.exit_code == 0 and warning in res.stderr
    p.write_text("G21 G90 G0 X1\nM30\n")
    res = _plan(p, *args)
    assert json.loads(res.stdout)["final_position"]["X"] == pytest.approx(-299.0)
    assert "G20/G21" not in res.stderr


def test_bad_units_option() -> None:
    res = runner.invoke(nc_app, ["check", "x.nc", "--units", "cm"])
    assert res.exit_code == 2 and "--units" in res.stderr


def test_gcode_system_option_reads_a_system_b_lathe_program(tmp_path) -> None:
    p = tmp_path / "b.nc"
    p.write_text("G21 G90 G95\nG92 S800\nG97 S500 M3\nG0 X18 Z2\nG33 Z-17 F1.5\nG0 X20\nM30\n")
    assert runner.invoke(nc_app, ["check", "--kind", "lathe", str(p)]).exit_code == 1
    res = runner.invoke(nc_app, ["check", "--kind", "lathe", "--gcode-system", "B", str(p)])
    assert res.exit_code == 0, res.output
    for args in (["--gcode-system", "D", "--kind", "lathe"], ["--gcode-system", "B"]):
        res = runner.invoke(nc_app, ["check", str(p), *args])
        assert res.exit_code == 2 and "--gcode-system" in res.output, res.output


def test_lathe_uses_lathe2_and_its_tool_offsets(tmp_path) -> None:
    p = tmp_path / "l.nc"
    p.write_text("G21\nT0202\nG0 X50 Z2\nM30\n")
    res = _plan(p, "--kind", "lathe")
    assert res.exit_code == 0, res.output
    final = json.loads(res.stdout)["final_position"]
    # G54 X-200 Z-400 (lathe2.yaml), T2's offset X+1.5 (radius) Z-2, X50 = radius 25
    assert final == {"X": pytest.approx(-173.5), "Z": pytest.approx(-400.0)}


def test_simulate_takes_offsets_and_warns_about_units(tmp_path) -> None:
    p = tmp_path / "p.nc"
    p.write_text("%\nO0001\nG90 G0 X0 Y0 Z0\nM30\n%\n")
    offsets = tmp_path / "ofs.csv"
    offsets.write_text("offset,x,y,z\nG54,-100,-100,-100\n")
    res = runner.invoke(nc_app, ["simulate", str(p), "--ideal", "--offsets", str(offsets)])
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    assert out["final_position"] == pytest.approx({"X": -100.0, "Y": -100.0, "Z": -100.0})
    assert "no G20/G21" in res.stderr


@pytest.mark.skipif(not GCODE_CORPUS.exists(), reason=MISSING)
def test_an_ordinary_corpus_program_plans_without_options() -> None:
    # a Fusion 360 program, G54 at the part, Z10 clearance: inside mill3's travel as shipped
    for name in ("led-1024-block.nc", "led-1089-wall.nc", "led-1040-sq.nc"):
        res = runner.invoke(nc_app, ["check", str(GCODE_CORPUS / name)])
        assert res.exit_code == 0, res.output
    res = runner.invoke(nc_app, ["plan", str(GCODE_CORPUS / "led-1024-block.nc"), "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["moves"] > 10
