"""The cell's machines and the host's links to them, through their faces only.

A `MachineLink` is what the host knows of one machine: its name, kind and face addresses,
plus the few operator actions that have no face yet (`operator`, in-process machines only).
Machines run in this process (`InProcessMachine`: a `cnc.machine.Machine` stepped by a
`RealtimeRunner` on its own thread) or as `fmscell machine` subprocesses
(`SubprocessMachine`); the host talks to both through the same faces: Modbus remote panel,
DNC port, SHDR status, simulation face.
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

from server.clock import FAST_SPEED


class MachineUnavailable(RuntimeError):
    """A face of the machine cannot be reached or refused the request (text says which)."""


@dataclass
class MachineLink:
    name: str
    kind: str
    host: str
    ports: dict[str, int | None]
    axes: tuple[str, ...]
    memory_bytes: int
    local: object | None = field(default=None, repr=False)  # the Machine, in-process only

    def address(self, face: str) -> str:
        port = self.ports.get(face)
        return f"{self.host}:{port}" if port else ""

    # ------------------------------------------------------------------ Modbus remote panel
    def panel(self, action: str, value: int | None = None) -> None:
        """One remote-panel request over a fresh Modbus/TCP connection."""
        from pymodbus.client import ModbusTcpClient

        from plc.remote_panel import RemotePanel, RemotePanelError

        port = self.ports.get("modbus")
        if not port:
            raise MachineUnavailable(f"{self.name} has no Modbus face")
        client = ModbusTcpClient(self.host, port=port, timeout=3, retries=1)
        try:
            if not client.connect():
                raise MachineUnavailable(
                    f"{self.name}: Modbus face {self.host}:{port} not reachable"
                )
            panel = RemotePanel(client)
            fn = getattr(panel, action)
            try:
                fn() if value is None else fn(value)
            except RemotePanelError as exc:
                raise MachineUnavailable(f"{self.name}: {exc}") from None
        finally:
            client.close()

    def panel_status(self) -> dict:
        from pymodbus.client import ModbusTcpClient

        from plc.remote_panel import RemotePanel

        client = ModbusTcpClient(self.host, port=self.ports["modbus"], timeout=3, retries=1)
        try:
            if not client.connect():
                raise MachineUnavailable(f"{self.name}: Modbus face not reachable")
            return RemotePanel(client).status()
        finally:
            client.close()

    # ------------------------------------------------------------------ simulation face
    def simulation(self, line: str, timeout_s: float = 10.0) -> str:
        """One command on the simulation face; returns the text after `OK`, raises on ERR."""
        port = self.ports.get("simulation")
        if not port:
            raise MachineUnavailable(
                f"{self.name}: the simulation face is off (start the cell with --faults)"
            )
        try:
            with socket.create_connection((self.host, port), timeout=timeout_s) as sock:
                sock.sendall(line.encode("ascii") + b"\n")
                answer = sock.makefile("rb").readline().decode("ascii", "replace").strip()
        except OSError as exc:
            raise MachineUnavailable(f"{self.name}: simulation face: {exc}") from None
        if answer.startswith("OK"):
            return answer[2:].strip()
        raise MachineUnavailable(
            f"{self.name}: {answer.removeprefix('ERR').strip() or 'no answer'}"
        )

    # ------------------------------------------------------------------ no face yet
    def operator(self, command: str, timeout_s: float = 10.0, **args) -> None:
        """An operator command at the machine's own panel (select program, home).

        The machine has no face for these yet, so only an in-process machine can take them:
        the call is queued onto the machine's thread and its refusal comes back as an error.
        """
        machine = self.local
        if machine is None:
            raise MachineUnavailable(
                f"{self.name}: {command} has no face on a machine in another process"
            )
        done = threading.Event()
        outcome: list[BaseException | None] = [None]

        def run() -> None:
            try:
                machine.command(command, **args)
            except BaseException as exc:  # noqa: BLE001 - handed back to the caller
                outcome[0] = exc
            finally:
                done.set()

        machine.call_soon(run)
        if not done.wait(timeout_s):
            raise MachineUnavailable(f"{self.name}: {command} not taken within {timeout_s} s")
        if outcome[0] is not None:
            raise MachineUnavailable(f"{self.name}: {outcome[0]}")


def power_on(machine, *, home: bool = True, max_s: float = 60.0) -> None:
    """The operator's power-on routine at the machine: reference every axis, then AUTO.

    Runs in lockstep on the machine before its runner starts (no face carries a home
    command yet)."""
    if home:
        machine.command("mode", mode="REF")
        end = machine.t + max_s
        while True:  # the drives come up over the first PLC scans: home once enabled
            try:
                machine.command("home")
                break
            except Exception:
                if machine.t >= end:
                    raise
                machine.step(machine.plc_every)
        if not machine.run_until(lambda m: all(m.controller.referenced.values()), max_s):
            raise MachineUnavailable(f"{machine.name}: homing did not finish in {max_s} s")
    machine.command("mode", mode="AUTO")
    machine.step(machine.plc_every)


class InProcessMachine:
    """One machine in this process: faces up, powered on, stepped by a runner thread."""

    def __init__(
        self, name: str, config, *, fast: bool, simulation: bool, ideal: bool = False
    ) -> None:
        from cnc.machine import Machine, RealtimeRunner

        self.machine = Machine(config, name, ideal=ideal)
        self.runner = RealtimeRunner(self.machine, speed=FAST_SPEED if fast else 1.0)
        self.ready = threading.Event()
        self.error: BaseException | None = None
        faces = self.machine.start_faces(simulation=simulation)
        self.link = MachineLink(
            name,
            config.kind,
            config.ports.host,
            faces.ports(),
            tuple(config.axes),
            config.program_memory_bytes,
            local=self.machine,
        )
        self.thread = threading.Thread(target=self._run, name=f"machine-{name}", daemon=True)

    def start(self) -> InProcessMachine:
        self.thread.start()
        return self

    def _run(self) -> None:
        try:
            power_on(self.machine)
        except BaseException as exc:  # noqa: BLE001 - reported by wait_ready
            self.error = exc
            self.ready.set()
            return
        self.ready.set()
        self.runner.run()

    def wait_ready(self, timeout_s: float) -> None:
        if not self.ready.wait(timeout_s):
            raise MachineUnavailable(f"{self.link.name}: not powered on in {timeout_s} s")
        if self.error is not None:
            raise MachineUnavailable(f"{self.link.name}: power-on failed: {self.error}")

    def stop(self) -> None:
        self.runner.stop()
        self.thread.join(10)
        self.machine.close()


class SubprocessMachine:
    """One machine as `fmscell machine --config FILE --name NAME` in its own process.

    The process prints its bound ports as one JSON line; fixed ports in the configuration
    let a restarted host find machines that kept running."""

    def __init__(
        self, name: str, config_file: Path, *, fast: bool, simulation: bool, config
    ) -> None:
        self.name = name
        cmd = [
            sys.executable,
            "-m",
            "server.cli",
            "machine",
            "--config",
            str(config_file),
            "--name",
            name,
            "--speed",
            "100" if fast else "1",
        ]
        if simulation:
            cmd.append("--simulation")
        self.proc = subprocess.Popen(
            cmd,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
        )
        line = self.proc.stdout.readline()
        if not line:
            err = self.proc.stderr.read()
            raise MachineUnavailable(f"{name}: machine process ended: {err.strip()}")
        ports = json.loads(line)["ports"]
        self.link = MachineLink(
            name,
            config.kind,
            config.ports.host,
            ports,
            tuple(config.axes),
            config.program_memory_bytes,
        )

    def stop(self, timeout_s: float = 10.0) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
        for stream in (self.proc.stdout, self.proc.stderr):
            with contextlib.suppress(Exception):
                stream.close()


def wait_for(predicate, timeout_s: float, what: str, poll_s: float = 0.02):
    """Poll `predicate` until it returns a truthy value; MachineUnavailable after timeout."""
    end = time.monotonic() + timeout_s
    while True:
        got = predicate()
        if got:
            return got
        if time.monotonic() >= end:
            raise MachineUnavailable(f"{what} not seen within {timeout_s} s")
        time.sleep(poll_s)
