"""The cell: database, machines, host loops, MTConnect agent and REST API in one composition.

    cell = Cell(default_cell(), clock="fast", database_url="sqlite:///cell.db").start()
    app = cell.app(ApiSettings(insecure_open=True))   # serve with uvicorn
    ...
    cell.stop()

`start()` migrates the database, starts the machines (in this process, or as `fmscell
machine` subprocesses with `processes=True`; either way reached only through their faces),
registers them in the library with their face
addresses, connects the MTConnect agent to their SHDR streams and starts the host loops:
scheduler tick, transfer worker (whose starter presses cycle start on the machine's Modbus
remote panel), remote-request listeners and, when configured, the outbox publisher to MQTT.
`stop()` ends the loops after their current database transaction, then the machines.
See docs/cell.md.
"""

from __future__ import annotations

import contextlib
import logging
import os
import secrets
import sys
import threading
import time
from pathlib import Path
from typing import Any

from cnc.errors import NcError
from cnc.faces.dnc_port import ALARM_BAD_DATA, ALARM_REFUSED
from cnc.machine.faults import DRIVE_ALIASES, PLC_ALIASES, parse_fault_spec
from dnc.cell import CommandRefused, FaultRefused, InvalidFault, InvalidMachineData
from dnc.checker import nc_checker
from dnc.db import make_engine, migrate, session_factory
from dnc.dispatch import Dispatches
from dnc.errors import Conflict, NotFound
from dnc.jobs import Jobs, Scheduler
from dnc.library import Library
from dnc.machine_link import RemoteRequests, client_for
from dnc.outbox import OutboxPublisher
from dnc.transfer import TransferError
from dnc.transfer_worker import RetryPolicy, TransferWorker, _default_client
from mtconnect import Agent
from mtconnect.client import AgentConnections
from plc.machine_io import DETECTION, FAULTS, RECOVERY, RECOVERY_CLASS
from server.config import load_cell_config
from server.cycle_audit import CycleAudit, HostRequests
from server.host import AlarmWatch, Loop, MonitoringModel, make_starter
from server.mqtt import CellFace, mqtt_settings
from server.supervisor import (
    InProcessMachine,
    MachineLink,
    MachineUnavailable,
    SubprocessMachine,
    wait_for,
)
from web_api.app import create_app
from web_api.settings import ApiKey

log = logging.getLogger(__name__)

CLOCKS = ("realtime", "fast")


DEFAULT_PORTS = {
    "mill1": {"dnc": 7001, "modbus": 5021, "shdr": 7878, "opcua": 4841},
    "mill2": {"dnc": 7003, "modbus": 5023, "shdr": 7880, "opcua": 4843},
    "lathe1": {"dnc": 7002, "modbus": 5022, "shdr": 7879, "opcua": 4842},
}


def default_cell(*, free_ports: bool = False, opcua: bool | None = None):
    """The built-in cell of `fmscell run`: two identical 3-axis mills and one lathe, built
    from the shipped machines (mill3 twice, lathe2), faces on fixed loopback ports (so a
    restarted host finds machines that kept running) or, with `free_ports`, on any free
    port (tests). `opcua`: the OPC UA faces on or off; None = on with the fixed ports, off
    with free ports (an OPC UA server takes seconds to start on a loaded box, and most
    tests of the cell do not read it)."""
    if opcua is None:
        opcua = not free_ports
    bases = {"mill1": "mill3", "mill2": "mill3", "lathe1": "lathe2"}
    machines = {}
    for name, base in bases.items():
        ports = dict.fromkeys(DEFAULT_PORTS[name], 0) if free_ports else dict(DEFAULT_PORTS[name])
        if not opcua:
            ports["opcua"] = None
        machines[name] = {"base": base, "ports": {"host": "127.0.0.1", **ports}}
    return load_cell_config({"machines": machines})


#: Cleared faults kept per machine for the API's fault history (`GET .../faults`); older
#: ones are forgotten so a host injecting faults for weeks does not grow without bound.
CLEARED_FAULTS_KEPT = 100


