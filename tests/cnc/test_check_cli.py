"""`fmscell nc check FILE` (through the real `fmscell` typer app): exit 0 when valid, else exit 1 and FILE:LINE:COL: message lines."""

from pathlib import Path

from typer.testing import CliRunner

from server.cli import app

PROGRAMS = Path(__file__).parent / "programs"
runner = CliRunner()


def test_valid_mill_program_exits_0() -> None:
    res = runner.invoke(app, ["nc", "check", str(PROGRAMS / "pocket_mill.nc")])
    assert res.exit_code == 0, res.output
    assert res.output == ""


def test_valid_lathe_and_least_increment_programs() -> None:
    res = runner.invoke(app, ["nc", "check", "--kind", "lathe", str(PROGRAMS / "lathe_shaft.nc")])
    assert res.exit_code == 0, res.output
    res = runner.invoke(
        app, ["nc", "check", "--decimal", "least_increment", str(PROGRAMS / "least_increment.nc")]
    )
    assert res.exit_code == 0, res.output
    # the same program read calculator style runs off the travel: X-10000 mm
    res = runner.invoke(app, ["nc", "check", str(PROGRAMS / "least_increment.nc")])
    assert res.exit_code == 1 and "soft limit" in res.output


def test_broken_program_lists_every_error() -> None:
    path = PROGRAMS / "broken.nc"
    res = runner.invoke(app, ["nc", "check", str(path)])
    assert res.exit_code == 1
    assert "no G20/G21 in the program: read in mm" in res.stderr
    lines = res.stdout.splitlines()
    assert lines == [
        f"{path}:4:1: feed move without F",
        f"{path}:5:1: unsupported G code G5",
        f"{path}:6:8: E word with no code in this block that uses it",
        f"{path}:7:1: PS0116 #0 is always vacant (read only)",
        f"{path}:8:14: unterminated comment: '(' without ')'",
    ]


def test_soft_limits_and_work_offset_options(tmp_path) -> None:
    p = tmp_path / "pos.nc"
    p.write_text("G0 X10 Y10 Z10\nM30\n")
    # the shipped mill's setup (G54 at the table centre) takes an ordinary program
    assert runner.invoke(app, ["nc", "check", str(p)]).exit_code == 0
    res = runner.invoke(app, ["nc", "check", "--g54", "0,0,0", str(p)])
    assert res.exit_code == 1 and "beyond the soft limit" in res.stdout
    assert runner.invoke(app, ["nc", "check", "--g54", "-300,-200,-100", str(p)]).exit_code == 0
    args = ["nc", "check", "--g54", "0,0,0", "--no-soft-limits", str(p)]
    assert runner.invoke(app, args).exit_code == 0
    assert runner.invoke(app, ["nc", "check", "--g54", "1,2", str(p)]).exit_code == 2


def test_missing_file_and_bad_options() -> None:
    res = runner.invoke(app, ["nc", "check", "/nonexistent/x.nc"])
    assert res.exit_code == 1
    assert runner.invoke(app, ["nc", "check", "--kind", "robot", "x.nc"]).exit_code == 2


def test_block_delete_option(tmp_path) -> None:
    p = tmp_path / "bd.nc"
    p.write_text("G0 X-1\n/G5\nM30\n")
    assert runner.invoke(app, ["nc", "check", str(p)]).exit_code == 1
    assert runner.invoke(app, ["nc", "check", "--block-delete", str(p)]).exit_code == 0


def test_config_option_uses_the_machine_yaml() -> None:
    machines = Path(__file__).resolve().parents[2] / "cnc" / "machines"
    prog = str(PROGRAMS / "lathe_shaft.nc")
    res = runner.invoke(
        app, ["nc", "check", "--config", str(machines / "lathe2.yaml"), "--no-soft-limits", prog]
    )
    assert res.exit_code == 0, res.output
    res = runner.invoke(app, ["nc", "check", "--config", "/nonexistent.yaml", prog])
    assert res.exit_code == 2
