"""`fmscell machine`: one machine in its own process, faces up, stopped by SIGTERM."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import textwrap

import pytest

from cnc.cli_machine import opcua_exposure
from cnc.config import PortsConfig

RUNNER = textwrap.dedent(
    """
    import typer
    from cnc.cli_machine import machine
    app = typer.Typer()
    app.command()(machine)
    app()
    """
)


def test_standalone_machine_serves_its_faces_and_stops_on_sigterm(tmp_path):
    cfg = tmp_path / "cell.yaml"
    cfg.write_text(
        "machines:\n  mill9:\n    base: mill3\n"
        "    ports: {dnc: 0, modbus: 0, shdr: 0, simulation: 0}\n"
    )
    proc = subprocess.Popen(
        [sys.executable, "-c", RUNNER, "--config", str(cfg), "--name", "mill9", "--ideal"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        first = json.loads(proc.stdout.readline())
        assert first["machine"] == "mill9"
        ports = first["ports"]
        assert all(ports[f] > 0 for f in ("dnc", "modbus", "shdr", "simulation"))
        with socket.create_connection(("127.0.0.1", ports["shdr"]), timeout=5) as s:
            assert s.recv(64).startswith(b"* shdrVersion: 2")
        with socket.create_connection(("127.0.0.1", ports["simulation"]), timeout=5) as s:
            f = s.makefile("rwb")
            f.write(b"STATUS\n")
            f.flush()
            assert f.readline().startswith(b"OK t=")
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    last = json.loads(out.strip().splitlines()[-1])
    assert last["stopped"] is True and last["realtime"]["cycles"] > 0


def test_standalone_machine_serves_opcua_with_the_opcua_option(tmp_path):
    """`fmscell machine --opcua 0`: the ready line names the bound OPC UA port, and a client
    browses the machine there (identification from the machine itself, no host)."""
    import asyncio

    from asyncua import Client, ua

    cfg = tmp_path / "cell.yaml"
    cfg.write_text(
        "machines:\n  mill9:\n    base: mill3\n    ports: {dnc: 0, modbus: 0, shdr: 0}\n"
    )
    proc = subprocess.Popen(
        [
            sys.executable,
            "-c",
            RUNNER,
            "--config",
            str(cfg),
            "--name",
            "mill9",
            "--ideal",
            "--opcua",
            "0",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        ports = json.loads(proc.stdout.readline())["ports"]
        assert ports["opcua"] > 0

        async def serial() -> str:
            async with Client(f"opc.tcp://127.0.0.1:{ports['opcua']}", timeout=30) as c:
                ns = await c.get_namespace_index("urn:fmscell:machine:mill9")
                node = c.get_node(ua.NodeId("mill9.Identification.SerialNumber", ns))
                return await node.read_value()

        assert asyncio.run(serial()) == "mill9"
        proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0


def test_standalone_machine_refuses_an_unknown_machine_name(tmp_path):
    cfg = tmp_path / "cell.yaml"
    cfg.write_text("machines:\n  mill9:\n    base: mill3\n")
    proc = subprocess.run(
        [sys.executable, "-c", RUNNER, "--config", str(cfg), "--name", "lathe7"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2
    assert "lathe7" in proc.stderr


def test_standalone_machine_powers_on_writes_its_ready_file_and_takes_panel_requests(tmp_path):
    """`--power-on --ready-file --clock fast`: what a cell host starts. The ready file
    appears once the axes are homed; program select and home all then work over Modbus."""
    import time

    from pymodbus.client import ModbusTcpClient

    from plc.remote_panel import PanelRefused, RemotePanel

    cfg = tmp_path / "cell.yaml"
    cfg.write_text(
        "machines:\n  lathe9:\n    base: lathe2\n    ports: {dnc: 0, modbus: 0, shdr: 0}\n"
    )
    ready = tmp_path / "lathe9.machine.json"
    argv = ["--config", str(cfg), "--name", "lathe9", "--ideal", "--no-simulation"]
    argv += ["--power-on", "--ready-file", str(ready), "--clock", "fast"]
    proc = subprocess.Popen(
        [sys.executable, "-c", RUNNER, *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        end = time.monotonic() + 60
        while not ready.exists():
            assert proc.poll() is None, proc.stderr.read()
            assert time.monotonic() < end, "no ready file within 60 s"
            time.sleep(0.05)
        state = json.loads(ready.read_text())
        assert state["machine"] == "lathe9" and state["pid"] == proc.pid
        assert state["ports"]["simulation"] is None
        client = ModbusTcpClient("127.0.0.1", port=state["ports"]["modbus"], timeout=3)
        assert client.connect()
        panel = RemotePanel(client)
        nc = panel.nc_state()
        assert nc["AllReferenced"] and nc["NcMode"] == 1  # homed, AUTO
        assert panel.referenced() == dict.fromkeys("XYZABC", False) | {"X": True, "Z": True}
        with pytest.raises(PanelRefused, match="not in memory") as refused:
            panel.select_program(4711)
        assert refused.value.code == 1
        panel.request_mode(4)
        while panel.nc_state()["NcMode"] != 4:
            assert time.monotonic() < end
            time.sleep(0.01)
        panel.home_all()
        while (s := panel.nc_state())["HomingActive"] or not s["AllReferenced"]:
            assert time.monotonic() < end
            time.sleep(0.01)
        client.close()
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err


def test_a_bind_address_off_loopback_needs_the_shared_secret(tmp_path):
    """`--bind 10.x.y.z` puts the DNC port and the simulation face within reach of other
    hosts: refused without a shared secret, before any face is bound."""
    cfg = tmp_path / "cell.yaml"
    cfg.write_text(
        "machines:\n  mill9:\n    base: mill3\n    ports: {dnc: 0, modbus: 0, shdr: 0}\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "FMSCELL_MACHINE_SECRET"}
    args = [sys.executable, "-c", RUNNER, "--config", str(cfg), "--name", "mill9", "--ideal"]
    run = subprocess.run(
        [*args, "--bind", "10.77.0.2"], capture_output=True, text=True, timeout=60, env=env
    )
    assert run.returncode == 2, run.stderr
    assert "--bind 10.77.0.2 is reachable from other hosts" in run.stderr
    assert "need a shared secret" in run.stderr and run.stdout == ""


@pytest.mark.parametrize(
    ("host", "opcua", "security", "warns"),
    [
        ("127.0.0.1", 4841, "none", False),  # loopback: the default cell
        ("::1", 4841, "none", False),
        ("10.77.0.2", 4841, "none", True),  # reachable, anonymous and unencrypted
        ("0.0.0.0", 4841, "none", True),
        ("mill9.plant", 4841, "none", True),  # a host name: assumed reachable
        ("10.77.0.2", 4841, "Basic256Sha256", False),
        ("10.77.0.2", None, "none", False),  # no OPC UA server
    ],
)
def test_an_opcua_server_off_loopback_without_security_warns(host, opcua, security, warns):
    """As the DNC port without a secret does (cnc/cli_machine.py): `fmscell machine` says
    so on stderr when the OPC UA server is reachable from other hosts unsecured."""
    ports = PortsConfig(host=host, opcua=opcua, opcua_security=security)
    warning = opcua_exposure("mill9", ports)
    assert (warning is not None) == warns, warning
    if warns:
        assert f"listens on {host} with opcua_security: none" in warning
        assert "Basic256Sha256" in warning