class Fault:
    """One fault injected through the API: its spec on the simulation face and its life."""

    def __init__(self, fault_id: int, machine: str, request: dict, spec: str) -> None:
        self.id, self.machine, self.request, self.spec = fault_id, machine, request, spec
        self.state = "active"
        self.created_at = time.time()
        self.cleared_at: float | None = None
        # the machine's clock when it took the injection / the clear (None: not reported)
        self.machine_t: float | None = None
        self.cleared_machine_t: float | None = None

    def as_dict(self) -> dict:
        return {
            "id": self.id,
            "machine": self.machine,
            **self.request,
            "spec": self.spec,
            "state": self.state,
            "created_at": self.created_at,
            "cleared_at": self.cleared_at,
            "machine_t": self.machine_t,
            "cleared_machine_t": self.cleared_machine_t,
        }


class Cell:
    """One cell: see the module docstring."""

    def __init__(
        self,
        config=None,
        *,
        clock: str = "realtime",
        database_url: str | None = None,
        processes: bool = False,
        faults: bool = False,
        ideal_axes: bool = False,
        config_file: str | Path | None = None,
        tick_s: float | None = None,
        rule: str | None = None,
        state_dir: str | Path | None = None,
        attach: bool = False,
        opcua_users=None,
    ) -> None:
        if clock not in CLOCKS:
            raise ValueError(f"clock {clock!r}: one of {', '.join(CLOCKS)}")
        self.config = config if config is not None else default_cell()
        self.clock = clock
        self.database_url = database_url or self.config.host.database_url
        self.processes = processes
        self.attach = attach
        self.faults_enabled = faults
        self.ideal_axes = ideal_axes
        self.config_file = Path(config_file) if config_file else None
        self.state_dir = Path(state_dir) if state_dir else Path.cwd()
        self.tick_s = tick_s if tick_s is not None else (0.05 if clock == "fast" else 0.5)
        self.rule = rule or self.config.host.dispatch_rule  # None: the cell file's choice
        #: (user, password) -> cell role, for machines with a secured OPC UA face (in-process)
        self.opcua_users = opcua_users
        self.links: dict[str, MachineLink] = {}
        self.machines: list[Any] = []
        self.loops: list[Loop] = []
        self.remote_requests: list[Any] = []
        self.faults: dict[int, Fault] = {}
        self._fault_lock = threading.Lock()
        self._next_fault = 1
        # a duration's timer per active fault id; dropped (cancelled) once the fault clears
        self._timers: dict[int, threading.Timer] = {}
        self.started = False

    # ------------------------------------------------------------------ lifetime
    def start(self, ready_timeout_s: float = 120.0) -> Cell:
        self.engine = make_engine(self.database_url)
        migrate(self.engine)
        self.sessions = session_factory(self.engine)
        # every upload is NC-checked for the machine kind it is for, as `fmscell dnc` does:
        # a program with errors is stored with them and cannot be released; APT/CL
        # revisions are posted with each machine's own configuration (dnc/posting.py)
        self.library = Library(
            self.sessions, checker=nc_checker, machine_configs=self._machine_config
        )
        self.dispatches = Dispatches(self.sessions, machine_configs=self._machine_config)
        self.jobs = Jobs(self.sessions)
        try:
            self._start_machines(ready_timeout_s)
            for link in self.links.values():
                self.library.register_machine(
                    link.name,
                    link.kind,
                    dnc_address=link.address("dnc"),
                    modbus_address=link.address("modbus"),
                    status_address=link.address("shdr"),
                    memory_bytes=link.memory_bytes,
                    axes=link.axes,
                    actor="cell",
                )
            # a buffer that fills for hours is memory growing for hours (host.mtconnect_buffer_size)
            self.agent = Agent.from_cell(
                self.config, buffer_size=self.config.host.mtconnect_buffer_size
            )
            self.connections = AgentConnections(
                self.agent, {n: (lk.host, lk.ports["shdr"]) for n, lk in self.links.items()}
            ).start()
            self.monitor = MonitoringModel(self.agent, self.links)
            self._wait_connected(ready_timeout_s)
            self.scheduler = Scheduler(
                self.sessions,
                self.monitor.views,
                rule=self.rule,
                lost_contact_s=self.config.host.lost_contact_s,
            )
            self.host_requests = HostRequests()
            self.worker = TransferWorker(
                self.sessions,
                client_factory=self._dnc_client,
                starter=self._audited(make_starter(self.links, self.monitor)),
                retry=RetryPolicy(max_attempts=3, base_s=0.5, cap_s=5.0),
                part_counter=lambda name: self.monitor.status(name)["counters"]["part_count"],
                machine_configs=self._machine_config,
            )
            self.worker.recover()
            self.alarm_watch = AlarmWatch(self.sessions, self.monitor)
            self.cycle_audit = CycleAudit(self.sessions, self.monitor, self.host_requests)
            self.loops = [
                Loop("alarm-watch", self.alarm_watch.check, self.tick_s).start(),
                Loop("cycle-audit", self.cycle_audit.check, self.tick_s).start(),
                Loop("scheduler", self.scheduler.tick, self.tick_s).start(),
                Loop("transfer-worker", self.worker.run_once, self.tick_s).start(),
            ]
            self._start_publisher()
            self._start_opcua_feed()
            self._start_remote_requests()
        except BaseException:
            self.stop()
            raise
        self.started = True
        return self

    def _machine_config(self, name: str, kind: str):
        """A cell machine's configuration, for posting APT/CL revisions for it."""
        return self.config.machines.get(name)

    def _audited(self, starter):
        """The transfer worker's starter, announcing its select and cycle start so the
        cycle audit gives them to the host (server/cycle_audit.py)."""

        def start(machine: str, number: int) -> None:
            self.host_requests.expect(machine, f"program_select O{number:04d}", "transfer worker")
            self.host_requests.expect(machine, "cycle_start", "transfer worker")
            starter(machine, number)

        return start

    def _dnc_client(self, host: str, port: int, profile: dict):
        """The transfer worker's DncClient: the registry's profile plus the port's shared
        secret, which stays in the host's memory (the registry's profile is public)."""
        secret = next(
            (lk.secret for lk in self.links.values() if lk.address("dnc") == f"{host}:{port}"),
            None,
        )
        return _default_client(host, port, {**profile, "secret": secret})

    def _secret(self, name: str, mcfg, *, persist: bool) -> str:
        """The shared secret of a machine's DNC port and simulation face: the configured
        `ports.secret`, else one generated for it. A machine process outlives its host, so
        its generated secret is kept (owner-only) in the state directory for the next host
        that adopts it; an in-process machine gets a fresh one each start."""
        if mcfg.ports.secret is not None:
            return mcfg.ports.secret
        if not persist:
            return secrets.token_urlsafe(24)
        path = self.state_dir / f"{name}.machine.secret"
        with contextlib.suppress(OSError):
            kept = path.read_text().strip()
            if len(kept) >= 16:
                return kept
        made = secrets.token_urlsafe(24)
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, "w") as f:
            f.write(made + "\n")
        return made

    def _start_machines(self, timeout_s: float) -> None:
        fast = self.clock == "fast"
        if self.attach:
            # machines run elsewhere (their own services): connect to the configured faces
            for name, mcfg in self.config.machines.items():
                p = mcfg.ports
                ports = {"dnc": p.dnc, "modbus": p.modbus, "shdr": p.shdr, "opcua": p.opcua}
                ports["simulation"] = p.simulation if self.faults_enabled else None
                self.links[name] = MachineLink(
                    name,
                    mcfg.kind,
                    p.host,
                    ports,
                    tuple(mcfg.axes),
                    mcfg.program_memory_bytes,
                    secret=p.secret,
                )
            return
        if self.processes:
            config_file = self._config_file()
            for name, mcfg in self.config.machines.items():
                proc = SubprocessMachine(
                    name,
                    config_file,
                    fast=fast,
                    simulation=self.faults_enabled,
                    config=mcfg,
                    state_dir=self.state_dir,
                    ideal=self.ideal_axes,
                    timeout_s=timeout_s,
                    secret=self._secret(name, mcfg, persist=True),
                )
                self.machines.append(proc)
            for proc in self.machines:
                self.links[proc.name] = proc.wait_ready()
            return
        for name, mcfg in self.config.machines.items():
            secret = self._secret(name, mcfg, persist=False)
            mcfg = mcfg.model_copy(
                update={"ports": mcfg.ports.model_copy(update={"secret": secret})}
            )
            m = InProcessMachine(
                name,
                mcfg,
                fast=fast,
                simulation=self.faults_enabled,
                ideal=self.ideal_axes,
                opcua_users=self.opcua_users,
            )
            self.machines.append(m)
            self.links[name] = m.link
            m.start()
        for m in self.machines:
            m.wait_ready(timeout_s)

    def _config_file(self) -> Path:
        if self.config_file is not None:
            return self.config_file
        import yaml

        machines = {
            n: {"base": _base_of(m), "ports": m.ports.model_dump()}
            for n, m in self.config.machines.items()
        }
        path = self.state_dir / "fmscell-cell.yaml"
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)  # may hold secrets
        with os.fdopen(fd, "w") as f:
            f.write(yaml.safe_dump({"machines": machines}))
        return path

    def _wait_connected(self, timeout_s: float) -> None:
        end = time.monotonic() + timeout_s
        for name in self.links:
            while not self.agent.state[name].connected or self.agent.value(name, "exec") in (
                "UNAVAILABLE",
                "",
            ):
                if time.monotonic() > end:
                    raise MachineUnavailable(f"{name}: no SHDR status within {timeout_s} s")
                time.sleep(0.02)

    def _start_publisher(self) -> None:
        """The MQTT face (`host.mqtt`, or FMSCELL_MQTT=HOST:PORT) and the outbox publisher
        that sends it the events (docs/mqtt.md)."""
        settings = mqtt_settings(self.config.host)
        if settings is None:
            return
        self.mqtt = CellFace(settings, self.monitor).start()
        publisher = OutboxPublisher(self.sessions, self.mqtt.publish_event)
        self.loops.append(Loop("outbox-publisher", publisher.publish_pending, 0.2).start())

    def _start_opcua_feed(self) -> None:
        """The host's knowledge (dispatched revisions, jobs) into the machines' OPC UA
        faces, in this process or through their DNC ports; their clients' method calls
        back into the audit log (server/opcua_feed.py, docs/opcua.md)."""
        if not any(link.ports.get("opcua") for link in self.links.values()):
            return
        # deferred: asyncua (about a second to import) only for a cell with OPC UA faces
        from server.opcua_feed import OpcUaFeed

        def client(name: str):
            return client_for(self.library, name, secret=self.links[name].secret)

        users = getattr(self.opcua_users, "records", None)
        self.opcua_feed = OpcUaFeed(
            self.library, self.dispatches, self.jobs, self.links, client, users=users
        )
        self.loops.append(Loop("opcua-feed", self.opcua_feed.tick, 1.0).start())

    def _start_remote_requests(self) -> None:
        for name, link in self.links.items():

            def client(name=name, secret=link.secret):
                return client_for(self.library, name, secret=secret)

            with contextlib.suppress(Exception):
                self.remote_requests.append(
                    RemoteRequests(self.library, name, client=client).start()
                )

    def stop(self) -> None:
        """Finish the host loops' current writes, then stop machines and connections."""
        with self._fault_lock:
            timers, self._timers = list(self._timers.values()), {}
        for timer in timers:
            timer.cancel()
        for loop in self.loops:
            loop.stop()
        for rr in self.remote_requests:
            with contextlib.suppress(Exception):
                rr.stop(2.0)
        if getattr(self, "connections", None) is not None:
            with contextlib.suppress(Exception):
                self.connections.stop()
        for m in self.machines:
            with contextlib.suppress(Exception):
                m.stop()
        if getattr(self, "mqtt", None) is not None:
            with contextlib.suppress(Exception):
                self.mqtt.stop()
        if getattr(self, "engine", None) is not None:
            self.engine.dispose()
        self.started = False

    # ------------------------------------------------------------------ the API's view
    def app(self, settings):
        """The FastAPI app over this cell (monitoring, commands and, if enabled, faults)."""
        return create_app(
            settings,
            library=self.library,
            dispatches=self.dispatches,
            jobs=self.jobs,
            sessions=self.sessions,
            machines_provider=self.monitor.all,
            opcua_addresses=self.opcua_addresses,
            faults_enabled=self.faults_enabled,
            mtconnect_agent=self.agent,
            cell_control=self,
        )

    def opcua_addresses(self) -> dict[str, str]:
        """Each machine's OPC UA endpoint (machines whose OPC UA face is off are absent)."""
        return {
            name: f"opc.tcp://{link.host}:{link.ports['opcua']}"
            for name, link in self.links.items()
            if link.ports.get("opcua")
        }

    # ------------------------------------------------------------------ commands
    def link(self, name: str) -> MachineLink:
        try:
            return self.links[name]
        except KeyError:
            raise NotFound(f"unknown machine {name!r}") from None

    def command(self, name: str, command: str, **args) -> str:
        """A command to a machine through its faces; returns what was done.

        CommandRefused (refused, or no face carries it) says why not."""
        link = self.link(name)
        try:
            return self._command(link, name, command, **args)
        except CommandRefused:
            raise
        except MachineUnavailable as exc:  # a face refused: the refusal of this command
            raise CommandRefused(str(exc), command=command) from None

    def _command(self, link: MachineLink, name: str, command: str, **args) -> str:
        requests = getattr(self, "host_requests", None)
        if requests is not None and command == "cycle_start":
            requests.expect(name, "cycle_start", "REST machine command")
        if requests is not None and command == "select_program":
            requests.expect(
                name, f"program_select O{int(args['number']):04d}", "REST machine command"
            )
        if command in ("cycle_start", "feed_hold", "reset"):
            link.panel(command)
            return f"{command} pressed on the Modbus remote panel"
        if command == "estop":
            if args.get("release"):
                link.simulation("ESTOP RELEASE")
                return "E-stop button released (simulation face)"
            link.simulation("ESTOP PRESS")
            return "E-stop button pressed (simulation face)"
        if command == "home":
            link.home()  # REF, home all, every axis referenced, AUTO: all on the panel
            # answer once the host's own view (SHDR -> agent) shows it too
            wait_for(
                lambda: self.monitor.status(name)["mode"] == "AUTOMATIC",
                10,
                f"{name}: AUTO after homing seen on the status face",
            )
            return (
                "homed on the Modbus remote panel: mode REF, home all in the homing sequence,"
                " every axis referenced, AUTO"
            )
        if command == "select_program":
            number = int(args["number"])
            link.select_program(number)  # answers once the NC selected it
            return f"program O{number:04d} selected on the Modbus remote panel"
        if command == "mode":
            link.mode(str(args["mode"]).upper())
            return f"mode {args['mode']} taken (Modbus remote panel)"
        raise CommandRefused(f"unknown command {command!r}", command=command)

    # ------------------------------------------------------------------ machine data
    def machine_data(self, name: str, what: str, doc: dict | None = None) -> dict:
        """The machine's tool table (`what` = "tools") or work offsets ("offsets") read
        through its DNC port; with `doc`, replaced first. Conflict: the machine refuses
        (in cycle); InvalidMachineData (a cnc MachineDataError): a bad value (`.pointer`
        into doc); MachineUnavailable: the DNC port cannot be reached."""
        link = self.link(name)  # NotFound for an unknown machine
        try:
            with client_for(self.library, name, secret=link.secret) as client:
                return client.machine_data(what, doc)
        except TransferError as exc:
            text = exc.message.split(": ", 1)[-1]
            if exc.alarm == ALARM_BAD_DATA:
                pointer, _, reason = text.partition(": ")
                raise InvalidMachineData(
                    reason or text, pointer if reason else "", what=what
                ) from None
            if exc.alarm == ALARM_REFUSED:
                raise Conflict(f"{name}: {text}") from None
            raise MachineUnavailable(f"{name}: {exc.message}") from None

    # ------------------------------------------------------------------ faults
    def fault_types(self) -> list[dict]:
        return fault_types()

    def inject(self, name: str, request: dict) -> Fault:
        """Inject a fault through the machine's simulation face (InvalidFault: a bad spec,
        a ValueError; FaultRefused: the machine refused)."""
        link = self.link(name)
        at = request.get("at")
        try:
            spec = fault_spec(request)
            full = f"{spec}@{at}s" if at is not None else spec
            parse_fault_spec(full if at is not None else spec + "@0", link.axes)
        except ValueError as exc:  # the spec parser's refusal, said as the cell's
            raise InvalidFault(str(exc)) from None
        try:
            answer = link.simulation(f"FAULT {full}")
        except MachineUnavailable as exc:
            raise FaultRefused(str(exc)) from None
        with self._fault_lock:
            fault = Fault(self._next_fault, name, dict(request), full)
            fault.machine_t = machine_time(answer)
            self._next_fault += 1
            self.faults[fault.id] = fault
        duration = request.get("duration")
        if duration:
            timer = threading.Timer(float(duration), self._expire, args=(fault.id,))
            timer.daemon = True
            with self._fault_lock:
                self._timers[fault.id] = timer
            timer.start()
        return fault

    def _expire(self, fault_id: int) -> None:
        with contextlib.suppress(Exception):  # KeyError: cleared and forgotten meanwhile
            self.clear(self.faults[fault_id].machine, fault_id)

    def machine_faults(self, name: str) -> list[Fault]:
        self.link(name)
        with self._fault_lock:  # a clear may forget old faults from a timer's thread
            return [f for f in self.faults.values() if f.machine == name]

    def clear(self, name: str, fault_id: int) -> Fault:
        fault = self.faults.get(fault_id)
        if fault is None or fault.machine != name:
            raise NotFound(f"no fault {fault_id} on machine {name!r}")
        if fault.state == "active":
            spec = fault.spec.split("@", 1)[0]
            try:
                answer = self.link(name).simulation(f"CLEAR {spec}@0")
            except MachineUnavailable as exc:
                raise FaultRefused(str(exc)) from None
            fault.state, fault.cleared_at = "cleared", time.time()
            fault.cleared_machine_t = machine_time(answer)
            self._forget_cleared(fault)
        return fault

    def _forget_cleared(self, fault: Fault) -> None:
        """Drop a cleared fault's timer, and the machine's oldest cleared faults beyond
        CLEARED_FAULTS_KEPT (the active ones stay, whatever their age)."""
        with self._fault_lock:
            timer = self._timers.pop(fault.id, None)
            cleared = sorted(
                f.id
                for f in self.faults.values()
                if f.machine == fault.machine and f.state == "cleared"
            )
            for fault_id in cleared[: max(0, len(cleared) - CLEARED_FAULTS_KEPT)]:
                del self.faults[fault_id]
        if timer is not None:
            timer.cancel()  # from the timer's own thread (a duration ran out) a no-op


