"""The cell's commands and its start-up where they fail (server/cell.py): which face carries
each machine command and what the host records of it, machine-data refusals mapped to the
API's errors, a cell attached to machines that are not there, and `fmscell run` refusing a
bad start with one line and an exit status.

No machine runs here: the remote panel is scripted and the simulation face is a loopback
socket (tests/server/test_supervisor.py), so every path is reached at once and the same way.
"""

from __future__ import annotations

import contextlib
import os

import pytest
import yaml

from cnc.config import load_cell_config
from server.cell import Cell, default_cell, run_cell
from server.cycle_audit import HostRequests
from server.supervisor import MachineLink, MachineUnavailable
from tests.server.test_supervisor import ScriptedPanel, SimFace, free_port


@pytest.fixture
def cell(monkeypatch):
    """A cell (not started) whose machine m1 is a scripted panel and a simulation face."""
    panel = ScriptedPanel()
    monkeypatch.setattr(
        MachineLink, "remote_panel", lambda self, timeout_s=3.0: contextlib.nullcontext(panel)
    )
    face = SimFace(None, {"ESTOP PRESS": "OK", "ESTOP RELEASE": "OK"})
    c = Cell(default_cell(free_ports=True))
    c.links["m1"] = MachineLink(
        "m1", "mill", "127.0.0.1", {"modbus": 1, "simulation": face.port}, ("X", "Y", "Z"), 0
    )
    c.host_requests = HostRequests()
    c.panel, c.face = panel, face
    yield c
    face.close()


@pytest.mark.parametrize("button", ["cycle_start", "feed_hold", "reset"])
def test_panel_buttons(cell, button):
    cell.panel.feed_hold = lambda: cell.panel.requests.append(("feed_hold",))
    cell.panel.reset = lambda: cell.panel.requests.append(("reset",))
    assert cell.command("m1", button) == f"{button} pressed on the Modbus remote panel"
    assert cell.panel.requests == [(button,)]
    # the cycle audit gives a cycle start to the REST command, not to a panel
    taken = cell.host_requests.take("m1", "cycle_start")
    assert taken == ("REST machine command" if button == "cycle_start" else None)


def test_estop_press_and_release_on_the_simulation_face(cell):
    assert cell.command("m1", "estop") == "E-stop button pressed (simulation face)"
    assert cell.command("m1", "estop", release=True) == "E-stop button released (simulation face)"
    assert cell.face.seen == ["ESTOP PRESS", "ESTOP RELEASE"]


def test_program_select_and_mode(cell):
    assert cell.command("m1", "select_program", number="17") == (
        "program O0017 selected on the Modbus remote panel"
    )
    assert cell.host_requests.take("m1", "program_select O0017") == "REST machine command"
    assert cell.command("m1", "mode", mode="mdi") == "mode mdi taken (Modbus remote panel)"
    assert cell.panel.requests == [("select", 17), ("mode", 2)]


def test_refusals_come_back_as_machine_unavailable(cell):
    cell.panel.in_cycle = True
    with pytest.raises(MachineUnavailable, match="mode MDI refused: a program is active"):
        cell.command("m1", "mode", mode="MDI")
    with pytest.raises(MachineUnavailable, match=r"^unknown command 'spin'$"):
        cell.command("m1", "spin")
    from dnc.errors import NotFound

    with pytest.raises(NotFound, match="unknown machine 'm9'"):
        cell.command("m9", "reset")


class _Client:
    def __init__(self, error) -> None:
        self.error = error

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        return None

    def machine_data(self, what, doc):
        raise self.error


@pytest.mark.parametrize(
    ("alarm", "message", "want"),
    [
        (2012, "refused: /tools/3/length_mm: must be a number", ("MachineDataError", "/tools/3/length_mm: must be a number", "/tools/3/length_mm")),
        (2012, "refused: value out of range", ("MachineDataError", "value out of range", "")),
        (2009, "refused: program O0001 active", ("Conflict", "m1: program O0001 active", None)),
        (None, "connect: [Errno 111] Connection refused", ("MachineUnavailable", "m1: connect: [Errno 111] Connection refused", None)),
    ],
    ids=["bad-value-with-pointer", "bad-value", "in-cycle", "unreachable"],
)  # fmt: skip
def test_machine_data_refusals_become_the_apis_errors(cell, monkeypatch, alarm, message, want):
    from dnc import machine_link
    from dnc.transfer import TransferError

    error = TransferError("refused" if alarm else "connect", message, alarm=alarm)
    monkeypatch.setattr(machine_link, "client_for", lambda *a, **kw: _Client(error))
    cell.library = object()
    kind, text, pointer = want
    with pytest.raises(Exception) as err:
        cell.machine_data("m1", "tools", {"tools": []})
    assert type(err.value).__name__ == kind
    assert str(err.value) == text
    if pointer is not None:
        assert err.value.pointer == pointer


