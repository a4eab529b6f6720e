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
import time

import pytest
import yaml

from cnc.machine_data import MachineDataError
from dnc.cell import CommandRefused, FaultRefused, InvalidFault
from dnc.errors import NotFound
from server.cell import Cell, default_cell, fault_spec, run_cell
from server.config import load_cell_config
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


def test_refusals_come_back_as_command_refused(cell):
    cell.panel.in_cycle = True
    with pytest.raises(CommandRefused, match="mode MDI refused: a program is active") as err:
        cell.command("m1", "mode", mode="MDI")
    assert err.value.command == "mode" and isinstance(err.value, MachineUnavailable)
    with pytest.raises(CommandRefused, match=r"^unknown command 'spin'$"):
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
        (2012, "refused: /tools/3/length_mm: must be a number", ("InvalidMachineData", "/tools/3/length_mm: must be a number", "/tools/3/length_mm")),
        (2012, "refused: value out of range", ("InvalidMachineData", "value out of range", "")),
        (2009, "refused: program O0001 active", ("Conflict", "m1: program O0001 active", None)),
        (None, "connect: [Errno 111] Connection refused", ("MachineUnavailable", "m1: connect: [Errno 111] Connection refused", None)),
    ],
    ids=["bad-value-with-pointer", "bad-value", "in-cycle", "unreachable"],
)  # fmt: skip
def test_machine_data_refusals_become_the_apis_errors(cell, monkeypatch, alarm, message, want):
    from dnc.transfer import TransferError
    from server import cell as cell_module

    error = TransferError("refused" if alarm else "connect", message, alarm=alarm)
    monkeypatch.setattr(cell_module, "client_for", lambda *a, **kw: _Client(error))
    cell.library = object()
    kind, text, pointer = want
    with pytest.raises(Exception) as err:
        cell.machine_data("m1", "tools", {"tools": []})
    assert type(err.value).__name__ == kind
    assert str(err.value) == text
    if pointer is not None:
        assert err.value.pointer == pointer
    if kind == "InvalidMachineData":  # still the machine's own MachineDataError
        assert isinstance(err.value, MachineDataError) and err.value.what == "tools"


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


def test_the_cell_file_rebuilds_a_mill4_and_a_mill5_from_their_own_machines(tmp_path):
    cfg = load_cell_config(
        {"machines": {"r4": {"base": "mill4", "ports": {"dnc": 0, "modbus": 0, "shdr": 0}},
                      "r5": {"base": "mill5", "ports": {"dnc": 0, "modbus": 0, "shdr": 0}}}}
    )  # fmt: skip
    cell = Cell(cfg, processes=True, state_dir=tmp_path)
    doc = yaml.safe_load(cell._config_file().read_text())
    assert {n: m["base"] for n, m in doc["machines"].items()} == {"r4": "mill4", "r5": "mill5"}


# ------------------------------------------------------------------ faults
def test_fault_refusals_are_the_cells_typed_errors(cell):
    """A bad spec is InvalidFault (a ValueError; its first line says why, the rest lists the
    valid specs), a face that refuses is FaultRefused, an unknown fault NotFound."""
    with pytest.raises(InvalidFault, match=r"(?s)^fault spec .*nonsense.*\n  valid specs: "):
        cell.inject("m1", {"type": "nonsense", "target": "X"})
    with pytest.raises(InvalidFault, match="target must be plc"):
        cell.inject("m1", {"type": "encoder", "target": "drive:"})
    with pytest.raises(FaultRefused, match="m1"):  # the face cuts the line: no answer
        cell.inject("m1", {"type": "encoder", "target": "X"})
    with pytest.raises(NotFound, match="no fault 7 on machine 'm1'"):
        cell.clear("m1", 7)
    assert cell.faults == {}


@pytest.mark.parametrize(
    ("request_", "spec"),
    [
        ({"type": "door_open", "target": "plc"}, "plc:door_open"),
        ({"type": "door_open", "target": "PLC", "params": {}}, "plc:door_open"),
        ({"type": "bus_off", "target": "bus:x"}, "bus:bus_off:X"),
        ({"type": "drop", "target": "BUS:y", "params": {"count": 3}}, "bus:drop:Y:count=3"),
        ({"type": "encoder_break", "target": "drive:z"}, "drive:Z:encoder_break"),
        ({"type": "load_force", "target": "x", "params": {"newtons": 500, "ramp_s": 2}},
         "drive:X:load_force:newtons=500,ramp_s=2"),
    ],
)  # fmt: skip
def test_fault_spec_of_an_api_request(request_, spec):
    assert fault_spec(request_) == spec