def fault_spec(request: dict) -> str:
    """The simulation face's spec (without time) for an API fault request.

    `target` is `plc`, `drive:X` (or just `X`), or `bus:X`; `params` become `:k=v,...`."""
    kind = str(request["type"])
    target = str(request.get("target") or "")
    params = request.get("params") or {}
    tail = ":" + ",".join(f"{k}={v}" for k, v in params.items()) if params else ""
    if target.lower() == "plc":
        if params:
            raise ValueError("plc faults take no params")
        return f"plc:{kind}"
    if target.lower().startswith("bus:"):
        return f"bus:{kind}:{target[4:].upper()}{tail}"
    axis = target[6:] if target.lower().startswith("drive:") else target
    if not axis:
        raise ValueError("target must be plc, drive:<AXIS>, <AXIS> or bus:<AXIS>")
    return f"drive:{axis.upper()}:{kind}{tail}"


def _base_of(config) -> str:
    """The shipped machine a cell's machine is rebuilt from (its axes decide: a mill with
    a rotary table A is a mill4)."""
    if config.kind == "lathe":
        return "lathe2"
    if config.kind == "mill5":
        return "mill5"
    return "mill4" if "A" in config.axes else "mill3"


def run_cell(
    *,
    config: Path | None = None,
    clock: str = "realtime",
    processes: bool = False,
    host: str | None = None,
    port: int | None = None,
    insecure_open: bool = False,
    faults: bool = False,
    ideal_axes: bool = False,
    database_url: str | None = None,
    attach: bool = False,
    echo=print,
) -> int:
    """`fmscell run`: start the cell and serve the API until SIGINT/SIGTERM; exit status."""
    import uvicorn

    if clock not in CLOCKS:
        echo(f"--clock {clock!r}: one of {', '.join(CLOCKS)}")
        return 2
    try:
        cfg = load_cell_config(config) if config else default_cell()
        settings = cfg.host.auth.api_settings()
        if insecure_open:
            settings = settings.model_copy(update={"insecure_open": True})
    except (NcError, ValueError, OSError) as err:
        echo(f"{config or 'default cell'}: {err}")
        return 2
    faults = (
        faults or cfg.host.faults or os.environ.get("FMSCELL_FAULTS", "") in ("1", "true", "yes")
    )
    bind = host or cfg.host.bind
    port = cfg.host.port if port is None else port
    tls = _tls_files(cfg.host.tls, config)
    if isinstance(tls, str):
        echo(tls)
        return 2
    refusal, warnings = exposure(bind, port, settings, tls=tls is not None)
    for line in warnings:
        echo(line)
    if refusal:
        echo(refusal)
        return 2
    demo_key = None
    if not settings.api_keys and not settings.insecure_open:
        # loopback without keys (the built-in cell of `make run`): a one-run admin key,
        # printed below, so the API and the README's tour work from the first start
        demo_key = secrets.token_urlsafe(24)
        settings = settings.model_copy(
            update={"api_keys": (ApiKey(user="local-admin", role="admin", key=demo_key),)}
        )
    cell = Cell(
        cfg,
        clock=clock,
        database_url=database_url,
        processes=processes,
        faults=faults,
        ideal_axes=ideal_axes,
        config_file=config,
        attach=attach,
        opcua_users=opcua_users(settings),
    )
    # SIGINT/SIGTERM: uvicorn stops serving, then the cell stops its loops after their
    # current transaction and its machines. uvicorn re-raises the signal once it has shut
    # down; these handlers take it so the process ends through `cell.stop()`, not mid-write.
    import signal

    stop_requested: list[int] = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda signum, _frame: stop_requested.append(signum))
    try:
        cell.start()
    except Exception as err:  # noqa: BLE001 - one clear line, not a traceback
        echo(f"cannot start the cell: {err}")
        return 1
    try:
        if stop_requested:
            return 0
        import threading

        app = cell.app(settings)
        hub = app.state.event_hub

        class CellServer(uvicorn.Server):
            # uvicorn waits for open responses before it runs the app's shutdown, and an
            # event stream (a watching dashboard) never ends by itself: on SIGINT/SIGTERM
            # the hub is closed first, which ends every stream; the graceful timeout bounds
            # whatever else is still open.
            def handle_exit(self, sig, frame) -> None:
                super().handle_exit(sig, frame)
                # Not here: a signal handler runs between two bytecodes of the main thread,
                # which may be inside the hub's (non-reentrant) lock just then.
                threading.Thread(target=hub.close, kwargs={"wait": False}, daemon=True).start()

            async def startup(self, sockets=None) -> None:
                await super().startup(sockets)
                # The banner (and the run's key) only once the API answers: a script that
                # reads the key and connects at once must not meet a refused connection.
                if self.started:
                    for line in announcement:
                        echo(line)
                    sys.stdout.flush()  # a log file or a pipe reads it now, not at exit

        server = CellServer(
            uvicorn.Config(
                app,
                host=bind,
                port=port,
                log_level="warning",
                timeout_graceful_shutdown=10,
                ssl_certfile=tls[0] if tls else None,
                ssl_keyfile=tls[1] if tls else None,
            )
        )
        url = f"{'https' if tls else 'http'}://{bind}:{port}"
        announcement = banner(tuple(cell.links), clock, url, cell.opcua_addresses())
        if settings.insecure_open:
            announcement.append(
                "WARNING: --insecure-open: no API key needed, every caller is an admin"
            )
        if demo_key is not None:
            announcement += [
                "no API keys configured (host.auth.api_keys): this run's admin key is",
                f"export KEY={demo_key}",
            ]
        server.run()
    finally:
        cell.stop()
        echo("fmscell cell stopped")
    return 0


