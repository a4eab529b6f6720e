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
    def operator(self, command: str, timeout_s: float = 30.0, **args) -> None:
        """An operator command at the machine's own panel (select program, home, mode).

        The machine's standard faces carry no program select or homing, so the cell gives
        each machine a small operator face (`OperatorFace`, loopback, one line per command)
        that queues the command onto the machine's thread and answers with its outcome."""
        port = self.ports.get("operator")
        if not port:
            raise MachineUnavailable(f"{self.name}: no operator face for {command}")
        words = [command.upper(), *(str(v) for v in args.values())]
        try:
            with socket.create_connection((self.host, port), timeout=timeout_s) as sock:
                sock.sendall(" ".join(words).encode("ascii") + b"\n")
                answer = sock.makefile("rb").readline().decode("ascii", "replace").strip()
        except OSError as exc:
            raise MachineUnavailable(f"{self.name}: operator face: {exc}") from None
        if not answer.startswith("OK"):
            raise MachineUnavailable(
                f"{self.name}: {answer.removeprefix('ERR').strip() or 'no answer'}"
            )


class OperatorFace:
    """The machine operator's panel keys the standard faces lack, on a loopback TCP port:

        SELECT_PROGRAM <n> | HOME | MODE <AUTO|MDI|JOG|REF> | PING   ->  OK ... | ERR <reason>

    Each command runs on the machine's thread (`call_soon`) and is answered once taken."""

    def __init__(self, machine, host: str = "127.0.0.1", port: int = 0) -> None:
        import socketserver

        face = self

        class Handler(socketserver.StreamRequestHandler):
            def handle(self) -> None:
                line = self.rfile.readline(256).decode("ascii", "replace").strip()
                self.wfile.write((face.answer(line) + "\n").encode("ascii", "replace"))

        socketserver.ThreadingTCPServer.allow_reuse_address = True
        self.machine = machine
        self.server = socketserver.ThreadingTCPServer((host, port), Handler)
        self.server.daemon_threads = True
        self.port = self.server.server_address[1]
        self._thread = threading.Thread(
            target=self.server.serve_forever, name=f"operator-{machine.name}", daemon=True
        )

    def start(self) -> OperatorFace:
        self._thread.start()
        return self

    def answer(self, line: str) -> str:
        words = line.split()
        if not words:
            return "ERR empty command"
        word, rest = words[0].upper(), words[1:]
        try:
            if word == "PING":
                return f"OK {self.machine.name}"
            if word == "SELECT_PROGRAM" and len(rest) == 1 and rest[0].isdigit():
                args = {"number": int(rest[0])}
                name = "select_program"
            elif word == "HOME" and not rest:
                name, args = "home", {}
            elif word == "MODE" and len(rest) == 1:
                name, args = "mode", {"mode": rest[0].upper()}
            else:
                return f"ERR unknown or malformed command {line[:60]!r}"
        except ValueError as exc:
            return f"ERR {exc}"
        done = threading.Event()
        outcome: list[BaseException | None] = [None]

        def run() -> None:
            try:
                self.machine.command(name, **args)
            except BaseException as exc:  # noqa: BLE001 - answered to the client
                outcome[0] = exc
            finally:
                done.set()

        self.machine.call_soon(run)
        if not done.wait(20):
            return f"ERR {name} not taken within 20 s"
        if outcome[0] is not None:
            return f"ERR {outcome[0]}"
        if name == "home" and not self._referenced(timeout_s=60.0):
            return "ERR homing did not finish within 60 s"
        return f"OK {name}"

    def _referenced(self, timeout_s: float) -> bool:
        """HOME answers once every axis is referenced, so the caller can go on to AUTO."""
        end = time.monotonic() + timeout_s
        ctl = self.machine.controller
        while time.monotonic() < end:
            if all(ctl.referenced.values()) and not getattr(ctl, "_homing", ""):
                return True
            time.sleep(0.01)
        return False

    def stop(self) -> None:
        self.server.shutdown()
        self.server.server_close()


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
        self.operator_face = OperatorFace(self.machine, config.ports.host).start()
        self.link = MachineLink(
            name,
            config.kind,
            config.ports.host,
            {**faces.ports(), "operator": self.operator_face.port},
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
        self.operator_face.stop()
        self.machine.close()


class SubprocessMachine:
    """One machine in its own process (`python -m server.supervisor --config FILE --name
    NAME`), or one such process that survived its host and is adopted again.

    The process writes its pid and bound ports to `state_dir/<NAME>.machine.json`; a host
    that starts (or restarts after a crash) first pings the operator face named there and
    adopts a machine that answers, so machines keep running across host restarts."""

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
    ) -> None:
        self.name = name
        self.state_file = Path(state_dir) / f"{name}.machine.json"
        self.proc: subprocess.Popen | None = None
        self.adopted = False
        ports = self._adopt(config.ports.host)
        if ports is None:
            cmd = [sys.executable, "-m", "server.supervisor", "--config", str(config_file)]
            cmd += ["--name", name, "--state", str(self.state_file)]
            cmd += ["--fast"] if fast else []
            cmd += ["--simulation"] if simulation else []
            cmd += ["--ideal"] if ideal else []
            self.state_file.unlink(missing_ok=True)
            log_file = open(Path(state_dir) / f"{name}.machine.log", "ab")  # noqa: SIM115
            self.proc = subprocess.Popen(
                cmd,
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
        )
        return self.link

    def _read_state(self) -> dict | None:
        try:
            return json.loads(self.state_file.read_text())
        except (OSError, ValueError):
            return None

    def _died(self) -> None:
        if self.proc is not None and self.proc.poll() is not None:
            raise MachineUnavailable(
                f"{self.name}: machine process ended (exit {self.proc.returncode}); "
                f"see {self.state_file.with_suffix('.log')}"
            )
        return None

    def _adopt(self, host: str) -> dict | None:
        state = self._read_state()
        if not state or not state.get("ports", {}).get("operator"):
            return None
        link = MachineLink(self.name, "", host, state["ports"], (), 0)
        try:
            link_ping(link)
        except MachineUnavailable:
            return None
        self.adopted, self.pid = True, state.get("pid")
        return state["ports"]

    def stop(self, timeout_s: float = 10.0) -> None:
        """Stop the machine process (also one adopted from an earlier host)."""
        import signal

        pid = self.proc.pid if self.proc is not None else getattr(self, "pid", None)
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