@pytest.mark.parametrize(
    ("request_", "why"),
    [
        ({"type": "door_open", "target": "plc", "params": {"s": 1}}, "plc faults take no params"),
        ({"type": "blocked"}, "target must be plc, drive:<AXIS>, <AXIS> or bus:<AXIS>"),
        ({"type": "blocked", "target": "drive:"}, "target must be plc, drive:<AXIS>"),
    ],
)
def test_fault_spec_refuses_a_request_that_names_no_target(request_, why):
    with pytest.raises(ValueError) as refused:
        fault_spec(request_)
    assert str(refused.value).startswith(why)


def test_fault_types_list_drive_bus_and_plc_faults_with_their_aliases():
    types = {t["type"]: t for t in Cell(default_cell(free_ports=True)).fault_types()}
    assert types["encoder_break"]["target"] == "drive:<AXIS>"
    assert types["encoder_break"]["detection"] and types["encoder_break"]["recovery"]
    assert types["bus_off"]["target"] == "bus:<AXIS>"
    assert {p["name"] for p in types["load_force"]["params"]} == {"newtons"}
    assert types["encoder"] == {
        "type": "encoder", "target": "drive:<AXIS>", "params": [], "description": "= encoder_break"
    }  # fmt: skip
    assert types["door_open"]["target"] == "plc" and types["door_open"]["params"] == []
    assert types["estop"]["description"] == "= estop_button"


def test_every_fault_type_says_how_to_bring_the_machine_back():
    """Every kind /api/fault-types lists, drive, bus or PLC, carries its recovery procedure
    and class (docs/recovery.md); an alias names its kind, which does."""
    rows = Cell(default_cell(free_ports=True)).fault_types()
    kinds = {t["type"]: t for t in rows if not t["description"].startswith("= ")}
    missing = [k for k, t in kinds.items() if not t.get("recovery") or not t.get("recovery_class")]
    assert not missing, f"no recovery procedure for {missing}"
    for alias in (t for t in rows if t["description"].startswith("= ")):
        assert alias["description"].removeprefix("= ") in kinds, alias


@pytest.fixture
def fault_cell(cell):
    """The cell whose m1 simulation face takes these fault and clear commands."""
    face = SimFace(
        None,
        {
            "FAULT drive:X:encoder_break": "OK injected drive:X:encoder_break t=12.5000",
            "FAULT drive:Y:encoder_break@2.5s": "OK scheduled drive:Y:encoder_break@2.5s",
            "CLEAR drive:X:encoder_break@0": "OK cleared drive:X:encoder_break t=13.0000",
            "CLEAR drive:Y:encoder_break@0": "OK cleared drive:Y:encoder_break t=14.2500",
            "FAULT plc:door_open": "ERR 2010 PLC faults are off on this machine",
        },
    )
    cell.links["m1"].ports["simulation"] = face.port
    cell.face = face
    yield cell
    cell.stop()
    face.close()


def test_inject_and_clear_go_to_the_simulation_face_once(fault_cell):
    cell = fault_cell
    fault = cell.inject("m1", {"type": "encoder_break", "target": "X"})
    later = cell.inject("m1", {"type": "encoder_break", "target": "drive:Y", "at": 2.5})
    assert (fault.id, later.id) == (1, 2)
    assert [f.spec for f in cell.machine_faults("m1")] == [
        "drive:X:encoder_break",
        "drive:Y:encoder_break@2.5s",
    ]
    assert fault.as_dict()["state"] == "active" and fault.as_dict()["target"] == "X"
    assert cell.clear("m1", 2) is later and later.state == "cleared" and later.cleared_at
    # the machine's clock at the injection and the clear, as the face answered them
    assert (fault.machine_t, later.machine_t, later.cleared_machine_t) == (12.5, None, 14.25)
    assert fault.as_dict()["machine_t"] == 12.5
    cell.clear("m1", 2)  # cleared already: nothing is sent again
    assert cell.face.seen == [
        "FAULT drive:X:encoder_break",
        "FAULT drive:Y:encoder_break@2.5s",
        "CLEAR drive:Y:encoder_break@0",
    ]
    assert fault.state == "active"


def test_a_fault_the_machine_refuses_is_not_recorded(fault_cell):
    with pytest.raises(MachineUnavailable, match=r"^m1: 2010 PLC faults are off on this machine$"):
        fault_cell.inject("m1", {"type": "door_open", "target": "plc"})
    assert fault_cell.machine_faults("m1") == []


def test_a_bad_fault_is_refused_before_the_machine_hears_of_it(fault_cell):
    from dnc.errors import NotFound

    with pytest.raises(ValueError):
        fault_cell.inject("m1", {"type": "no_such_fault", "target": "X"})
    with pytest.raises(ValueError):
        fault_cell.inject("m1", {"type": "encoder_break", "target": "Q"})  # m1 has no Q axis
    with pytest.raises(NotFound, match="unknown machine 'm9'"):
        fault_cell.inject("m9", {"type": "encoder_break", "target": "X"})
    with pytest.raises(NotFound, match="unknown machine 'm9'"):
        fault_cell.machine_faults("m9")
    assert fault_cell.face.seen == []