def banner(machines: tuple[str, ...], clock: str, url: str, opcua: dict[str, str]) -> list[str]:
    """What `fmscell run` prints once the cell is up: where to reach it, the API's and
    each machine's OPC UA endpoint (machines whose OPC UA face is off have none)."""
    lines = [
        f"fmscell cell: {', '.join(machines)} ({clock} clock)",
        f"dashboard:      {url}/",
        f"API reference:  {url}/docs  (OpenAPI: {url}/openapi.json)",
        f"MTConnect:      {url}/mtconnect/probe",
    ]
    lines += [f"OPC UA {name}:".ljust(16) + opcua[name] for name in machines if name in opcua]
    return lines


def exposure(bind: str, port: int, settings, *, tls: bool) -> tuple[str | None, list[str]]:
    """What serving the API on `bind` means: (the reason to refuse, or None; warnings).

    Off loopback the API needs keys: without any, `fmscell run` refuses unless the
    insecure-open demo mode is asked for, which it then announces loudly."""
    if is_loopback(bind):
        return None, []
    if settings.insecure_open:
        return None, [
            f"WARNING: --insecure-open on {bind}, which is not loopback: ANYONE who can reach"
            f" port {port} is an admin (uploads, dispatches, machine commands, faults)."
            " Demo networks only."
        ]
    if not settings.api_keys:
        return (
            f"refusing to serve on {bind}: it is not loopback and the cell has no API keys."
            " Add keys under host.auth.api_keys in the cell file (docs/api.md), bind to"
            " 127.0.0.1, or pass --insecure-open for a demo network (no authentication).",
            [],
        )
    return None, [
        f"WARNING: serving on {bind}, which is not loopback: reachable from other hosts"
        + ("" if tls else "; without host.tls, API keys cross the network in clear")
    ]