def link_ping(link: MachineLink) -> None:
    port = link.ports["operator"]
    try:
        with socket.create_connection((link.host, port), timeout=2) as sock:
            sock.sendall(b"PING\n")
            answer = sock.makefile("rb").readline().decode("ascii", "replace")
    except OSError as exc:
        raise MachineUnavailable(f"{link.name}: {exc}") from None
    if answer.strip() != f"OK {link.name}":
        raise MachineUnavailable(f"{link.name}: operator face answered {answer.strip()!r}")


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except OSError:
        return False
    return True


def machine_main(argv: list[str] | None = None) -> int:
    """One machine process for a cell: faces, operator face, power-on, runner until
    SIGTERM/SIGINT; its pid and ports go to `--state` once it is ready."""
    import argparse
    import signal

    from cnc.config import load_machine_config
    from cnc.machine import Machine, RealtimeRunner

    ap = argparse.ArgumentParser(prog="python -m server.supervisor")
    ap.add_argument("--config", required=True)
    ap.add_argument("--name", required=True)
    ap.add_argument("--state", required=True)
    ap.add_argument("--fast", action="store_true")
    ap.add_argument("--simulation", action="store_true")
    ap.add_argument("--ideal", action="store_true")
    args = ap.parse_args(argv)
    cfg = load_machine_config(args.config, args.name)
    machine = Machine(cfg, args.name, ideal=args.ideal)
    faces = machine.start_faces(simulation=bool(args.simulation))
    operator = OperatorFace(machine, cfg.ports.host).start()
    runner = RealtimeRunner(machine, speed=FAST_SPEED if args.fast else 1.0)
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: runner.stop())
    power_on(machine)
    governor = None
    if args.fast:
        from server.clock import FastClockGovernor

        governor = FastClockGovernor([runner]).start()
    state = {"pid": os.getpid(), "ports": {**faces.ports(), "operator": operator.port}}
    tmp = Path(args.state + ".tmp")
    tmp.write_text(json.dumps(state))
    tmp.replace(args.state)  # atomic: the host never reads half a file
    try:
        runner.run()
    finally:
        if governor is not None:
            governor.stop()
        operator.stop()
        machine.close()
    return 0


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


if __name__ == "__main__":
    raise SystemExit(machine_main())
