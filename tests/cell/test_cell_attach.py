"""`fmscell run --attach`: a host that connects to machines running elsewhere (their own
services) through the faces named in the configuration, and leaves them running."""

from __future__ import annotations

import pytest

from cnc.config import load_cell_config
from server.cell import Cell, default_cell
from server.supervisor import MachineUnavailable

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
            # program select needs the operator face, which an attached machine may lack
            with pytest.raises(MachineUnavailable, match="no operator face"):
                attached.command("mill1", "select_program", number=1)
        finally:
            attached.stop()
        # the attached host's stop leaves the machines running
        assert owner.monitor.status("mill1")["connected"]
        assert owner.machines[0].thread.is_alive()
    finally:
        owner.stop()
