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
import hashlib
import hmac
import logging
import time
from collections import deque
from collections.abc import Callable

from asyncua import Server, ua

from cnc.faces.opcua import instance
from cnc.faces.opcua import model as m
from cnc.faces.opcua.alarms import AlarmBook
from cnc.faces.opcua.host_data import FaceCommand, HostData
from cnc.faces.opcua.instance import Identification
from cnc.faces.opcua.security import CellRoles, CellUsers, Security, caller, secure_endpoint
from cnc.faces.opcua.space import Builder, Space
from cnc.faces.opcua.values import status_values
from cnc.status import MachineStatus

log = logging.getLogger(__name__)

DEFAULT_SAMPLE_MS = 50  # half the 100 ms publishing interval clients use


#: the Channel's vendor methods (OPC 40501-1 v1.02 defines none to start or stop a program:
#: job control moves to OPC 40001-3): the panel button each presses
METHODS = {"Start": "cycle_start", "Stop": "feed_hold"}
COMMANDS_KEPT = 1000  # method calls not yet taken by the host (oldest dropped)


class OpcUaFace:
    def __init__(
        self,
        machine: str,
        axes: tuple[str, ...],
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        identification: Identification | None = None,
        tools: Callable[[], tuple[int, Callable[[], dict[str, dict]]]] | None = None,
        program_sha256: Callable[[str], str] | None = None,
        switches: Callable[[], dict[str, bool]] | None = None,
        press: Callable[[str], str | None] | None = None,
        on_command: Callable[[FaceCommand], None] | None = None,
        security: Security | None = None,
        sample_ms: float = DEFAULT_SAMPLE_MS,
    ) -> None:
        """`tools`: the machine data's revision and how to get its tool table (read only
        when the revision has changed: every sample asks); `program_sha256`: the
        digest of a program in memory; `switches`: the channel's BlockSkip, OptionalStop
        and SingleStep; `press`: a panel button for Start/Stop ("cycle_start",
        "feed_hold") -> None when pressed, else why not; `on_command`: each method call,
        for the machine's event log. All are called on the server's thread: none may
        wait for the machine's cycle."""
        self.machine = machine
        self.axes = axes
        self.host, self.port = host, port
        self.identification = identification or Identification(serial_number=machine)
        self.tools = tools
        self.program_sha256 = program_sha256
        self.switches = switches
        self.press = press
        self.on_command = on_command
        self.security = security
        self.sample_s = sample_ms / 1000.0
        self.server: Server | None = None
        self.space: Space | None = None
        self._latest: tuple[MachineStatus, float] | None = None
        self._host: HostData = HostData()
        self._commands: deque[FaceCommand] = deque(maxlen=COMMANDS_KEPT)
        self._written: dict[str, object] = {}
        self._tools_revision: int | None = None
        self._tool_nodes: dict[str, tuple[ua.NodeId, tuple[bool, ...]]] = {}
        self._job_nodes: dict[str, ua.NodeId] = {}
        self._first_ts: float | None = None
        self._task: asyncio.Task | None = None
        self._bound: int | None = None
        self._builder: Builder | None = None
        self.alarms: AlarmBook | None = None
        self.samples = 0

    # ------------------------------------------------------------ machine side (any thread)

    def publish(self, status: MachineStatus, timestamp: float) -> None:
        """The machine's newest snapshot; never blocks (one reference store)."""
        self._latest = (status, timestamp)

    def set_host_data(self, data: HostData) -> None:
        self._host = data

    def take_commands(self) -> list[FaceCommand]:
        """The method calls made since the last take, oldest first (the host audits them)."""
        out = []
        while self._commands:
            out.append(self._commands.popleft())
        return out

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
                (sec.authenticate or self._host_user) if sec else None,
                sec.anonymous if sec else True,
            )
        )
        await server.init()
        server.set_endpoint(f"opc.tcp://{self.host}:{port}/")
        server.set_server_name(f"fmscell {self.machine}")
        await server.set_application_uri(f"urn:fmscell:{self.machine}")
        roles = CellRoles(on_denied=self._denied)
        if sec is None:
            server.set_security_policy([ua.SecurityPolicyType.NoSecurity], roles)
            server.set_identity_tokens([ua.AnonymousIdentityToken])
        else:
            await secure_endpoint(server, sec, self.machine, roles)
        ns = {uri: await server.register_namespace(uri) for uri in m.COMPANION_URIS}
        machine_ns = await server.register_namespace(f"urn:fmscell:machine:{self.machine}")
        self.space = Space(ns, machine_ns)
        self._builder = Builder(server, self.space)
        self._builder.types()
        methods = {name: self._method(name, button) for name, button in METHODS.items()}
        instance.machine_tool(self._builder, self.machine, self.identification, self.axes, methods)
        self.alarms = AlarmBook(server, self.space, self.machine, record=self._record)
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

    # ------------------------------------------------------------ methods and their audit

    def _method(self, name: str, button: str):
        """Start / Stop on the Channel: the panel's cycle start / feed hold, pressed for the
        caller (the permission check has let operators and above through)."""

        async def call(parent, *args):
            if args:
                return self._record(button, ua.StatusCodes.BadTooManyArguments, f"{name}()")
            if self.press is None:
                return self._record(button, ua.StatusCodes.BadNotExecutable, "no machine")
            refused = self.press(button)
            if refused:
                return self._record(button, ua.StatusCodes.BadInvalidState, refused)
            self._record(button, ua.StatusCodes.Good, f"{name} on Channel1")
            return []

        return call

    def _record(
        self, command: str, code: int, detail: str = "", *, log: bool = True
    ) -> ua.StatusCode:
        """Keep a method call for the host's audit and (`log`) tell the machine's event log."""
        user = caller()
        result = "done" if code == ua.StatusCodes.Good else ua.StatusCode(code).name
        entry = FaceCommand(user, command, result, detail, time.time())
        self._commands.append(entry)
        if log and self.on_command is not None:
            with contextlib.suppress(Exception):  # the log must not fail the call
                self.on_command(entry)
        return ua.StatusCode(code)

    def _host_user(self, user: str, password: str) -> int | None:
        """The role of a user name + password among the users the host sent (`HOST PUT`:
        the cell's API keys as sha256 digests), for a face with no user source of its
        own (a machine in its own process); None if unknown. Compared in constant time,
        every entry, as the REST API compares keys."""
        digest = hashlib.sha256(password.encode("utf-8", "surrogatepass")).hexdigest()
        found = None
        for entry in self._host.users:
            if hmac.compare_digest(digest, entry.key_sha256) and entry.user == user:
                found = entry.role_level
        return found

    def _denied(self, user: str, service: str) -> None:
        """A write or call refused by role: kept for the host only. Anyone may send those
        by the thousand; none of them may add work to the machine's cycle."""
        code = ua.StatusCodes.BadUserAccessDenied
        self._record(service, code, f"{user}: not an operator", log=False)

    # ------------------------------------------------------------ sampling

    async def _sampler(self) -> None:
        seen: tuple[MachineStatus, float] | None = None
        host_seen: HostData | None = None
        while True:
            await asyncio.sleep(self.sample_s)
            latest, host = self._latest, self._host
            try:
                if host is not host_seen:
                    host_seen = host
                    await self._apply_jobs(host)
                    seen = None  # the revision and job of the running program may change
                if latest is not None and latest is not seen:
                    seen = latest
                    await self._apply(*latest)
                await self._apply_switches()
                await self._apply_tools()
                self.samples += 1
            except Exception:  # noqa: BLE001 - a bad sample must not end the face
                log.exception("OPC UA face %s: sample failed", self.machine)

    async def _apply(self, status: MachineStatus, timestamp: float) -> None:
        if self._first_ts is None:
            self._first_ts = timestamp
        values = status_values(status, timestamp - self._first_ts)
        host = self._host
        program = "Production.ActiveProgram"
        values[f"{program}.Revision"] = host.revision_by_program.get(status.program, "")
        sha = host.sha256_by_program.get(status.program, "")
        if not sha and self.program_sha256 is not None and status.program:
            sha = self.program_sha256(status.program)
        values[f"{program}.Sha256"] = sha
        job = next((j.identifier for j in host.jobs if j.state in ("Running", "Interrupted")), "")
        values[f"{program}.JobIdentifier"] = job
        values[f"{program}.JobNodeId"] = self._job_nodes.get(job, ua.NodeId())
        await self._write_changed(values, _utc(timestamp))
        await self.alarms.update(status.alarms, _utc(timestamp))

    async def _apply_switches(self) -> None:
        if self.switches is None:
            return
        mods = "Monitoring.Channel1.ChannelModifiers"
        values = {f"{mods}.{k}": bool(v) for k, v in self.switches().items()}
        await self._write_changed(values, _dt.datetime.now(_dt.UTC))

    async def _write_changed(self, values: dict[str, object], source: _dt.datetime) -> None:
        now = _dt.datetime.now(_dt.UTC)
        for key, value in values.items():
            if self._written.get(key, _UNSET) == value:
                continue
            self._written[key] = value
            await self._write(f"{self.machine}.{key}", value, source, now)

    async def _write(self, key: str, value, source, now) -> None:
        entry = self.space.variables.get(key)
        if entry is None:
            return  # an axis that appeared after start (never, in practice)
        nodeid, vtype = entry
        if vtype == ua.VariantType.LocalizedText:
            value = ua.LocalizedText(value)
        elif vtype == ua.VariantType.NodeId and isinstance(value, tuple):
            value = self.space.node(value)  # a state's node in a companion namespace
        dv = Written(ua.Variant(value, vtype), SourceTimestamp=source, ServerTimestamp=now)
        await self.server.write_attribute_value(nodeid, dv)

    async def _apply_tools(self) -> None:
        if self.tools is None:
            return
        revision, table = self.tools()
        if revision == self._tools_revision:
            return
        self._tools_revision = revision
        tools = table()
        parent = ua.NodeId(f"{self.machine}.Equipment.Tools", self.space.machine_ns)
        now = _dt.datetime.now(_dt.UTC)
        for number in [n for n in self._tool_nodes if n not in tools]:
            await self._delete(self._tool_nodes.pop(number)[0])
        for number, data in tools.items():
            p = f"{self.machine}.Equipment.Tools.T{number}"
            # a limit set or cleared adds or removes a LimitValue: the tool is built anew
            shape = tuple(limit is None for limit in instance.tool_limits(data))
            known = self._tool_nodes.get(number)
            if known is not None and known[1] != shape:
                await self._delete(known[0])
                known = None
            if known is None:
                node = instance.tool(self._builder, parent, p, number, data)
                self._tool_nodes[number] = (node, shape)
            for key, value in instance.tool_values(data).items():
                await self._write(f"{p}.{key}", value, now, now)

    async def _delete(self, node: ua.NodeId) -> None:
        """A node of the instance with everything under it, and the updater's keys."""
        await self.server.delete_nodes([self.server.get_node(node)], recursive=True)
        prefix = f"{node.Identifier}."
        for key in [k for k in self.space.variables if k.startswith(prefix)]:
            del self.space.variables[key]

    async def _apply_jobs(self, host: HostData) -> None:
        name, ns = self.machine, self.space.machine_ns
        plan = ua.NodeId(f"{name}.Production.ProductionPlan", ns)
        wanted = {j.identifier for j in host.jobs}
        for ident in list(self._job_nodes):
            if ident not in wanted:
                await self._delete(self._job_nodes.pop(ident))
        now = _dt.datetime.now(_dt.UTC)
        for i, job in enumerate(host.jobs):
            p = f"{name}.Production.ProductionPlan.{job.identifier}"
            if job.identifier not in self._job_nodes:
                self._job_nodes[job.identifier] = instance.production_job(
                    self._builder, plan, p, job, i
                )
            for key, value in instance.job_values(job, i).items():
                await self._write(f"{p}.{key}", value, now, now)


_UNSET = object()


class Written(ua.DataValue):
    """A value the face wrote: never changed afterwards (each write makes a new one, of
    scalars and immutable texts), so the copy asyncua keeps of it per monitored item may
    be the value itself. asyncua deep-copies every value written once per monitored item
    (so that a writer changing a list in place cannot change what was sent): with 4
    clients that copying was a quarter of the server's time under a 50-item
    subscription load (bench/bench_opcua.py, profiled), for values that cannot change."""

    __slots__ = ()

    def __deepcopy__(self, memo) -> Written:
        return self


def _utc(timestamp: float) -> _dt.datetime:
    return _dt.datetime.fromtimestamp(timestamp, _dt.UTC)


def _free_port(host: str) -> int:
    """asyncua cannot report the port it bound for port 0: pick a free one first."""
    import socket

    with socket.socket() as s:
        s.bind((host, 0))
        return s.getsockname()[1]
