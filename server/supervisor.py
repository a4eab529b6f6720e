"""The cell's machines and the host's links to them, through their faces only.

A `MachineLink` is what the host knows of one machine: its name, kind and face addresses,
and the operator actions it does through them: remote panel requests (cycle start, feed
hold, reset, mode, program select, home all) on the Modbus face, fault injection and the
E-stop button on the simulation face. Machines run in this process (`InProcessMachine`: a
`cnc.machine.Machine` stepped by a `RealtimeRunner` on its own thread) or as `fmscell
machine` subprocesses (`SubprocessMachine`); the host talks to both through the same faces.
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

from dnc.cell import MachineUnavailable  # re-exported: the faces' refusals, the cell's error

MODE_NUMBERS = {"AUTO": 1, "MDI": 2, "JOG": 3, "REF": 4}
# `fmscell machine` takes its faces' shared secret from here when its config has none
SECRET_ENV = "FMSCELL_MACHINE_SECRET"


@dataclass
class MachineLink:
    name: str
    kind: str
    host: str
    ports: dict[str, int | None]
    axes: tuple[str, ...]
    memory_bytes: int
    local: object | None = field(default=None, repr=False)  # the Machine, in-process only
    # shared secret of the DNC port and simulation face (`AUTH <secret>` first), None = none
    secret: str | None = field(default=None, repr=False)

    def address(self, face: str) -> str:
        port = self.ports.get(face)
        return f"{self.host}:{port}" if port else ""

    # ------------------------------------------------------------------ Modbus remote panel
    @contextlib.contextmanager
    def remote_panel(self, timeout_s: float = 3.0):
        """A `plc.remote_panel.RemotePanel` on a fresh Modbus/TCP connection; a Modbus
        failure or a refusal comes out as MachineUnavailable naming the machine."""
        from pymodbus.client import ModbusTcpClient
        from pymodbus.exceptions import ModbusException

        # deferred: with pymodbus; `fmscell --help` loads this module (server.factory)
        from plc.remote_panel import PanelRefused, RemotePanel, RemotePanelError

        port = self.ports.get("modbus")
        if not port:
            raise MachineUnavailable(f"{self.name} has no Modbus face")
        client = ModbusTcpClient(self.host, port=port, timeout=timeout_s, retries=1)
        try:
            if not client.connect():
                raise MachineUnavailable(
                    f"{self.name}: Modbus face {self.host}:{port} not reachable"
                )
            yield RemotePanel(client)
        except (RemotePanelError, PanelRefused, ModbusException) as exc:
            raise MachineUnavailable(f"{self.name}: {exc}") from None
        finally:
            client.close()

    def panel(self, action: str, value: int | None = None) -> None:
        """One remote-panel request (`cycle_start`, `feed_hold`, `reset`, overrides...)."""
        with self.remote_panel() as panel:
            fn = getattr(panel, action)
            fn() if value is None else fn(value)

    def panel_status(self) -> dict:
        with self.remote_panel() as panel:
            return panel.status()

    def ping(self) -> bool:
        """The machine's PLC answers on its Modbus face and runs its program."""
        try:
            with self.remote_panel(timeout_s=2.0) as panel:
                return bool(panel.status()["PlcReady"])
        except (MachineUnavailable, OSError):
            return False

    def select_program(self, number: int, timeout_s: float = 20.0) -> None:
        """Program select on the remote panel (O number + strobe, through the PLC to the
        NC); returns once the NC selected it, MachineUnavailable says why not."""
        with self.remote_panel() as panel:
            if panel.nc_state()["NcInCycle"]:
                raise MachineUnavailable(
                    f"{self.name}: program select O{number:04d} refused: a program is active"
                )
            panel.select_program(number, timeout_s=timeout_s)

    def mode(self, mode: str, timeout_s: float = 20.0) -> None:
        """Mode request on the remote panel; returns once the NC reports the mode."""
        with self.remote_panel() as panel:
            self._mode(panel, mode, timeout_s)

    def _mode(self, panel, mode: str, timeout_s: float) -> None:
        if mode not in MODE_NUMBERS:
            raise MachineUnavailable(f"mode {mode!r}: one of {', '.join(MODE_NUMBERS)}")
        want = MODE_NUMBERS[mode]
        state = panel.nc_state()
        if state["NcMode"] == want:
            return
        if state["NcInCycle"]:
            raise MachineUnavailable(f"{self.name}: mode {mode} refused: a program is active")
        if panel.status()["ModeSelect"] == want:
            # the NC takes ModeSelect on a change: request the present mode first
            panel.request_mode(state["NcMode"])
            wait_for(
                lambda: panel.status()["ModeSelect"] == state["NcMode"],
                timeout_s,
                f"{self.name}: PLC taking the mode request",
                poll_s=0.01,
            )
        panel.request_mode(want)
        end = time.monotonic() + timeout_s
        while (state := panel.nc_state())["NcMode"] != want:
            if time.monotonic() > end:
                why = (
                    "refused by the PLC (a program is active)"
                    if panel.status()["ModeRefused"]
                    else "not taken by the NC (homing in progress or a program active)"
                )
                raise MachineUnavailable(
                    f"{self.name}: mode {mode} {why}; the NC is in mode {state['NcMode']}"
                )
            time.sleep(0.01)

    def home(self, timeout_s: float = 120.0) -> None:
        """Home every axis through the remote panel: mode REF, home all (the NC's homing
        sequence), wait until every axis is referenced, mode AUTO."""
        with self.remote_panel() as panel:
            if panel.nc_state()["NcInCycle"]:
                raise MachineUnavailable(f"{self.name}: home refused: a program is active")
            self._mode(panel, "REF", 30.0)
            panel.home_all(timeout_s=30.0)
            end = time.monotonic() + timeout_s
            while (state := panel.nc_state())["HomingActive"] or not state["AllReferenced"]:
                if not state["HomingActive"] and not state["AllReferenced"]:
                    got = [a for a, ok in panel.referenced().items() if ok]
                    raise MachineUnavailable(
                        f"{self.name}: homing ended with only {', '.join(got) or 'no axis'}"
                        " referenced (see the machine's alarms)"
                    )
                if time.monotonic() > end:
                    raise MachineUnavailable(f"{self.name}: homing not done in {timeout_s} s")
                time.sleep(0.01)
            self._mode(panel, "AUTO", 30.0)

    # ------------------------------------------------------------------ simulation face
    def simulation(self, line: str, timeout_s: float = 30.0) -> str:
        """One command on the simulation face; returns the text after `OK`, raises on ERR.

        The face answers once the machine's thread has taken the command (its own limit is
        10 s); the client waits three times that, so a loaded host gets the answer, not a
        socket time-out (seen at load 20: a fault injection refused with 'timed out')."""
        port = self.ports.get("simulation")
        if not port:
            raise MachineUnavailable(
                f"{self.name}: the simulation face is off (start the cell with --faults)"
            )
        try:
            with socket.create_connection((self.host, port), timeout=timeout_s) as sock:
                lines = sock.makefile("rb")
                if self.secret is not None:
                    sock.sendall(f"AUTH {self.secret}\n".encode("ascii"))
                    answer = lines.readline().decode("ascii", "replace").strip()
                    if not answer.startswith("OK"):
                        raise MachineUnavailable(
                            f"{self.name}: simulation face: {answer or 'no answer to AUTH'}"
                        )
                sock.sendall(line.encode("ascii") + b"\n")
                answer = lines.readline().decode("ascii", "replace").strip()
        except OSError as exc:
            raise MachineUnavailable(f"{self.name}: simulation face: {exc}") from None
        if answer.startswith("OK"):
            return answer[2:].strip()
        raise MachineUnavailable(
            f"{self.name}: {answer.removeprefix('ERR').strip() or 'no answer'}"
        )


