"""Machine data through the machine's DNC port (TOOLS / OFFSETS [PUT]), with real sockets:
read, write, refused in cycle, bad values named by JSON pointer, saved in the state dir."""

from __future__ import annotations

import json
import socket

import pytest

from cnc.config import load_machine_config
from cnc.faces.dnc_port import ALARM_BAD_DATA, ALARM_REFUSED
from cnc.machine import Machine
from dnc.transfer import DncClient, TransferError

LONG = "%\nO0020\nG21 G90 G0 X0 Y0 Z10\nG1 X200 F300\nM30\n%\n"


def config():
    ports = {"dnc": 0, "modbus": None, "shdr": None, "simulation": None}
    return load_machine_config({"base": "mill3", "ports": ports})


@pytest.fixture
def machine(tmp_path):
    m = Machine(config(), "mill1", ideal=True, state_dir=str(tmp_path))
    m.start_faces()
    yield m
    m.close()


def client(m) -> DncClient:
    return DncClient("127.0.0.1", m.faces.ports()["dnc"], timeout_s=5)


def test_read_and_write_tools_and_offsets(machine, tmp_path) -> None:
    with client(machine) as c:
        tools = c.machine_data("tools")
        assert tools["1"]["comment"].startswith("master")
        offsets = c.machine_data("offsets")
        assert offsets["work_offsets"]["G54"] == [-300.0, -200.0, -300.0]
        assert len(offsets["work_offsets"]) == 55
        got = c.machine_data("tools", {"7": {"length": -33.5, "radius": 4.0}})
        assert list(got) == ["7"] and got["7"]["length"] == -33.5
        got = c.machine_data("offsets", {"work_offsets": {"G54.1P48": [1, 2, 3]}})
        assert got["work_offsets"]["G54.1P48"] == [1.0, 2.0, 3.0]
        assert got["work_offsets"]["G54"] == [-300.0, -200.0, -300.0]  # not named: kept
    md = machine.controller.machine_data
    assert md.tools[7].length == -33.5 and md.work_offsets[54] == (1.0, 2.0, 3.0)
    machine.step(machine.plc_every)
    saved = json.loads((tmp_path / "mill1.machine-data.json").read_text())
    assert saved["tools"]["7"]["length"] == -33.5


@pytest.mark.parametrize(
    "what,doc,pointer",
    [
        ("tools", {"1000": {}}, "/1000"),
        ("tools", {"3": {"radius": "big"}}, "/3/radius"),
        ("offsets", {"work_offsets": {"G53": [0, 0, 0]}}, "/work_offsets/G53"),
        ("offsets", {"g92": [0, 0]}, "/g92"),
    ],
)
def test_bad_values_are_refused_with_the_json_pointer(machine, what, doc, pointer) -> None:
    before = machine.controller.machine_data.to_dict()
    with client(machine) as c, pytest.raises(TransferError) as ei:
        c.machine_data(what, doc)
    assert ei.value.alarm == ALARM_BAD_DATA and pointer in ei.value.message
    assert machine.controller.machine_data.to_dict() == before


def test_writes_are_refused_in_cycle(machine) -> None:
    m = machine
    m.step(50)
    m.command("mode", mode="REF")
    m.command("home")
    assert m.run_until(lambda mm: all(mm.controller.referenced.values()), 30)
    m.command("mode", mode="AUTO")
    m.load_program(LONG)
    m.command("select_program", number=20)
    m.command("cycle_start")
    m.step(20)
    assert m.status.execution == "ACTIVE"
    with client(m) as c:
        assert "1" in c.machine_data("tools")  # reading is fine in cycle
        with pytest.raises(TransferError) as ei:
            c.machine_data("tools", {"1": {"length": 0.0}})
    assert ei.value.alarm == ALARM_REFUSED and "ACTIVE" in ei.value.message


def test_a_body_cut_short_or_not_json_is_refused(machine) -> None:
    port = machine.faces.ports()["dnc"]
    with socket.create_connection(("127.0.0.1", port), timeout=5) as s:
        s.sendall(b"TOOLS PUT 5\nnope!")
        reply = s.recv(4096).decode()
        assert reply.startswith(f"ERR {ALARM_BAD_DATA} body is not ASCII JSON")
        s.sendall(b"TOOLS PUT\n")
        assert "needs the body size" in s.recv(4096).decode()


def test_the_hosts_tool_data_is_sent_with_fmscell_dnc(machine, tmp_path) -> None:
    from typer.testing import CliRunner

    from server.cli import app

    runner = CliRunner()
    args = ["--database-url", f"sqlite:///{tmp_path / 'host.db'}"]
    dnc = f"127.0.0.1:{machine.faces.ports()['dnc']}"
    added = runner.invoke(app, ["dnc", "machine", "mill1", "--kind", "mill", "--dnc", dnc, *args])
    assert added.exit_code == 0, added.output
    table = tmp_path / "tools.csv"
    table.write_text("number,length,radius,comment\n12,-22.5,6,12 mm end mill\n")
    res = runner.invoke(app, ["dnc", "tools", "-m", "mill1", "--send", str(table), *args])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout) == {"12": pytest.approx(json.loads(res.stdout)["12"])}
    assert machine.controller.machine_data.tools[12].comment == "12 mm end mill"
    ofs = tmp_path / "ofs.csv"
    ofs.write_text("offset,x,y,z\nG55,-1,-2,-3\n")
    res = runner.invoke(app, ["dnc", "offsets", "-m", "mill1", "--send", str(ofs), *args])
    assert res.exit_code == 0, res.output
    assert machine.controller.machine_data.work_offsets[2] == (-1.0, -2.0, -3.0)
    table.write_text("number,length\n12,x\n")
    res = runner.invoke(app, ["dnc", "tools", "-m", "mill1", "--send", str(table), *args])
    assert res.exit_code == 2 and f"{table}:2:4: length: 'x' is not a number" in res.stderr
    res = runner.invoke(app, ["dnc", "tools", "-m", "mill1", *args])
    assert res.exit_code == 0 and list(json.loads(res.stdout)) == ["12"]
