"""`fmscell dnc import` of APT and CL files, and `dnc send` of an APT revision: posted for
the machine's kind on the way (dnc/posting.py)."""

from __future__ import annotations

import shutil
from pathlib import Path

from typer.testing import CliRunner

from server.cli import app
from tests.cnc.dnc_helpers import Machine

from .test_posting import FIVE_AXIS_CL

PLATE = Path(__file__).resolve().parents[2] / "cam" / "examples" / "plate.apt"


def test_import_apt_and_cl_then_send_the_posted_program(tmp_path):
    db = ["--database-url", f"sqlite:///{tmp_path / 'cli.db'}"]
    progs = tmp_path / "cam"
    progs.mkdir()
    shutil.copy(PLATE, progs / "plate.apt")
    (progs / "tilt.cls").write_text(FIVE_AXIS_CL)
    (progs / "bad.apt").write_text("PARTNO BAD 3\nGOTO/P9\n")
    runner = CliRunner()
    result = runner.invoke(app, ["dnc", "import", str(progs), "--post-kind", "mill5", *db])
    assert result.exit_code == 1, result.output  # bad.apt refused
    assert "bad.apt: refused: " in result.output and ":2:6: undefined name 'P9'" in result.output
    assert "plate.apt: program 1 revision 1 (check ok; apt, posted for mill5)" in result.output
    assert "tilt.cls: program 2 revision 1 (check ok; cl, posted for mill5)" in result.output
    # without --post-kind the plate's MACHIN/MILL decides; the tilted CL to a mill fails
    again = runner.invoke(app, ["dnc", "import", str(progs / "plate.apt"), *db])
    assert "plate.apt: program 1 revision 2 (check ok; apt, posted for mill)" in again.output
    tilt = runner.invoke(
        app, ["dnc", "import", str(progs / "tilt.cls"), "--post-kind", "mill", *db]
    )
    assert "tilt.cls: program 2 revision 2 (1 check error(s); cl, posted for mill)" in tilt.output
    assert ":9:1: post for mill: 5-axis CL data" in tilt.output

    m = Machine(capacity=16384)
    try:
        port = m.port.bound_port
        added = runner.invoke(
            app, ["dnc", "machine", "mill1", "--kind", "mill", "--dnc", f"127.0.0.1:{port}", *db]
        )
        assert added.exit_code == 0
        from dnc.db import make_engine, session_factory
        from dnc.library import Library

        lib = Library(session_factory(make_engine(db[1])))
        lib.release(lib.search(number=2001).items[0].latest_revision_id, approver="a", comment="ok")
        sent = runner.invoke(app, ["dnc", "send", "O2001", "-m", "mill1", *db])
        assert sent.exit_code == 0, sent.output
        assert "verified" in sent.output
        held = m.memory.get(2001)
        assert held.startswith("%\nO2001 (PLATE 2001)\nG21 G90 G94\n") and "GOTO" not in held
    finally:
        m.close()