def is_loopback(bind: str) -> bool:
    """Whether a bind address is reachable from this host only (`0.0.0.0`, `::`, an
    interface's address or a host name are not)."""
    import ipaddress

    if bind == "localhost":
        return True
    try:
        return ipaddress.ip_address(bind).is_loopback
    except ValueError:
        return False


def _tls_files(tls, config: Path | None) -> tuple[str, str] | str | None:
    """(cert, key) paths of `host.tls` (relative ones from the cell file's folder), None
    without TLS, or the message saying which file is missing."""
    if tls is None:
        return None
    base = Path(config).resolve().parent if config else Path.cwd()
    paths = []
    for key in ("cert", "key"):
        path = Path(getattr(tls, key)).expanduser()
        path = path if path.is_absolute() else base / path
        if not path.is_file():
            return f"host.tls.{key}: no such file {path}"
        paths.append(str(path))
    import ssl

    try:  # a bad pair is refused now, not after the machines have started
        ssl.create_default_context(ssl.Purpose.CLIENT_AUTH).load_cert_chain(paths[0], paths[1])
    except (ssl.SSLError, OSError) as err:
        return f"host.tls: cannot load {paths[0]} with {paths[1]}: {err}"
    return paths[0], paths[1]


class OpcUaUsers:
    """The OPC UA users of the cell, from the API keys: user name = the key's `user`,
    password = the key; the session gets the key's role (docs/opcua.md). A machine in this
    process asks by call; one in its own process gets `records()` (digests, never keys)
    with the host's data over its DNC port."""

    def __init__(self, settings) -> None:
        self.settings = settings

    def __call__(self, user: str, password: str) -> int | None:
        principal = self.settings.authenticate(password)
        if principal is None or principal.user != user:
            return None
        return int(principal.role)

    def records(self) -> tuple:
        # deferred: the OPC UA face's records (asyncua) only for a cell that has one
        from cnc.faces.opcua import FaceUser

        return tuple(FaceUser(k.user, k.role.name, k.digest()) for k in self.settings.api_keys)