class InProcessMachine:
    """One machine in this process: faces up, powered on, stepped by a runner thread."""

    def __init__(
        self,
        name: str,
        config,
        *,
        fast: bool,
        simulation: bool,
        ideal: bool = False,
        opcua_users=None,
    ) -> None:
        # deferred: the machine (drives, canopen, PLC) loads only in a process that runs one;
        # `fmscell --help` loads this module (server.factory)
        from cnc.machine import Machine, RealtimeRunner
        from cnc.machine.runner import FAST_SPEED, IDLE_SPEED

        self.machine = Machine(config, name, ideal=ideal)
        # the fast clock: full speed while cutting, a slow tick while idle (see runner.py)
        if fast:
            self.runner = RealtimeRunner(self.machine, speed=FAST_SPEED, idle_speed=IDLE_SPEED)
        else:
            self.runner = RealtimeRunner(self.machine)
        self.ready = threading.Event()
        self.error: BaseException | None = None
        faces = self.machine.start_faces(simulation=simulation, opcua_users=opcua_users)
        self.link = MachineLink(
            name,
            config.kind,
            config.ports.host,
            faces.ports(),
            tuple(config.axes),
            config.program_memory_bytes,
            local=self.machine,
            secret=config.ports.secret,
        )
        self.thread = threading.Thread(target=self._run, name=f"machine-{name}", daemon=True)

    def start(self) -> InProcessMachine:
        self.thread.start()
        return self

    def _run(self) -> None:
        try:
            # the operator's power-on routine at the machine, in lockstep: home, AUTO
            self.machine.power_on()
        except BaseException as exc:  # noqa: BLE001 - reported by wait_ready
            self.error = exc
            self.ready.set()
            return
        self.runner.prepare()  # setup's collection before the first cycle (runner.py)
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


