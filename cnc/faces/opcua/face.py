"""The machine's OPC UA face: an OPC 40501-1 MachineTool server (asyncua) fed from the
machine's status snapshots.

The machine's cycle only hands over a reference (`publish`: one attribute store, no lock,
no I/O); the server runs on its own event loop thread and samples the newest snapshot every
`sample_ms`, writing what changed. A slow, hostile or numerous client can therefore cost
the server's thread CPU, never the machine's cycle its deadline.
"""

from __future__ import annotations

import asyncio
import contextlib
import datetime as _dt
import logging
from collections.abc import Callable
from dataclasses import dataclass, field

from asyncua import Server, ua

from cnc.faces.opcua import model as m
from cnc.faces.opcua.alarms import AlarmBook
from cnc.faces.opcua.security import CellRoles, CellUsers, Security, secure_endpoint
from cnc.faces.opcua.space import Builder, Space
from cnc.faces.opcua.values import STACK_LAMPS, color, status_values
from cnc.status import MachineStatus

log = logging.getLogger(__name__)

DEFAULT_SAMPLE_MS = 50  # half the 100 ms publishing interval clients use


@dataclass(frozen=True)
class Identification:
    manufacturer: str = "fmscell"
    model: str = ""
    serial_number: str = ""
    software_revision: str = ""
    location: str = ""


@dataclass(frozen=True)
class ProductionJob:
    """A cell job as the host sees it (OPC 40501 ProductionJob)."""

    identifier: str
    program: str
    runs_planned: int
    runs_completed: int
    parts_completed: int
    state: str  # Initializing | Running | Interrupted | Ended | Aborted


@dataclass
class HostData:
    """What only the DNC host knows: the dispatched revision of the running program and the
    cell's jobs on this machine. Replaced as a whole (`OpcUaFace.set_host_data`)."""

    revision_by_program: dict[str, str] = field(default_factory=dict)
    jobs: tuple[ProductionJob, ...] = ()
    sha256_by_program: dict[str, str] = field(default_factory=dict)