def opcua_users(settings) -> OpcUaUsers:
    return OpcUaUsers(settings)


def machine_time(answer: str) -> float | None:
    """The machine time a simulation face answer reports (`... t=12.3456`), or None."""
    for word in answer.split():
        if word.startswith("t="):
            try:
                return float(word[2:])
            except ValueError:
                return None
    return None


def fault_types() -> list[dict]:
    """The `/api/fault-types` rows: the drive, bus and node kinds of drives.fault_registry,
    their aliases, the PLC field faults with plc.machine_io.DETECTION, RECOVERY_CLASS and
    RECOVERY, the PLC aliases."""
    # deferred: drives.faults loads python-can and canopen, which a host whose machines
    # run in their own processes does not otherwise need
    from drives.faults import fault_types as drive_fault_types

    out = drive_fault_types()
    for alias, (kind, _) in DRIVE_ALIASES.items():
        out.append(
            {"type": alias, "target": "drive:<AXIS>", "params": [], "description": f"= {kind}"}
        )
    for name, text in FAULTS.items():
        bound, since, how = DETECTION[name]
        out.append(
            {
                "type": name,
                "target": "plc",
                "params": [],
                "description": str(text),
                "detection": how,
                "bound_s": bound,
                "detect_from": since,
                "recovery_class": RECOVERY_CLASS[name],
                "recovery": RECOVERY[name],
            }
        )
    for alias, kind in PLC_ALIASES.items():
        out.append({"type": alias, "target": "plc", "params": [], "description": f"= {kind}"})
    return out
