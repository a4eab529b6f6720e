"""The NC check on upload (the real NC kernel) and the `fmscell dnc` commands."""

from __future__ import annotations

from typer.testing import CliRunner

from dnc.checker import nc_checker
from server.cli import app

GOOD = "%\nO1000 (PLATE)\nG21 G90 G54\nG0 X10 Y10 Z5\nG1 Z-1 F200\nG1 X60\nG0 Z5\nM30\n%\n"


def test_valid_program_passes_the_nc_check():
    assert nc_checker(GOOD, "mill") == []


def test_errors_carry_line_column_and_reason():
    errors = nc_checker(GOOD.replace("G1 X60", "G1 X60 G2"), "mill")
    assert errors == [
        {
            "line": 6,
            "col": 8,
            "message": "G2 and another G code of modal group 'motion' in one block",
        }
    ]


def test_work_offsets_unknown_to_the_host_do_not_fail_soft_limits():
    far = GOOD.replace("G1 X60", "G1 X900")
    assert nc_checker(far, "mill") == []


def test_lathe_programs_are_checked_as_lathe():
    lathe = "%\nO2000\nG18 G21\nG97 S1000 M3\nG0 X40 Z2\nG1 Z-20 F0.2\nM30\n%\n"
    assert nc_checker(lathe, "lathe") == []
    # On a lathe (Fanuc G code system A) G90 is the turning cycle, not absolute mode.
    assert (
        "turning cycle"
        in nc_checker(lathe.replace("G18 G21", "G18 G21 G90"), "lathe")[0]["message"]
    )


def test_dnc_import_and_list(tmp_path):
    db = f"sqlite:///{tmp_path / 'cli.db'}"
    progs = tmp_path / "progs"
    progs.mkdir()
    (progs / "plate.nc").write_text(GOOD)
    (progs / "bad.nc").write_text("%\nO1001\nG1 X10 Q\n%\n")
    (progs / "empty.nc").write_text("")
    runner = CliRunner()
    result = runner.invoke(
        app, ["dnc", "import", str(progs), "--tag", "demo", "--database-url", db]
    )
    assert result.exit_code == 1  # one file refused
    assert "plate.nc: program 2 revision 1 (check ok)" in result.output
    assert "bad.nc: program 1 revision 1 (1 check error(s))" in result.output
    assert "empty.nc: refused: " in result.output and "empty" in result.output
    listed = runner.invoke(app, ["dnc", "list", "--database-url", db])
    assert listed.exit_code == 0
    assert "O1000  mill   PLATE [demo]  released: none" in listed.output
