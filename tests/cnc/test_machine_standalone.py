"""`fmscell machine`: one machine in its own process, faces up, stopped by SIGTERM."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import textwrap

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
