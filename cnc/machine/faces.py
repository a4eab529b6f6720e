"""The machine's faces on one LoopThread: DNC port, Modbus TCP, SHDR, simulation face; the
OPC UA face on a loop thread of its own (its clients cost CPU the other faces must not wait
for)."""

from __future__ import annotations

import contextlib
from pathlib import Path

from cnc.controller import CommandRefused
from cnc.faces.dnc_port import ALARM_BAD_DATA, ALARM_REFUSED, DncAlarm, DncPort
from cnc.faces.loop_thread import LoopThread
from cnc.faces.shdr import ShdrAdapter
from cnc.machine.simface import SimulationFace
from cnc.machine_data import MachineDataError
from plc.modbus import ModbusFace
from plc.remote_panel import WRITABLE


class MachineFaces:
    """Starts the faces the configuration asks for (`ports`: null = off, 0 = any free port).

    `simulation`: None follows `ports.simulation`; True starts it (port 0 when the config
    has none); False keeps it off whatever the config says.
    """

    def __init__(
        self, machine, *, simulation: bool | None = None, dnc_parity: bool = False
    ) -> None:
        self.dnc_parity = dnc_parity
        self.machine = machine
        self.loop = LoopThread(f"faces-{machine.name}")
        self.dnc = None
        self.modbus = None
        self.shdr = None
        self.simulation = None
        self.opcua = None
        self.opcua_loop: LoopThread | None = None
        #: user name + password -> cell role (1 viewer .. 4 admin), for a secured OPC UA face
        self.opcua_authenticate = None
        self._want_sim = simulation

    def start(self) -> MachineFaces:
        m, ports = self.machine, self.machine.config.ports
        ctl = m.controller
        self.loop.start()
        if ports.dnc is not None:
            self.dnc = DncPort(
                m.memory,
                host=ports.host,
                port=ports.dnc,
                parity=self.dnc_parity,
                drip=self._drip,
                on_alarm=lambda n, text: m.raise_face_alarm(n, text, "DNC"),
                on_warning=lambda n, text: m.raise_face_alarm(n, text, "DNC", "WARNING"),
                policy=getattr(ctl, "policy", None),
                secret=ports.secret,
                machine_data=self._machine_data if hasattr(ctl, "machine_data") else None,
                host_data=self._host_data if ports.opcua is not None else None,
            )
            self.loop.run(self.dnc.start)
        if ports.modbus is not None:
            rt = m.plc
            allow = m.config.plc.modbus_write_allow or WRITABLE
            self.modbus = ModbusFace(
                lambda: rt.snapshot,
                rt.writes,
                rt.image.size,
                host=ports.host,
                port=ports.modbus,
                writable=allow,
            )
            self.loop.run(self.modbus.start)
        if ports.shdr is not None:
            self.shdr = ShdrAdapter(
                list(m.axis_names),
                host=ports.host,
                port=ports.shdr,
                tool_tip=m.config.kind == "mill5",
                continuous=[n for n, a in m.config.axes.items() if a.continuous],
            )
            self.loop.run(self.shdr.start)
            m.shdr = self.shdr
        if ports.opcua is not None:
            self._start_opcua()
        sim_port = ports.simulation
        if self._want_sim is True and sim_port is None:
            sim_port = 0
        if self._want_sim is False:
            sim_port = None
        if sim_port is not None:
            self.simulation = SimulationFace(m, host=ports.host, port=sim_port, secret=ports.secret)
            self.loop.run(self.simulation.start)
        return self

    def _start_opcua(self) -> None:
        # deferred: asyncua (about a second to import) only for a machine with an OPC UA port
        from cnc.faces.opcua import Identification, OpcUaFace, Security

        m, ports = self.machine, self.machine.config.ports
        security = None
        if ports.opcua_security != "none":
            base = Path(m.state_dir) if getattr(m, "state_dir", None) else Path.home() / ".fmscell"
            security = Security(
                cert_dir=base / "opcua",
                trusted_dir=base / "opcua" / "trusted",
                authenticate=self.opcua_authenticate,
            )
        ctl = m.controller
        md = getattr(ctl, "machine_data", None)
        self.opcua = OpcUaFace(
            m.name,
            tuple(m.axis_names),
            host=ports.host,
            port=ports.opcua,
            identification=Identification(
                model=m.config.kind,
                serial_number=m.name,
                software_revision=_version(),
                location=ports.host,
            ),
            tools=(lambda: (md.revision, md.tools_dict)) if md is not None else None,
            program_sha256=self._program_sha256,
            switches=lambda: {
                "BlockSkip": getattr(ctl, "block_skip", False),
                "OptionalStop": getattr(ctl, "optional_stop", False),
                "SingleStep": getattr(ctl, "single_block", False),
                "DryRun": False,  # the controllers have no dry run
            },
            press=self._press,
            on_command=self._face_command,
            security=security,
        )
        self.opcua_loop = LoopThread(f"opcua-{m.name}").start()
        self.opcua_loop.run(self.opcua.start, timeout=60.0)
        m.opcua = self.opcua

    def _press(self, button: str) -> None:
        """OPC UA Start / Stop: the panel's button, pressed at the machine's next cycle
        (the server's thread never waits for the cycle)."""
        m = self.machine
        panel = {"cycle_start": "PanelCycleStart", "feed_hold": "PanelFeedHold"}[button]
        m.call_soon(lambda: m.press(panel))

    def _face_command(self, command) -> None:
        """An OPC UA method call into the machine's event log (the machine's own audit)."""
        from dataclasses import asdict

        m = self.machine
        text = f"OPC UA {command.command} by {command.user}: {command.result}"
        m.call_soon(lambda: m.events.add(m.t, "command", text, asdict(command)))

    def _program_sha256(self, name: str) -> str:
        """The sha256 of the running program as held in program memory (O-number names)."""
        from cnc.faces.opcua.values import program_number  # deferred: with the OPC UA face

        number = program_number(name)
        for entry in self.machine.memory.directory():
            if entry.number == number:
                return entry.sha256
        return ""

    def _drip(self):
        buffer = self.machine.controller.drip_input()
        if buffer is None:
            raise DncAlarm(ALARM_REFUSED, "DRIP refused: the NC is not ready for a drip-feed")
        return buffer

    def _machine_data(self, what: str, doc):
        """The DNC port's TOOLS / OFFSETS: read, or write through the controller (refused
        in cycle, validated all or nothing; the machine saves it to its state directory)."""
        ctl = self.machine.controller
        if doc is not None:
            try:
                ctl.put_machine_data(what, doc)
            except CommandRefused as exc:
                raise DncAlarm(ALARM_REFUSED, f"{what.upper()} refused: {exc}") from None
            except MachineDataError as exc:
                raise DncAlarm(ALARM_BAD_DATA, f"{exc.pointer or '/'}: {exc.message}") from None
        md = ctl.machine_data
        return md.tools_dict() if what == "tools" else md.offsets_dict()

    def _host_data(self, doc) -> dict:
        """The DNC port's HOST PUT: the host's knowledge into the OPC UA face; the answer
        is what the face's clients did since the last exchange (the host audits it)."""
        from dataclasses import asdict

        # deferred: part of the OPC UA face (asyncua), loaded with it
        from cnc.faces.opcua import HostDataError
        from cnc.faces.opcua.host_data import from_doc

        if self.opcua is None:
            raise DncAlarm(ALARM_REFUSED, "HOST refused: the OPC UA face is not running")
        try:
            self.opcua.set_host_data(from_doc(doc))
        except HostDataError as exc:
            raise DncAlarm(ALARM_BAD_DATA, f"{exc.pointer}: {exc.message}") from None
        return {"commands": [asdict(c) for c in self.opcua.take_commands()]}

    def ports(self) -> dict[str, int | None]:
        """Bound TCP ports by face (None = off)."""
        return {
            "dnc": self.dnc.bound_port if self.dnc else None,
            "modbus": self.modbus.bound_port if self.modbus else None,
            "shdr": self.shdr.bound_port if self.shdr else None,
            "simulation": self.simulation.bound_port if self.simulation else None,
            "opcua": self.opcua.bound_port if self.opcua else None,
        }

    def stop(self) -> None:
        for face in (self.simulation, self.shdr, self.modbus, self.dnc):
            if face is not None:
                # a face that fails to stop must not keep the others up
                with contextlib.suppress(Exception):
                    self.loop.run(face.stop)
        self.machine.shdr = None
        self.machine.opcua = None
        if self.opcua is not None and self.opcua_loop is not None:
            with contextlib.suppress(Exception):
                # its sessions close first: with many clients on a loaded box, seconds
                self.opcua_loop.run(self.opcua.stop, timeout=30.0)
            self.opcua_loop.stop()
        self.loop.stop()


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("fmscell")
    except PackageNotFoundError:
        return "dev"
