"""`fmscell machine --config FILE --name NAME`: one machine with its faces, in its own process.

The lead mounts `machine` as a command of the top-level app. The machine runs in realtime
(paced to the wall clock, or the fast clock) until SIGINT or SIGTERM; on start it prints one
JSON line with its name and bound ports so a supervisor (or a cell on another host) can find
its faces, and with `--ready-file` writes the same (with its pid) atomically to a file once it
is ready: a cell host starts its machine processes with it and adopts them again after a
host restart. Everything else (program select, homing, cycle start) reaches the machine
through its faces: DNC port, Modbus remote panel, simulation face.
"""

from __future__ import annotations

import ipaddress
import json
import os
import re
from pathlib import Path

import typer

from cnc.errors import NcError


def machine(
    config: Path | None = typer.Option(None, "--config", help="cell or machine YAML"),
    name: str = typer.Option("mill3", "--name", help="machine name in the cell file"),
    simulation: bool | None = typer.Option(
        None,
        "--simulation/--no-simulation",
        help="simulation face (faults, operator, clock) on or off (default: as configured)",
    ),
    ideal: bool = typer.Option(False, "--ideal", help="ideal axes instead of CANopen drives"),
    opcua: int | None = typer.Option(
        None,
        "--opcua",
        min=0,
        max=65535,
        help="serve OPC UA (OPC 40501 MachineTool) on this port (0 = any free port);"
        " default: as configured (ports.opcua)",
    ),
    bind: str | None = typer.Option(
        None,
        "--bind",
        help="address every face binds to (default: ports.host, 127.0.0.1); an address"
        " other than loopback needs the shared secret (ports.secret or FMSCELL_MACHINE_SECRET)",
    ),
    dnc_parity: bool = typer.Option(False, "--dnc-parity", help="ISO 7-bit even parity"),
    speed: float = typer.Option(1.0, "--speed", help="clock speed factor (1 = real time)"),
    clock: str = typer.Option(
        "realtime",
        "--clock",
        help="realtime (paced at --speed) | fast (as fast as the CPU allows while a program"
        " is active, 4x real time while idle)",
    ),
    power_on: bool = typer.Option(
        False,
        "--power-on",
        help="the operator's power-on routine first: home every axis (homing sequence), AUTO",
    ),
    ready_file: Path | None = typer.Option(
        None, "--ready-file", help="write {machine, pid, ports} here (atomically) once ready"
    ),
    state_dir: Path | None = typer.Option(
        None,
        "--state-dir",
        help="keep the machine data (tools, offsets) here across restarts"
        " (default: the --ready-file's directory, else none)",
    ),
    seconds: float | None = typer.Option(None, "--seconds", help="stop after this wall time"),
    event_log: Path | None = typer.Option(None, "--event-log", help="JSONL event log file"),
    candump: Path | None = typer.Option(None, "--candump", help="CAN frames, candump log"),
) -> None:
    """Run one machine standalone with its faces (DNC, Modbus, SHDR, OPC UA, simulation)
    until SIGINT/SIGTERM."""
    import signal

    # deferred: the configuration and the machine (drives, PLC, faces) are not loaded for
    # the rest of `fmscell`
    from cnc.config import builtin_machine, load_machine_config
    from cnc.machine import Machine, RealtimeRunner
    from cnc.machine.runner import FAST_SPEED, IDLE_SPEED

    try:
        cfg = load_machine_config(config, name) if config else builtin_machine(name)
    except (NcError, ValueError, KeyError, OSError) as err:
        typer.echo(f"{config or name}: {err}", err=True)
        raise typer.Exit(2) from None
    secret = os.environ.get("FMSCELL_MACHINE_SECRET")
    if secret and cfg.ports.secret is None:
        # the cell host that starts this process passes its generated secret this way
        if not re.fullmatch(r"[!-~]{16,128}", secret):
            typer.echo("FMSCELL_MACHINE_SECRET: 16-128 printable characters, no blanks", err=True)
            raise typer.Exit(2)
        cfg = cfg.model_copy(update={"ports": cfg.ports.model_copy(update={"secret": secret})})
    if opcua is not None:
        cfg = cfg.model_copy(update={"ports": cfg.ports.model_copy(update={"opcua": opcua})})
    if bind is not None:
        if not bind.strip():
            typer.echo("--bind: an address (10.77.0.2, ::1, a host name)", err=True)
            raise typer.Exit(2)
        if cfg.ports.secret is None and not _loopback(bind):
            # asked for on the command line to be reached from elsewhere: never open, where a
            # cell file's ports.host only warns (below) for the files written before secrets
            typer.echo(
                f"{name}: --bind {bind} is reachable from other hosts: the DNC port and the"
                " simulation face need a shared secret (ports.secret in the cell file, or"
                " FMSCELL_MACHINE_SECRET in the environment; docs/dnc_port.md)",
                err=True,
            )
            raise typer.Exit(2)
        cfg = cfg.model_copy(update={"ports": cfg.ports.model_copy(update={"host": bind})})
    if cfg.ports.secret is None and not _loopback(cfg.ports.host):
        typer.echo(
            f"{name}: WARNING: the DNC port and simulation face listen on {cfg.ports.host}"
            " without a shared secret: anyone who reaches them can load, delete and punch"
            " programs (and inject faults); set ports.secret (docs/dnc_port.md)",
            err=True,
        )
    warning = opcua_exposure(name, cfg.ports)
    if warning:
        typer.echo(warning, err=True)
    if not 0.01 <= speed <= 100.0:
        typer.echo(f"--speed {speed}: must be 0.01..100", err=True)
        raise typer.Exit(2)
    if clock not in ("realtime", "fast"):
        typer.echo(f"--clock {clock!r}: realtime or fast", err=True)
        raise typer.Exit(2)
    dump = open(candump, "w", encoding="ascii") if candump else None  # noqa: SIM115
    if state_dir is None and ready_file is not None:
        state_dir = ready_file.parent
    try:
        m = Machine(
            cfg,
            name,
            ideal=ideal,
            candump=dump,
            event_log_path=str(event_log) if event_log else None,
            state_dir=str(state_dir) if state_dir else None,
        )
    except NcError as err:  # a damaged machine data file: say which and where
        typer.echo(f"{name}: {err}", err=True)
        raise typer.Exit(2) from None
    try:
        try:
            faces = m.start_faces(simulation=simulation, dnc_parity=dnc_parity)
        except OSError as err:
            typer.echo(f"{name}: cannot bind a face: {err}", err=True)
            raise typer.Exit(2) from None
        if clock == "fast":
            runner = RealtimeRunner(m, speed=FAST_SPEED, idle_speed=IDLE_SPEED)
        else:
            runner = RealtimeRunner(m, speed=speed)
        previous = {
            sig: signal.signal(sig, lambda *_: runner.stop())
            for sig in (signal.SIGINT, signal.SIGTERM)
        }
        if power_on:
            try:
                m.power_on()
            except Exception as err:  # noqa: BLE001 - one clear line, not a traceback
                typer.echo(f"{name}: power-on failed: {err}", err=True)
                raise typer.Exit(1) from None
        # the collection and freeze before the ready line, not in the first cycles: a cell
        # starting its machines one after another keeps the running ones' cycles clear
        runner.prepare()
        ready = {"machine": name, "ports": faces.ports(), "ipo_cycle_ms": cfg.ipo_cycle_ms}
        typer.echo(json.dumps(ready), nl=True)
        if ready_file is not None:
            _write_atomically(ready_file, {**ready, "pid": os.getpid()})
        try:
            summary = runner.run(seconds)
        finally:
            for sig, handler in previous.items():
                signal.signal(sig, handler)
        typer.echo(
            json.dumps({"machine": name, "stopped": True, "t": round(m.t, 3), "realtime": summary})
        )
    finally:
        m.close()
        if dump is not None:
            dump.close()


def _write_atomically(path: Path, data: dict) -> None:
    """A reader never sees half a file: write a sibling, then rename over the target."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(data))
    tmp.replace(path)


def opcua_exposure(name: str, ports) -> str | None:
    """The warning for an OPC UA server reachable from other hosts without security, as
    the DNC port's without a secret; None when it is off, secured or on loopback."""
    if ports.opcua is None or ports.opcua_security != "none" or _loopback(ports.host):
        return None
    return (
        f"{name}: WARNING: the OPC UA server listens on {ports.host} with opcua_security:"
        " none: anyone who reaches it reads and subscribes to the machine anonymously,"
        " unencrypted; set opcua_security: Basic256Sha256 (docs/opcua.md, Security)"
    )


def _loopback(host: str) -> bool:
    """Whether a bind address is reachable from this host only."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False  # a host name: assume it resolves to a reachable interface
