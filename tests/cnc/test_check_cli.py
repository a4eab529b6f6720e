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


# A Haas macro as payne-o9001-macro.nc (advanced_arcs_o9001.cnc) writes it: the answer goes
# to the variable whose number the caller passes in V.
PYTHAGORAS = "%\nO9001\n#[#22] = SQRT[[#3 * #3] - [#1 * #1]]\nG0 X#[#22]\nM99\n%\n"


def test_g65_option_checks_a_macro_with_its_callers_arguments(tmp_path) -> None:
    p = tmp_path / "o9001.nc"
    p.write_text(PYTHAGORAS)
    # on its own #22 is vacant: the write goes to #0, refused as on the control
    res = runner.invoke(app, ["nc", "check", str(p)])
    assert res.exit_code == 1 and f"{p}:3:1: PS0116 #0 is always vacant" in res.stdout
    res = runner.invoke(app, ["nc", "check", "--g65", "A3. C5. V10100.", str(p)])
    assert res.exit_code == 0, res.output
    for bad, says in [("A3. G1", "column 5: G is not a G65 argument address"),
                      ("A3. A4.", "column 5: A given twice"),
                      ("A", "column 1: expected an address and a number")]:  # fmt: skip
        res = runner.invoke(app, ["nc", "check", "--g65", bad, str(p)])
        assert res.exit_code == 2 and says in res.stderr, (bad, res.output)


def test_g65_arguments_follow_argument_specification_i() -> None:
    from cnc.cli import g65_arguments

    assert g65_arguments("A.125 C.625 V10100.") == {1: 0.125, 3: 0.625, 22: 10100.0}
    assert g65_arguments("x-1 Y+2.5 Z3 I4 J5 K6 D7 E8 F9 H11 M13 Q17 R18 S19 T20 U21 W23 B2") == {
        24: -1.0, 25: 2.5, 26: 3.0, 4: 4.0, 5: 5.0, 6: 6.0, 7: 7.0, 8: 8.0, 9: 9.0, 11: 11.0,
        13: 13.0, 17: 17.0, 18: 18.0, 19: 19.0, 20: 20.0, 21: 21.0, 23: 23.0, 2: 2.0,
    }  # fmt: skip


# The shape of versa-haasngc-o9001.nc: a G65 macro that waits for a robot to write #10000,
# returns with an M99 in the middle and ends with alarm blocks (its last block is no M99).
WAITER = (
    "%\nO9001\nN1\nIF[#10000 EQ 3] GOTO2\nG04 P1.\nGOTO1\n"
    "N2\nM99\nN3\n#3000=15 (CLIENT COMMAND FAILURE)\n%\n"
)


def test_subprogram_option_and_preset_macro_variables(tmp_path) -> None:
    p = tmp_path / "o9001.nc"
    p.write_text(WAITER)
    res = runner.invoke(app, ["nc", "check", "--subprogram", str(p)])
    assert res.exit_code == 1 and f"{p}:6:1: endless loop" in res.stdout, res.output
    cfg = tmp_path / "answered.yaml"
    cfg.write_text("base: mill3\nmachine_data:\n  macro_variables: {10000: 3}\n")
    res = runner.invoke(app, ["nc", "check", "--config", str(cfg), "--subprogram", str(p)])
    assert res.exit_code == 0, res.output
    # read as a main program the M99 in the middle would repeat it for ever
    res = runner.invoke(app, ["nc", "check", "--config", str(cfg), "--main-program", str(p)])
    assert res.exit_code == 1 and f"{p}:8:1: M99 in the main program" in res.stdout
    cfg.write_text("base: mill3\nmachine_data:\n  macro_variables: {100: 3}\n")
    res = runner.invoke(app, ["nc", "check", "--config", str(cfg), str(p)])
    assert res.exit_code == 2
    assert "machine_data.macro_variables.100: a kept macro variable is #500-#999" in res.output


def test_a_cycle_with_the_hole_bottom_above_r_passes_with_a_warning(tmp_path: Path) -> None:
    # a Fanuc runs it, feeding upward from R (z64-stdbc-o0010.nc: G84 Z.5 R.1): a warning
    # per line, however often the cycle repeats, with the file and line of the subprogram
    path = tmp_path / "up.nc"
    path.write_text(
        "G21 G90 G0 X0 Y0 Z10\nS500 M3\nM98 P11 L3\nM30\nO11\nG99 G81 Z2 R-2 F100\nG80\nM99\n"
    )
    res = runner.invoke(app, ["nc", "check", "--no-soft-limits", str(path)])
    assert res.exit_code == 0, res.output
    assert res.stderr.splitlines() == [
        f"{path}:6:1: warning: canned cycle with the hole bottom above R: it feeds upward "
        "from R (a Fanuc runs it; a sign slip?)"
    ]
