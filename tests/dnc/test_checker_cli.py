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
    # On a lathe (Fanuc G code system A) G90 is the turning cycle, not absolute mode: its
    # X Z are a cutting pass that needs a feed, and G91 does not exist (U W are incremental).
    cycle = lathe.replace("G1 Z-20 F0.2", "G90 X30 Z-20")
    assert nc_checker(cycle, "lathe")[0]["message"] == "feed move without F"
    assert nc_checker(cycle.replace("Z-20", "Z-20 F0.2"), "lathe") == []
    assert nc_checker(lathe.replace("G18 G21", "G18 G21 G91"), "lathe")[0]["message"] == (
        "unsupported G code G91"
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


def test_dnc_send_and_receive_against_a_machine(tmp_path):
    from tests.cnc.dnc_helpers import Machine

    db = f"sqlite:///{tmp_path / 'cli.db'}"
    (tmp_path / "plate.nc").write_text(GOOD)
    runner = CliRunner()
    m = Machine(capacity=8192)
    try:
        port = m.port.bound_port
        args = ["--database-url", db]
        assert (
            runner.invoke(app, ["dnc", "import", str(tmp_path / "plate.nc"), *args]).exit_code == 0
        )
        refused = runner.invoke(app, ["dnc", "send", "O1000", "-m", "mill1", *args])
        assert refused.exit_code == 1 and "unknown machine 'mill1'" in refused.output
        added = runner.invoke(
            app, ["dnc", "machine", "mill1", "--kind", "mill", "--dnc", f"127.0.0.1:{port}", *args]
        )
        assert added.exit_code == 0
        unreleased = runner.invoke(app, ["dnc", "send", "O1000", "-m", "mill1", *args])
        assert "no released revision of O1000 for mill" in unreleased.output
        from dnc.db import make_engine, session_factory
        from dnc.library import Library

        lib = Library(session_factory(make_engine(db)))
        lib.release(lib.search(number=1000).items[0].latest_revision_id, approver="a", comment="ok")
        sent = runner.invoke(app, ["dnc", "send", "1000", "-m", "mill1", *args])
        assert sent.exit_code == 0, sent.output
        assert "sent to mill1" in sent.output and "verified" in sent.output
        back = runner.invoke(app, ["dnc", "receive", "O1000", "-m", "mill1", *args])
        assert back.exit_code == 0 and "revision 1 (released) from mill1" in back.output
    finally:
        m.close()


def test_dnc_calls_and_send_bring_the_subprograms(tmp_path):
    """A folder imported main first (file name order): the main's check goes on past its
    call; `dnc calls` shows the dependency both ways and a dispatch brings O1002 along."""
    from dnc.db import make_engine, session_factory
    from dnc.library import Library
    from tests.cnc.dnc_helpers import Machine

    db = f"sqlite:///{tmp_path / 'cli.db'}"
    args = ["--database-url", db]
    folder = tmp_path / "gauge"
    folder.mkdir()
    (folder / "a-main.nc").write_text(
        "%\nO1001 (GAUGE)\nG21 G90\nG1 X-1 F100\nM98 P1002 L2\nM30\n%\n"
    )
    (folder / "b-sub.nc").write_text("%\nO1002 (PASS)\nG91 G1 X-1\nG90\nM99\n%\n")
    runner = CliRunner()
    imported = runner.invoke(app, ["dnc", "import", str(folder), *args])
    assert imported.exit_code == 0 and imported.output.count("(check ok)") == 2, imported.output
    shown = runner.invoke(app, ["dnc", "calls", "O1001", *args])
    assert "line 5: M98 calls O1002 (not released)" in shown.output
    assert shown.exit_code == 1 and "not dispatchable: O1001" in shown.output
    lib = Library(session_factory(make_engine(db)))
    for number in (1001, 1002):
        rev = lib.search(number=number).items[0].latest_revision_id
        lib.release(rev, approver="a", comment="ok")
    shown = runner.invoke(app, ["dnc", "calls", "1002", *args])
    assert shown.exit_code == 0 and "called by O1001 GAUGE line 5 (M98" in shown.output
    m = Machine(capacity=8192)
    try:
        runner.invoke(app, ["dnc", "machine", "mill1", "--kind", "mill", "--dnc",
                            f"127.0.0.1:{m.port.bound_port}", *args])  # fmt: skip
        sent = runner.invoke(app, ["dnc", "send", "O1001", "-m", "mill1", *args])
        assert sent.exit_code == 0, sent.output
        assert "with O1002 sent to mill1" in sent.output
        assert [e.number for e in m.memory.directory()] == [1001, 1002]
    finally:
        m.close()