class OpcUaFace:
    def __init__(
        self,
        machine: str,
        axes: tuple[str, ...],
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        identification: Identification | None = None,
        tools: Callable[[], tuple[int, dict[str, dict]]] | None = None,
        program_sha256: Callable[[str], str] | None = None,
        security: Security | None = None,
        sample_ms: float = DEFAULT_SAMPLE_MS,
    ) -> None:
        self.machine = machine
        self.axes = axes
        self.host, self.port = host, port
        self.identification = identification or Identification(serial_number=machine)
        self.tools = tools
        self.program_sha256 = program_sha256
        self.security = security
        self.sample_s = sample_ms / 1000.0
        self.server: Server | None = None
        self.space: Space | None = None
        self._latest: tuple[MachineStatus, float] | None = None
        self._host: HostData = HostData()
        self._written: dict[str, object] = {}
        self._tools_revision: int | None = None
        self._tool_nodes: dict[str, ua.NodeId] = {}
        self._job_nodes: dict[str, ua.NodeId] = {}
        self._first_ts: float | None = None
        self._task: asyncio.Task | None = None
        self._bound: int | None = None
        self.alarms: AlarmBook | None = None
        self.samples = 0

    # ------------------------------------------------------------ machine side (any thread)

    def publish(self, status: MachineStatus, timestamp: float) -> None:
        """The machine's newest snapshot; never blocks (one reference store)."""
        self._latest = (status, timestamp)

    def set_host_data(self, data: HostData) -> None:
        self._host = data

    # ------------------------------------------------------------ loop side

    @property
    def bound_port(self) -> int:
        if self._bound is None:
            raise RuntimeError("OPC UA face not started")
        return self._bound

    @property
    def address(self) -> str:
        return f"opc.tcp://{self.host}:{self.bound_port}"

    async def start(self) -> None:
        port = self.port or _free_port(self.host)
        sec = self.security
        server = Server(
            user_manager=CellUsers(
                sec.authenticate if sec else None, sec.anonymous if sec else True
            )
        )
        await server.init()
        server.set_endpoint(f"opc.tcp://{self.host}:{port}/")
        server.set_server_name(f"fmscell {self.machine}")
        await server.set_application_uri(f"urn:fmscell:{self.machine}")
        if sec is None:
            server.set_security_policy([ua.SecurityPolicyType.NoSecurity], CellRoles())
            server.set_identity_tokens([ua.AnonymousIdentityToken])
        else:
            await secure_endpoint(server, sec, self.machine)
        ns = {uri: await server.register_namespace(uri) for uri in m.COMPANION_URIS}
        machine_ns = await server.register_namespace(f"urn:fmscell:machine:{self.machine}")
        self.space = Space(ns, machine_ns)
        builder = Builder(server, self.space)
        builder.types()
        self._build_instance(builder)
        self.alarms = AlarmBook(server, self.space, self.machine)
        await self.alarms.start()
        await server.start()
        self.server, self._bound = server, port
        self._task = asyncio.create_task(self._sampler())

    async def stop(self) -> None:
        task, self._task = self._task, None
        if task is not None:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        server, self.server = self.server, None
        if server is not None:
            with contextlib.suppress(Exception):
                await server.stop()

    def _build_instance(self, b: Builder) -> None:
        sp = self.space
        name = self.machine
        machines = sp.node(m.MACHINES_FOLDER)
        b.object(
            ua.NodeId(ua.ObjectIds.ObjectsFolder),
            machines,
            ua.QualifiedName("Machines", sp.ns[m.MACHINERY]),
            ua.NodeId(ua.ObjectIds.FolderType),
            ref=ua.ObjectIds.Organizes,
        )
        root = b.child_object(
            machines,
            name,
            (m.FMSCELL, name),
            m.MACHINE_TOOL_TYPE.node,
            ref=ua.ObjectIds.Organizes,
            notifier=True,
        )
        sp.root = root
        ident = self.identification
        idn = b.child_object(
            root,
            f"{name}.Identification",
            (m.DI, "Identification"),
            m.MACHINE_TOOL_IDENTIFICATION.node,
            ref=m.HAS_ADD_IN,
        )
        for key, nm, dt, value in (
            ("Manufacturer", (m.DI, "Manufacturer"), m.LOCALIZED_TEXT, ident.manufacturer),
            ("SerialNumber", (m.DI, "SerialNumber"), m.STRING, ident.serial_number),
            (
                "ProductInstanceUri",
                (m.DI, "ProductInstanceUri"),
                m.STRING,
                f"urn:fmscell:{ident.manufacturer}:{ident.model}:{ident.serial_number}",
            ),
            ("Model", (m.DI, "Model"), m.LOCALIZED_TEXT, ident.model),
            ("SoftwareRevision", (m.DI, "SoftwareRevision"), m.STRING, ident.software_revision),
            ("Location", (m.MACHINERY, "Location"), m.STRING, ident.location),
        ):
            b.value(idn, f"{name}.Identification.{key}", nm, dt, value, prop=True)

        mon = b.child_object(
            root, f"{name}.Monitoring", (m.MACHINE_TOOL, "Monitoring"), m.MONITORING.node
        )
        op = b.child_object(
            mon,
            f"{name}.Monitoring.MachineTool",
            (m.MACHINE_TOOL, "MachineTool"),
            m.MACHINE_OPERATION_MONITORING.node,
        )
        p = f"{name}.Monitoring.MachineTool"
        b.value(
            op,
            f"{p}.OperationMode",
            (m.MACHINE_TOOL, "OperationMode"),
            m.MACHINE_OPERATION_MODE.node,
            1,
        )
        b.value(op, f"{p}.PowerOnDuration", (m.MACHINE_TOOL, "PowerOnDuration"), m.UINT32, 0)
        b.value(
            op,
            f"{p}.FeedOverride",
            (m.MACHINE_TOOL, "FeedOverride"),
            m.DOUBLE,
            100.0,
            typedef=m.ANALOG_UNIT_RANGE,
        )
        p = f"{name}.Monitoring.Channel1"
        ch = b.child_object(mon, p, (m.MACHINE_TOOL, "Channel1"), m.CHANNEL_MONITORING.node)
        b.value(ch, f"{p}.Name", (m.MACHINE_TOOL, "Name"), m.STRING, "Channel1", prop=True)
        b.value(ch, f"{p}.ChannelState", (m.MACHINE_TOOL, "ChannelState"), m.CHANNEL_STATE.node, 2)
        b.value(ch, f"{p}.ChannelMode", (m.MACHINE_TOOL, "ChannelMode"), m.CHANNEL_MODE.node, 0)
        for what in ("FeedOverride", "RapidOverride"):
            b.value(
                ch,
                f"{p}.{what}",
                (m.MACHINE_TOOL, what),
                m.DOUBLE,
                100.0,
                typedef=m.ANALOG_UNIT_RANGE,
            )
        b.value(ch, f"{p}.Line", (m.FMSCELL, "Line"), m.UINT32, 0)
        b.value(ch, f"{p}.PathFeedRate", (m.FMSCELL, "PathFeedRate"), m.DOUBLE, 0.0)
        for axis in self.axes:
            ax = b.child_object(ch, f"{p}.{axis}", (m.FMSCELL, axis), m.BASE_OBJECT)
            b.value(ax, f"{p}.{axis}.ActualPosition", (m.FMSCELL, "ActualPosition"), m.DOUBLE, 0.0)
        p = f"{name}.Monitoring.Spindle"
        sp_node = b.child_object(mon, p, (m.MACHINE_TOOL, "Spindle"), m.SPINDLE_MONITORING.node)
        b.value(sp_node, f"{p}.Name", (m.MACHINE_TOOL, "Name"), m.STRING, "Spindle", prop=True)
        b.value(sp_node, f"{p}.IsRotating", (m.MACHINE_TOOL, "IsRotating"), m.BOOLEAN, False)
        b.value(
            sp_node,
            f"{p}.Override",
            (m.MACHINE_TOOL, "Override"),
            m.DOUBLE,
            100.0,
            typedef=m.ANALOG_UNIT_RANGE,
        )
        b.value(sp_node, f"{p}.Speed", (m.FMSCELL, "Speed"), m.DOUBLE, 0.0)
        p = f"{name}.Monitoring.Stacklight"
        sl = b.child_object(mon, p, (m.MACHINE_TOOL, "Stacklight"), m.BASIC_STACKLIGHT.node)
        b.value(
            sl,
            f"{p}.StacklightMode",
            (m.IA, "StacklightMode"),
            m.STACKLIGHT_OPERATION_MODE.node,
            0,
            prop=True,
        )
        for i, (lamp, lamp_color) in enumerate(STACK_LAMPS):
            el = b.child_object(
                sl, f"{p}.{lamp}", (m.FMSCELL, lamp), m.STACK_ELEMENT_LIGHT.node, ref=49
            )  # HasOrderedComponent
            b.value(
                el, f"{p}.{lamp}.NumberInList", (m.UA, "NumberInList"), m.UINTEGER, i, prop=True
            )
            b.value(el, f"{p}.{lamp}.SignalOn", (m.IA, "SignalOn"), m.BOOLEAN, False, prop=True)
            b.value(
                el,
                f"{p}.{lamp}.SignalColor",
                (m.IA, "SignalColor"),
                m.SIGNAL_COLOR.node,
                color(lamp_color),
            )

        prod = b.child_object(
            root, f"{name}.Production", (m.MACHINE_TOOL, "Production"), m.PRODUCTION.node
        )
        p = f"{name}.Production.ActiveProgram"
        ap = b.child_object(
            prod, p, (m.MACHINE_TOOL, "ActiveProgram"), m.PRODUCTION_ACTIVE_PROGRAM.node
        )
        b.value(ap, f"{p}.Name", (m.MACHINE_TOOL, "Name"), m.STRING, "", prop=True)
        b.value(ap, f"{p}.NumberInList", (m.UA, "NumberInList"), m.UINT16, 0, prop=True)
        st = b.child_object(
            ap, f"{p}.State", (m.MACHINE_TOOL, "State"), m.PRODUCTION_PROGRAM_STATE_MACHINE.node
        )
        b.value(
            st,
            f"{p}.State.CurrentState",
            (m.UA, "CurrentState"),
            m.LOCALIZED_TEXT,
            "Initializing",
            typedef=m.FINITE_STATE_VARIABLE,
        )
        b.value(ap, f"{p}.JobIdentifier", (m.MACHINE_TOOL, "JobIdentifier"), m.STRING, "")
        for key, dt, value in (
            ("Number", m.UINT32, 0),
            ("Line", m.UINT32, 0),
            ("PartCount", m.UINT32, 0),
            ("Sha256", m.STRING, ""),
            ("Revision", m.STRING, ""),
        ):
            b.value(ap, f"{p}.{key}", (m.FMSCELL, key), dt, value)
        b.child_object(
            prod,
            f"{name}.Production.ProductionPlan",
            (m.MACHINE_TOOL, "ProductionPlan"),
            m.PRODUCTION_JOB_LIST.node,
        )

        note = b.child_object(
            root,
            f"{name}.Notification",
            (m.MACHINE_TOOL, "Notification"),
            m.NOTIFICATION.node,
            notifier=True,
        )
        b.child_object(
            note,
            f"{name}.Notification.Messages",
            (m.MACHINE_TOOL, "Messages"),
            m.MESSAGES.node,
            notifier=True,
        )
        eq = b.child_object(
            root, f"{name}.Equipment", (m.MACHINE_TOOL, "Equipment"), m.EQUIPMENT.node
        )
        b.child_object(eq, f"{name}.Equipment.Tools", (m.MACHINE_TOOL, "Tools"), m.TOOL_LIST.node)
        self._builder = b

    # ------------------------------------------------------------ sampling

    async def _sampler(self) -> None:
        seen: tuple[MachineStatus, float] | None = None
        host_seen: HostData | None = None
        while True:
            await asyncio.sleep(self.sample_s)
            latest, host = self._latest, self._host
            try:
                if latest is not None and latest is not seen:
                    seen = latest
                    await self._apply(*latest)
                if host is not host_seen:
                    host_seen = host
                    await self._apply_jobs(host)
                await self._apply_tools()
                self.samples += 1
            except Exception:  # noqa: BLE001 - a bad sample must not end the face
                log.exception("OPC UA face %s: sample failed", self.machine)

    async def _apply(self, status: MachineStatus, timestamp: float) -> None:
        if self._first_ts is None:
            self._first_ts = timestamp
        values = status_values(status, timestamp - self._first_ts)
        host = self._host
        values["Production.ActiveProgram.Revision"] = host.revision_by_program.get(
            status.program, ""
        )
        sha = host.sha256_by_program.get(status.program, "")
        if not sha and self.program_sha256 is not None and status.program:
            sha = self.program_sha256(status.program)
        values["Production.ActiveProgram.Sha256"] = sha
        job = next((j.identifier for j in host.jobs if j.state in ("Running", "Interrupted")), "")
        values["Production.ActiveProgram.JobIdentifier"] = job
        source = _utc(timestamp)
        now = _dt.datetime.now(_dt.UTC)
        for key, value in values.items():
            if self._written.get(key, _UNSET) == value:
                continue
            self._written[key] = value
            await self._write(f"{self.machine}.{key}", value, source, now)
        await self.alarms.update(status.alarms, source)

    async def _write(self, key: str, value, source, now) -> None:
        entry = self.space.variables.get(key)
        if entry is None:
            return  # an axis that appeared after start (never, in practice)
        nodeid, vtype = entry
        if vtype == ua.VariantType.LocalizedText:
            value = ua.LocalizedText(value)
        dv = ua.DataValue(ua.Variant(value, vtype), SourceTimestamp=source, ServerTimestamp=now)
        await self.server.write_attribute_value(nodeid, dv)

    async def _apply_tools(self) -> None:
        if self.tools is None:
            return
        revision, tools = self.tools()
        if revision == self._tools_revision:
            return
        self._tools_revision = revision
        b, name = self._builder, self.machine
        parent = ua.NodeId(f"{name}.Equipment.Tools", self.space.machine_ns)
        now = _dt.datetime.now(_dt.UTC)
        for number, tool in tools.items():
            p = f"{name}.Equipment.Tools.T{number}"
            if number not in self._tool_nodes:
                node = b.child_object(parent, p, (m.FMSCELL, f"T{number}"), m.TOOL.node)
                self._tool_nodes[number] = node
                b.value(
                    node,
                    f"{p}.Name",
                    (m.MACHINE_TOOL, "Name"),
                    m.STRING,
                    tool.get("comment") or f"T{number}",
                    prop=True,
                )
                b.value(
                    node,
                    f"{p}.Identifier",
                    (m.MACHINE_TOOL, "Identifier"),
                    m.STRING,
                    f"T{number}",
                    prop=True,
                )
                b.value(
                    node,
                    f"{p}.ControlIdentifier1",
                    (m.MACHINE_TOOL, "ControlIdentifier1"),
                    m.UINT32,
                    int(number),
                )
                b.value(
                    node,
                    f"{p}.ControlIdentifierInterpretation",
                    (m.MACHINE_TOOL, "ControlIdentifierInterpretation"),
                    m.TOOL_MANAGEMENT.node,
                    0,
                )
                b.value(node, f"{p}.Locked", (m.MACHINE_TOOL, "Locked"), m.BOOLEAN, False)
                life = b.child_object(
                    node, f"{p}.ToolLife", (m.MACHINE_TOOL, "ToolLife"), m.BASE_OBJECT
                )
                for key, dt in (
                    ("Uses", m.UINT32),
                    ("UsesLimit", m.UINT32),
                    ("CutTime", m.DOUBLE),
                    ("CutTimeLimit", m.DOUBLE),
                ):
                    b.value(life, f"{p}.ToolLife.{key}", (m.FMSCELL, key), dt, None)
            expired = (tool["life_uses"] > 0 and tool["uses"] >= tool["life_uses"]) or (
                tool["life_time_s"] > 0 and tool["cut_time_s"] >= tool["life_time_s"]
            )
            for key, value in (
                ("Locked", expired),
                ("ToolLife.Uses", int(tool["uses"])),
                ("ToolLife.UsesLimit", int(tool["life_uses"])),
                ("ToolLife.CutTime", float(tool["cut_time_s"])),
                ("ToolLife.CutTimeLimit", float(tool["life_time_s"])),
            ):
                await self._write(f"{p}.{key}", value, now, now)

    async def _apply_jobs(self, host: HostData) -> None:
        b, name, ns = self._builder, self.machine, self.space.machine_ns
        plan = ua.NodeId(f"{name}.Production.ProductionPlan", ns)
        wanted = {j.identifier for j in host.jobs}
        for ident in list(self._job_nodes):
            if ident not in wanted:
                node = self._job_nodes.pop(ident)
                await self.server.delete_nodes([self.server.get_node(node)], recursive=True)
                prefix = f"{name}.Production.ProductionPlan.{ident}."
                for key in [k for k in self.space.variables if k.startswith(prefix)]:
                    del self.space.variables[key]
        for i, job in enumerate(host.jobs):
            p = f"{name}.Production.ProductionPlan.{job.identifier}"
            values = {
                "NumberInList": i,
                "RunsPlanned": job.runs_planned,
                "RunsCompleted": job.runs_completed,
                "PartsCompleted": job.parts_completed,
                "State.CurrentState": job.state,
            }
            if job.identifier not in self._job_nodes:
                node = b.child_object(
                    plan, p, (m.FMSCELL, job.identifier), m.PRODUCTION_JOB.node, ref=49
                )
                self._job_nodes[job.identifier] = node
                b.value(
                    node,
                    f"{p}.Identifier",
                    (m.MACHINE_TOOL, "Identifier"),
                    m.STRING,
                    job.identifier,
                    prop=True,
                )
                b.value(node, f"{p}.NumberInList", (m.UA, "NumberInList"), m.UINT16, i, prop=True)
                for key in ("RunsPlanned", "RunsCompleted", "PartsCompleted"):
                    b.value(node, f"{p}.{key}", (m.MACHINE_TOOL, key), m.UINT32, 0)
                st = b.child_object(
                    node,
                    f"{p}.State",
                    (m.MACHINE_TOOL, "State"),
                    m.PRODUCTION_JOB_STATE_MACHINE.node,
                )
                b.value(
                    st,
                    f"{p}.State.CurrentState",
                    (m.UA, "CurrentState"),
                    m.LOCALIZED_TEXT,
                    "",
                    typedef=m.FINITE_STATE_VARIABLE,
                )
                progs = b.child_object(
                    node,
                    f"{p}.ProductionPrograms",
                    (m.MACHINE_TOOL, "ProductionPrograms"),
                    m.ORDERED_LIST,
                )
                prog = b.child_object(
                    progs,
                    f"{p}.ProductionPrograms.{job.program}",
                    (m.FMSCELL, job.program),
                    m.PRODUCTION_PROGRAM.node,
                    ref=49,
                )
                b.value(
                    prog,
                    f"{p}.ProductionPrograms.{job.program}.Name",
                    (m.MACHINE_TOOL, "Name"),
                    m.STRING,
                    job.program,
                    prop=True,
                )
                b.value(
                    prog,
                    f"{p}.ProductionPrograms.{job.program}.NumberInList",
                    (m.UA, "NumberInList"),
                    m.UINT16,
                    0,
                    prop=True,
                )
            now = _dt.datetime.now(_dt.UTC)
            for key, value in values.items():
                await self._write(f"{p}.{key}", value, now, now)


_UNSET = object()


def _utc(timestamp: float) -> _dt.datetime:
    return _dt.datetime.fromtimestamp(timestamp, _dt.UTC)


def _free_port(host: str) -> int:
    """asyncua cannot report the port it bound for port 0: pick a free one first."""
    import socket

    with socket.socket() as s:
        s.bind((host, 0))
        return s.getsockname()[1]