# ------------------------------------------------------------------ composition
def test_an_unknown_clock_is_refused():
    with pytest.raises(ValueError, match=r"clock 'slow': one of realtime, fast"):
        Cell(default_cell(free_ports=True), clock="slow")


def test_attach_links_the_configured_faces_and_the_simulation_only_with_faults():
    cfg = load_cell_config(
        {"machines": {"m1": {"base": "mill3", "ports": {"dnc": 7101, "modbus": 5121,
                                                        "shdr": 7978, "simulation": 7201}}}}
    )  # fmt: skip
    for faults, sim in ((False, None), (True, 7201)):
        cell = Cell(cfg, attach=True, faults=faults)
        cell._start_machines(1.0)
        lk = cell.links["m1"]
        assert lk.ports == {
            "dnc": 7101,
            "modbus": 5121,
            "shdr": 7978,
            "simulation": sim,
            "opcua": None,
        }
        assert cell.machines == []  # nothing started: the machines run elsewhere


def test_the_cell_file_written_for_machine_processes_is_owner_only(tmp_path):
    cell = Cell(default_cell(free_ports=True), processes=True, state_dir=tmp_path)
    path = cell._config_file()
    assert path == tmp_path / "fmscell-cell.yaml"
    assert path.stat().st_mode & 0o777 == 0o600
    doc = yaml.safe_load(path.read_text())
    assert {n: m["base"] for n, m in doc["machines"].items()} == {
        "mill1": "mill3",
        "mill2": "mill3",
        "lathe1": "lathe2",
    }
    given = tmp_path / "mine.yaml"
    assert Cell(default_cell(), config_file=given)._config_file() == given


def test_a_cell_attached_to_machines_that_are_not_there_says_which_and_stops(tmp_path):
    ports = {"dnc": free_port(), "modbus": free_port(), "shdr": free_port()}
    cfg = load_cell_config({"machines": {"m1": {"base": "mill3", "ports": ports}}})
    cell = Cell(cfg, attach=True, database_url=f"sqlite:///{tmp_path / 'cell.db'}",
                state_dir=tmp_path)  # fmt: skip
    with pytest.raises(MachineUnavailable, match=r"^m1: no SHDR status within 0.2 s$"):
        cell.start(ready_timeout_s=0.2)
    assert cell.started is False and cell.loops == []


# ------------------------------------------------------------------ fmscell run
def test_run_refuses_a_bad_clock_and_a_bad_cell_file(tmp_path):
    said: list[str] = []
    assert run_cell(clock="slow", echo=said.append) == 2
    assert said == ["--clock 'slow': one of realtime, fast"]
    bad = tmp_path / "cell.yaml"
    bad.write_text("machines: {m1: {base: nosuchmachine}}\n")
    said.clear()
    assert run_cell(config=bad, echo=said.append) == 2
    assert len(said) == 1 and said[0].startswith(f"{bad}: ")


def test_run_says_in_one_line_why_the_cell_did_not_start(monkeypatch):
    def fail(self, ready_timeout_s=120.0):
        raise MachineUnavailable("mill1: no SHDR status within 120 s")

    monkeypatch.setattr(Cell, "start", fail)
    said: list[str] = []
    env = {k: v for k, v in os.environ.items() if k != "FMSCELL_FAULTS"}
    monkeypatch.setattr(os, "environ", env)
    assert run_cell(echo=said.append) == 1
    assert said == ["cannot start the cell: mill1: no SHDR status within 120 s"]


def test_the_cell_lists_each_machines_opcua_endpoint():
    """`opcua_address` in GET /api/machines comes from the machines' bound OPC UA ports;
    a machine whose OPC UA face is off has none."""
    c = Cell(default_cell(free_ports=True))
    c.links["m1"] = MachineLink("m1", "mill", "127.0.0.1", {"opcua": 4999}, ("X",), 0)
    c.links["m2"] = MachineLink("m2", "mill", "127.0.0.1", {"opcua": None}, ("X",), 0)
    assert c.opcua_addresses() == {"m1": "opc.tcp://127.0.0.1:4999"}


def test_the_default_cell_serves_opcua_on_its_fixed_ports_and_not_with_free_ones():
    fixed = default_cell()
    assert {n: m.ports.opcua for n, m in fixed.machines.items()} == {
        "mill1": 4841,
        "lathe1": 4842,
        "mill2": 4843,
    }
    assert all(m.ports.opcua is None for m in default_cell(free_ports=True).machines.values())
    assert all(
        m.ports.opcua == 0 for m in default_cell(free_ports=True, opcua=True).machines.values()
    )