def test_clearing_a_fault_that_is_not_there_or_on_another_machine(fault_cell):
    from dnc.errors import NotFound

    fault_cell.inject("m1", {"type": "encoder_break", "target": "X"})
    with pytest.raises(NotFound, match=r"^no fault 7 on machine 'm1'$"):
        fault_cell.clear("m1", 7)
    with pytest.raises(NotFound, match=r"^no fault 1 on machine 'm2'$"):
        fault_cell.clear("m2", 1)


def test_a_fault_with_a_duration_clears_itself(fault_cell):
    fault = fault_cell.inject("m1", {"type": "encoder_break", "target": "X", "duration": 0.05})
    # the cell's own timer (wall clock): generous deadline for a loaded box
    deadline = time.monotonic() + 60.0
    while fault.state != "cleared" and time.monotonic() < deadline:
        time.sleep(0.01)
    assert fault.state == "cleared"
    assert fault_cell.face.seen == ["FAULT drive:X:encoder_break", "CLEAR drive:X:encoder_break@0"]


def test_stopping_the_cell_cancels_pending_fault_timers(fault_cell):
    fault = fault_cell.inject("m1", {"type": "encoder_break", "target": "X", "duration": 3600})
    fault_cell.stop()
    assert fault_cell._timers == {}
    assert fault.state == "active" and fault_cell.started is False


def test_cleared_faults_and_their_timers_are_not_kept_for_ever(fault_cell, monkeypatch):
    """A long-running host injecting and clearing faults keeps the active ones, the last
    CLEARED_FAULTS_KEPT cleared per machine (the API's history) and no timer of a cleared one."""
    monkeypatch.setattr("server.cell.CLEARED_FAULTS_KEPT", 3, raising=False)
    ids = []
    for _ in range(8):
        fault = fault_cell.inject("m1", {"type": "encoder_break", "target": "X", "duration": 3600})
        fault_cell.clear("m1", fault.id)
        ids.append(fault.id)
    still = fault_cell.inject("m1", {"type": "encoder_break", "target": "X", "duration": 3600})
    assert [f.id for f in fault_cell.machine_faults("m1")] == [*ids[-3:], still.id]
    assert list(fault_cell._timers) == [still.id]  # the cleared ones' timers are gone
    with pytest.raises(NotFound, match=f"no fault {ids[0]} on machine 'm1'"):
        fault_cell.clear("m1", ids[0])  # forgotten: as if it had never been


class _Monitor:
    """The host's status view of m1 as SHDR brings it (mode as MTConnect names it)."""

    def __init__(self, mode: str) -> None:
        self.mode = mode

    def status(self, name: str) -> dict:
        return {"mode": self.mode}


def test_home_goes_ref_home_all_auto_and_answers_once_the_host_sees_auto(cell):
    cell.monitor = _Monitor("AUTOMATIC")
    assert cell.command("m1", "home") == (
        "homed on the Modbus remote panel: mode REF, home all in the homing sequence,"
        " every axis referenced, AUTO"
    )
    assert cell.panel.requests == [("mode", 4), ("home_all",), ("mode", 1)]


def test_home_refused_while_a_program_is_active_or_ending_short(cell):
    cell.monitor = _Monitor("AUTOMATIC")
    cell.panel.in_cycle = True
    with pytest.raises(MachineUnavailable, match=r"^m1: home refused: a program is active$"):
        cell.command("m1", "home")
    cell.panel.in_cycle, cell.panel.homing = False, "partial"
    with pytest.raises(MachineUnavailable, match=r"^m1: homing ended with only X referenced"):
        cell.command("m1", "home")
    assert ("mode", 1) not in cell.panel.requests  # not put back in AUTO unreferenced


def test_a_machine_process_secret_is_kept_owner_only_for_the_next_host(tmp_path):
    cell = Cell(default_cell(free_ports=True), processes=True, state_dir=tmp_path)
    mcfg = cell.config.machines["mill1"]
    made = cell._secret("mill1", mcfg, persist=True)
    kept = tmp_path / "mill1.machine.secret"
    assert len(made) >= 16 and kept.read_text() == made + "\n"
    assert kept.stat().st_mode & 0o777 == 0o600
    assert cell._secret("mill1", mcfg, persist=True) == made  # the adopting host's
    kept.write_text("short\n")  # not a secret this host made: a new one replaces it
    again = cell._secret("mill1", mcfg, persist=True)
    assert again not in (made, "short") and kept.read_text() == again + "\n"
    fresh = cell._secret("mill1", mcfg, persist=False)
    assert fresh not in (made, again) and kept.read_text() == again + "\n"


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