def machine_command(
    config_file: Path,
    name: str,
    *,
    ready_file: Path,
    fast: bool,
    simulation: bool,
    ideal: bool = False,
) -> list[str]:
    """The `fmscell machine` command line of one cell machine process (this interpreter,
    `python -m server.cli`, so it runs from the same environment as the host)."""
    cmd = [sys.executable, "-m", "server.cli", "machine", "--config", str(config_file)]
    cmd += ["--name", name, "--ready-file", str(ready_file), "--power-on"]
    cmd += ["--clock", "fast"] if fast else []
    cmd += ["--simulation"] if simulation else ["--no-simulation"]
    cmd += ["--ideal"] if ideal else []
    return cmd


class SubprocessMachine:
    """One machine in its own process (`fmscell machine --config FILE --name NAME
    --ready-file FILE --power-on`), or one such process that survived its host and is
    adopted again.

    The process writes its pid and bound ports to `state_dir/<NAME>.machine.json` once it
    is ready; a host that starts (or restarts after a crash) first checks the machine named
    there (its process alive, its PLC answering on the Modbus face) and adopts it, so
    machines keep running across host restarts."""

    def __init__(
        self,
        name: str,
        config_file: Path,
        *,
        fast: bool,
        simulation: bool,
        config,
        state_dir: Path,
        ideal: bool = False,
        timeout_s: float = 60.0,
        secret: str | None = None,
    ) -> None:
        self.name = name
        self.secret = secret if secret is not None else config.ports.secret
        self.state_file = Path(state_dir) / f"{name}.machine.json"
        self.log_path = Path(state_dir) / f"{name}.machine.log"
        self.proc: subprocess.Popen | None = None
        self.adopted = False
        self.pid: int | None = None
        ports = self._adopt(config.ports.host)
        if ports is None:
            cmd = machine_command(
                config_file,
                name,
                ready_file=self.state_file,
                fast=fast,
                simulation=simulation,
                ideal=ideal,
            )
            self.state_file.unlink(missing_ok=True)
            log_file = open(self.log_path, "ab")  # noqa: SIM115
            env = dict(os.environ)
            env.pop(SECRET_ENV, None)
            if self.secret is not None:
                # in the environment, not on the command line (`ps` shows that to everyone)
                env[SECRET_ENV] = self.secret
            self.proc = subprocess.Popen(
                cmd,
                env=env,
                stdin=subprocess.DEVNULL,
                stdout=log_file,
                stderr=log_file,
                start_new_session=True,  # a host killed by a signal leaves its machines be
            )
            log_file.close()
        self._config, self._ports, self._timeout_s = config, ports, timeout_s
        self.link: MachineLink | None = None

    def wait_ready(self) -> MachineLink:
        """Wait until the process has written its ports (machines power on in parallel)."""
        ports = (
            self._ports
            or wait_for(
                lambda: self._read_state() or self._died(),
                self._timeout_s,
                f"{self.name}: machine process ready",
                poll_s=0.05,
            )["ports"]
        )
        config = self._config
        self.link = MachineLink(
            self.name,
            config.kind,
            config.ports.host,
            ports,
            tuple(config.axes),
            config.program_memory_bytes,
            secret=self.secret,
        )
        return self.link

    def _read_state(self) -> dict | None:
        try:
            state = json.loads(self.state_file.read_text())
        except (OSError, ValueError):
            return None
        return state if isinstance(state, dict) and "ports" in state else None

    def _died(self) -> None:
        if self.proc is not None and self.proc.poll() is not None:
            tail = ""
            with contextlib.suppress(OSError):
                tail = self.log_path.read_text(errors="replace").strip().splitlines()[-1]
            raise MachineUnavailable(
                f"{self.name}: machine process ended (exit {self.proc.returncode}): "
                f"{tail or 'no output'}; see {self.log_path}"
            )
        return None

    def _adopt(self, host: str) -> dict | None:
        """The ports of a machine process left running by an earlier host, if it is alive
        (its pid) and its PLC answers on the Modbus face; None otherwise."""
        state = self._read_state()
        if not state or state.get("machine") != self.name or not state.get("pid"):
            return None
        if not _alive(int(state["pid"])):
            return None
        link = MachineLink(self.name, "", host, state["ports"], (), 0)
        if not link.ping():
            return None
        self.adopted, self.pid = True, int(state["pid"])
        return state["ports"]

    def stop(self, timeout_s: float = 10.0) -> None:
        """Stop the machine process (also one adopted from an earlier host)."""
        import signal

        pid = self.proc.pid if self.proc is not None else self.pid
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
        elif self.proc is None and pid:
            with contextlib.suppress(OSError):
                os.kill(pid, signal.SIGTERM)
            end = time.monotonic() + timeout_s
            while time.monotonic() < end and _alive(pid):
                time.sleep(0.05)
        self.state_file.unlink(missing_ok=True)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except OSError:
        return False
    return True


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
