"""`fmscell run --attach`: a host that connects to machines running elsewhere (their own
services) through the faces named in the configuration, and leaves them running."""

from __future__ import annotations

import pytest

from server.cell import Cell, default_cell
from server.config import load_cell_config
from server.supervisor import MachineUnavailable
from tests.cell.conftest import poll

pytestmark = pytest.mark.timeout(120)


def test_an_attached_host_sees_and_commands_machines_it_did_not_start(tmp_path):
    owner = Cell(
        default_cell(free_ports=True),
        clock="fast",
        database_url=f"sqlite:///{tmp_path}/owner.db",
        ideal_axes=True,
    ).start()
    try:
        machines = {
            name: {
                "base": "lathe2" if link.kind == "lathe" else "mill3",
                "ports": {
                    "host": link.host,
                    **{f: link.ports[f] for f in ("dnc", "modbus", "shdr")},
                },
            }
            for name, link in owner.links.items()
        }
        attached = Cell(
            load_cell_config({"machines": machines}),
            clock="fast",
            database_url=f"sqlite:///{tmp_path}/attached.db",
            attach=True,
        ).start()
        try:
            assert attached.machines == []  # nothing started here
            registry = {m["name"]: m for m in attached.library.machines()}
            assert registry["mill1"]["dnc_address"] == owner.links["mill1"].address("dnc")
            status = attached.monitor.status("mill1")
            assert status["connected"] and status["mode"] == "AUTOMATIC"
            assert "Modbus" in attached.command("mill1", "feed_hold")
            # program select and homing travel on the Modbus remote panel too: an attached
            # host needs no other face (the NC answers: nothing is in its memory yet)
            with pytest.raises(MachineUnavailable, match=r"O0001 refused: program not in memory"):
                attached.command("mill1", "select_program", number=1)
            assert "homed" in attached.command("mill1", "home")
            status = attached.monitor.status("mill1")
            assert status["mode"] == "AUTOMATIC"
            assert status["actual"] == pytest.approx({"X": 0.0, "Y": 0.0, "Z": 0.0}, abs=1e-3)
        finally:
            attached.stop()
        # the attached host's stop leaves the machines running (the owner's status link
        # may have dropped and reconnected under load: poll to a deadline)
        poll(lambda: owner.monitor.status("mill1")["connected"], 20, "owner sees mill1")
        assert owner.machines[0].thread.is_alive()
    finally:
        owner.stop()
