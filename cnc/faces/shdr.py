"""The machine's status face: an MTConnect SHDR adapter.

SHDR is the line protocol an MTConnect agent reads from a machine (docs/mtconnect.md):

    2026-11-21T06:00:00.000000Z|exec|ACTIVE|line|120|Xact|-12.5000
    2026-11-21T06:00:00.000000Z|nc_cond|FAULT|1012|FAULT||Following error X
    * PING            (agent -> adapter)       * PONG 10000    (adapter -> agent)

The core (`ShdrFormatter`) is pure: it turns `MachineStatus` snapshots into data-item
values and diffs two of them into SHDR lines, with the timestamp supplied by the caller so
lockstep runs give byte-identical streams. `ShdrAdapter` is the thin asyncio shell: a TCP
server that sends every newly connected agent a full dump, then the changes, and answers
heartbeats.
"""

from __future__ import annotations

import asyncio
import contextlib
import datetime as _dt
import logging
import threading
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from cnc.status import UNAVAILABLE, Alarm, MachineStatus

log = logging.getLogger(__name__)

SHDR_VERSION = "2"
DEFAULT_HEARTBEAT_MS = 1_000  # the simulator answers fast; cppagent adapters often use 10 s
PAIRS_PER_LINE = 32  # keeps lines short enough for any agent's line buffer
SEND_BUFFER_LIMIT = 1 << 20  # an agent this far behind is dropped; it reconnects to a dump

# --- data items --------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class ShdrItem:
    """One data item of the stream: the SHDR key and what it is in the MTConnect model.

    `component` is where the agent's device model puts it: "Device", "Controller", "Path",
    "Axes", an axis name ("X") or "Spindle". Types prefixed `x:` are fmscell extensions.
    """

    key: str
    category: str  # SAMPLE | EVENT | CONDITION
    type: str
    component: str
    sub_type: str | None = None
    units: str | None = None
    native_units: str | None = None


ROTARY_AXES = frozenset("ABC")

# Which condition an alarm source raises; drive alarms go to the axis' own ACTUATOR
# condition when the alarm names a configured axis.
SOURCE_CONDITION = {"NC": "nc_cond", "PLC": "plc_cond", "BUS": "bus_cond", "DNC": "dnc_cond"}
DRIVE_CONDITION = "servo"


def spindle_name(axes: Sequence[str]) -> str:
    """The spindle's component name: C, as in the MTConnect demo, unless C is an axis."""
    return "S" if "C" in axes else "C"


def shdr_items(axes: Sequence[str], tool_tip: bool = False) -> tuple[ShdrItem, ...]:
    """The declared table of data items for a machine with these axes, in dump order.

    `tool_tip` (a mill5): the tool tip by forward kinematics (PATH_POSITION, workpiece
    frame) and its deviation from the programmed straight line, now and the program's
    peak (cnc.controller.tooltip)."""
    items = [
        ShdrItem("avail", "EVENT", "AVAILABILITY", "Device"),
        ShdrItem("estop", "EVENT", "EMERGENCY_STOP", "Controller"),
        ShdrItem("mode", "EVENT", "CONTROLLER_MODE", "Controller"),
        ShdrItem("mode_detail", "EVENT", "x:MODE_DETAIL", "Controller"),
        ShdrItem("bus_load", "SAMPLE", "x:CAN_BUS_LOAD", "Controller", "AVERAGE", "PERCENT"),
        ShdrItem("bus_load_peak", "SAMPLE", "x:CAN_BUS_LOAD", "Controller", "MAXIMUM", "PERCENT"),
        ShdrItem("plc_scan", "SAMPLE", "x:PLC_SCAN_TIME", "Controller"),  # ms
        ShdrItem("nc_cond", "CONDITION", "SYSTEM", "Controller"),
        ShdrItem("plc_cond", "CONDITION", "LOGIC_PROGRAM", "Controller"),
        ShdrItem("bus_cond", "CONDITION", "COMMUNICATIONS", "Controller"),
        ShdrItem("dnc_cond", "CONDITION", "COMMUNICATIONS", "Controller", "x:DNC"),
        ShdrItem("exec", "EVENT", "EXECUTION", "Path"),
        ShdrItem("program", "EVENT", "PROGRAM", "Path"),
        ShdrItem("line", "EVENT", "LINE_NUMBER", "Path", "ABSOLUTE"),
        ShdrItem("block", "EVENT", "BLOCK", "Path"),
        ShdrItem("path_feedrate", "SAMPLE", "PATH_FEEDRATE", "Path", "ACTUAL", "MILLIMETER/SECOND"),
        ShdrItem("feed_ovr", "EVENT", "PATH_FEEDRATE_OVERRIDE", "Path", "PROGRAMMED"),
        ShdrItem("rapid_ovr", "EVENT", "PATH_FEEDRATE_OVERRIDE", "Path", "RAPID"),
        ShdrItem("part_count", "EVENT", "PART_COUNT", "Path"),
        ShdrItem("acc", "EVENT", "x:ADAPTIVE_CONTROL", "Path"),
        # REFERENCED, or NOT_REFERENCED and the axes that need homing ("NOT_REFERENCED X Z")
        ShdrItem("referenced", "EVENT", "x:REFERENCED", "Controller"),
        ShdrItem("start_refused", "EVENT", "x:CYCLE_START_REFUSED", "Path"),
        ShdrItem(DRIVE_CONDITION, "CONDITION", "ACTUATOR", "Axes"),
    ]
    if tool_tip:
        items += [
            ShdrItem("tip", "SAMPLE", "PATH_POSITION", "Path", "COMMANDED", "MILLIMETER_3D"),
            ShdrItem("tip_dev", "SAMPLE", "x:TOOL_TIP_DEVIATION", "Path", None, "MILLIMETER"),
            ShdrItem(
                "tip_dev_peak", "SAMPLE", "x:TOOL_TIP_DEVIATION", "Path", "MAXIMUM", "MILLIMETER"
            ),
        ]
    for name in axes:
        if name in ROTARY_AXES:
            pos = ("ANGLE", "DEGREE")
        else:
            pos = ("POSITION", "MILLIMETER")
        items += [
            ShdrItem(f"{name}act", "SAMPLE", pos[0], name, "ACTUAL", pos[1]),
            ShdrItem(f"{name}cmd", "SAMPLE", pos[0], name, "COMMANDED", pos[1]),
            ShdrItem(f"{name}servo", "CONDITION", "ACTUATOR", name),
        ]
    s = spindle_name(axes)
    items += [
        ShdrItem(
            f"{s}speed", "SAMPLE", "ROTARY_VELOCITY", "Spindle", "ACTUAL", "REVOLUTION/MINUTE"
        ),
        ShdrItem(f"{s}load", "SAMPLE", "LOAD", "Spindle", None, "PERCENT"),
        ShdrItem(f"{s}ovr", "EVENT", "ROTARY_VELOCITY_OVERRIDE", "Spindle", None, "PERCENT"),
        ShdrItem(f"{s}mode", "EVENT", "ROTARY_MODE", "Spindle"),
    ]
    return tuple(items)


# --- value formatting ----------------------------------------------------------------------

Condition = tuple[tuple[str, str, str, str, str], ...]
"""Active conditions of one condition item: (level, native code, native severity, qualifier,
text) per alarm, sorted by native code; () is NORMAL; None (in a State) is UNAVAILABLE."""
State = dict[str, "str | Condition | None"]


def shdr_timestamp(timestamp: float | str) -> str:
    """UTC ISO 8601 with microseconds, from seconds since the epoch (or passed through)."""
    if isinstance(timestamp, str):
        return timestamp
    t = _dt.datetime.fromtimestamp(timestamp, _dt.UTC)
    return t.strftime("%Y-%m-%dT%H:%M:%S.%fZ")


def escape(value: str) -> str:
    """One SHDR token. Free text with `|`, quotes or backslashes is quoted the way the
    reference agent's tokenizer reads it back: `"` ... `"` with `\\` before each of them.
    Line breaks would end the record, so they become spaces; surrounding blanks go."""
    if "\n" in value or "\r" in value:
        value = value.replace("\r\n", " ").replace("\n", " ").replace("\r", " ")
    value = value.strip()  # SHDR trims tokens; trimming here keeps quoted and plain alike
    if any(c in value for c in '|"\\'):
        quoted = value.replace("\\", "\\\\").replace('"', '\\"').replace("|", "\\|")
        return f'"{quoted}"'
    return value


def _num(value: float, digits: int) -> str:
    text = f"{value:.{digits}f}"
    return "0" + text[2:] if text.startswith("-0") and float(text) == 0 else text


class ShdrFormatter:
    """Pure: MachineStatus -> data-item values -> SHDR lines."""

    def __init__(
        self, axes: Sequence[str], *, tool_tip: bool = False, continuous: Sequence[str] = ()
    ) -> None:
        self.axes = tuple(axes)
        self.spindle = spindle_name(self.axes)
        self.items = shdr_items(self.axes, tool_tip)
        self.tool_tip = tool_tip
        # endless rotary axes are shown modulo 360 (the NC keeps the unwrapped angle)
        self.continuous = frozenset(continuous)
        self._conditions = tuple(i.key for i in self.items if i.category == "CONDITION")
        self._values = tuple(i.key for i in self.items if i.category != "CONDITION")

    # ---------------------------------------------------------------- snapshot -> state

    def state(self, status: MachineStatus) -> State:
        """The value of every data item for this snapshot (SHDR text, or conditions)."""
        if status.availability == UNAVAILABLE:
            out: State = dict.fromkeys(self._values, UNAVAILABLE)
            out.update(dict.fromkeys(self._conditions))
            return out
        s = self.spindle
        out = {
            "avail": status.availability,
            "estop": status.emergency_stop,
            "mode": status.controller_mode,
            "mode_detail": status.mode_detail,
            "bus_load": _num(status.can_bus_load.mean, 1),
            "bus_load_peak": _num(status.can_bus_load.peak, 1),
            "plc_scan": _num(status.plc_scan_time_ms, 3),
            "exec": status.execution,
            "program": escape(status.program),
            "line": str(status.line),
            "block": escape(status.block),
            # MTConnect's PATH_FEEDRATE is mm/s; the controller thinks in mm/min.
            "path_feedrate": _num(status.path_feed_rate / 60.0, 3),
            "feed_ovr": _num(status.feed_override, 0),
            "rapid_ovr": _num(status.rapid_override, 0),
            "part_count": str(status.part_count),
            "acc": status.adaptive_control,
            "referenced": (
                "NOT_REFERENCED " + " ".join(status.unreferenced)
                if status.unreferenced
                else "REFERENCED"
            ),
            "start_refused": escape(status.cycle_start_refused),
            f"{s}speed": _num(status.spindle_speed, 1),
            f"{s}load": _num(status.spindle_load, 1),
            f"{s}ovr": _num(status.spindle_override, 0),
            f"{s}mode": "SPINDLE",
        }
        for name in self.axes:
            axis = status.axes.get(name)
            if axis is None:
                out[f"{name}act"] = out[f"{name}cmd"] = UNAVAILABLE
            elif name in self.continuous:
                out[f"{name}act"] = _num(axis.actual % 360.0, 4)
                out[f"{name}cmd"] = _num(axis.commanded % 360.0, 4)
            else:
                out[f"{name}act"] = _num(axis.actual, 4)
                out[f"{name}cmd"] = _num(axis.commanded, 4)
        if self.tool_tip:
            tip = status.tool_tip
            if tip is None:
                out["tip"] = out["tip_dev"] = out["tip_dev_peak"] = UNAVAILABLE
            else:
                out["tip"] = " ".join(_num(v, 4) for v in tip.position)
                out["tip_dev"] = _num(tip.deviation, 5)
                out["tip_dev_peak"] = _num(tip.peak, 5)
        active: dict[str, list[tuple[str, str, str, str, str]]] = {k: [] for k in self._conditions}
        for alarm in status.alarms:
            active[self.condition_key(alarm)].append(_condition_entry(alarm))
        for key, entries in active.items():
            # One entry per native code: the condition model keys activations by code.
            by_code = {e[1]: e for e in entries}
            out[key] = tuple(by_code[c] for c in sorted(by_code))
        return out

    def condition_key(self, alarm: Alarm) -> str:
        """The condition data item an alarm raises."""
        if alarm.source == "DRIVE":
            if alarm.axis in self.axes:
                return f"{alarm.axis}servo"
            return DRIVE_CONDITION
        return SOURCE_CONDITION[alarm.source]

    # ---------------------------------------------------------------- state -> lines

    def diff_states(self, prev: State | None, cur: State, timestamp: str) -> list[str]:
        """SHDR lines that take an agent from `prev` to `cur` (all of `cur` if prev is None)."""
        pairs = [(k, cur[k]) for k in self._values if prev is None or prev.get(k) != cur[k]]
        lines = [
            timestamp + "|" + "|".join(f"{k}|{v}" for k, v in pairs[i : i + PAIRS_PER_LINE])
            for i in range(0, len(pairs), PAIRS_PER_LINE)
        ]
        for key in self._conditions:
            lines += _condition_lines(
                key, prev.get(key, ()) if prev is not None else _FIRST, cur[key], timestamp
            )
        return lines

    def diff(
        self, prev: MachineStatus | None, cur: MachineStatus, timestamp: float | str
    ) -> list[str]:
        """SHDR lines for what changed between two snapshots."""
        ts = shdr_timestamp(timestamp)
        return self.diff_states(None if prev is None else self.state(prev), self.state(cur), ts)

    def dump(self, status: MachineStatus, timestamp: float | str) -> list[str]:
        """Every data item's value: what a newly connected agent is sent."""
        return self.diff_states(None, self.state(status), shdr_timestamp(timestamp))


_FIRST = ("first",)  # sentinel: no previous state, so even NORMAL must be stated


def _condition_entry(alarm: Alarm) -> tuple[str, str, str, str, str]:
    return (alarm.severity, str(alarm.number), alarm.severity, "", escape(alarm.text))


def _condition_lines(
    key: str, prev: Condition | None | tuple, cur: Condition | None, ts: str
) -> list[str]:
    if cur == prev:
        return []
    if cur is None:
        return [f"{ts}|{key}|UNAVAILABLE||||"]
    if not cur:
        return [f"{ts}|{key}|NORMAL||||"]
    out: list[str] = []
    before = {e[1]: e for e in prev} if prev and prev is not _FIRST else {}
    now = {e[1]: e for e in cur}
    for code in before:
        if code not in now:
            out.append(f"{ts}|{key}|NORMAL|{code}|||")
    for code, entry in now.items():
        if before.get(code) != entry:
            out.append(f"{ts}|{key}|" + "|".join(entry))
    return out


# --- the TCP shell -------------------------------------------------------------------------


@dataclass
class ShdrStats:
    lines_sent: int = 0
    pings: int = 0
    connections: int = 0
    dropped_slow: int = 0


class ShdrAdapter:
    """The status face: an SHDR server for MTConnect agents.

    `publish(status, timestamp)` may be called from any thread (the machine's cycle); the
    changes go to every connected agent in publish order. A new agent first gets
    `* shdrVersion`, then a full dump of the last published snapshot.
    """

    def __init__(
        self,
        axes: Sequence[str],
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        heartbeat_ms: int = DEFAULT_HEARTBEAT_MS,
        send_buffer_limit: int = SEND_BUFFER_LIMIT,
        tool_tip: bool = False,
        continuous: Sequence[str] = (),
    ) -> None:
        if heartbeat_ms <= 0:
            raise ValueError(f"SHDR heartbeat must be > 0 ms, got {heartbeat_ms}")
        self.formatter = ShdrFormatter(axes, tool_tip=tool_tip, continuous=continuous)
        self.host, self.port = host, port
        self.heartbeat_ms = int(heartbeat_ms)
        self.send_buffer_limit = send_buffer_limit
        self.stats = ShdrStats()
        self._lock = threading.Lock()
        self._state: State | None = None  # last published, formatter side
        self._sent: tuple[State, str] | None = None  # last broadcast, loop side
        self._server: asyncio.Server | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._writers: set[asyncio.StreamWriter] = set()
        self._sessions: set[asyncio.Task] = set()

    @classmethod
    def for_machine(cls, machine, **kwargs) -> ShdrAdapter:
        """An adapter for a `cnc.config.MachineConfig` on its configured host and port."""
        port = machine.ports.shdr
        if port is None:
            raise ValueError("the machine's SHDR face is off (ports.shdr is null)")
        return cls(list(machine.axes), host=machine.ports.host, port=port, **kwargs)

    @property
    def bound_port(self) -> int:
        if self._server is None:
            raise RuntimeError("SHDR adapter not started")
        return self._server.sockets[0].getsockname()[1]

    @property
    def clients(self) -> int:
        return len(self._writers)

    async def start(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._server = await asyncio.start_server(self._session, self.host, self.port)

    async def stop(self) -> None:
        server, self._server = self._server, None
        if server is None:
            return
        server.close()
        for writer in list(self._writers):
            writer.close()  # the sessions see EOF and end by themselves
        if self._sessions:
            _, pending = await asyncio.wait(set(self._sessions), timeout=1.0)
            for task in pending:
                task.cancel()
        await server.wait_closed()
        self._loop = None

    def publish(self, status: MachineStatus, timestamp: float | str) -> list[str]:
        """Send what changed since the last snapshot; returns the SHDR lines (for traces)."""
        ts = shdr_timestamp(timestamp)
        with self._lock:
            state = self.formatter.state(status)
            lines = self.formatter.diff_states(self._state, state, ts)
            self._state = state
            loop = self._loop
            if loop is None or loop.is_closed():
                self._sent = (state, ts)
            elif lines:
                text = "".join(line + "\n" for line in lines).encode()
                loop.call_soon_threadsafe(self._broadcast, text, len(lines), state, ts)
        return lines

    # ---------------------------------------------------------------- loop side

    def _broadcast(self, data: bytes, count: int, state: State, ts: str) -> None:
        self._sent = (state, ts)
        for writer in list(self._writers):
            self._write(writer, data, count)

    def _write(self, writer: asyncio.StreamWriter, data: bytes, count: int) -> None:
        transport = writer.transport
        if transport.is_closing():
            return
        if transport.get_write_buffer_size() > self.send_buffer_limit:
            # An agent that does not read would make us buffer without bound.
            self.stats.dropped_slow += 1
            log.warning("SHDR agent %s too slow; dropped", writer.get_extra_info("peername"))
            self._writers.discard(writer)
            transport.abort()
            return
        writer.write(data)
        self.stats.lines_sent += count

    async def _session(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        self._sessions.add(task)
        self.stats.connections += 1
        try:
            lines = [f"* shdrVersion: {SHDR_VERSION}"]
            if self._sent is not None:
                state, ts = self._sent
                lines += self.formatter.diff_states(None, state, ts)
            self._write(writer, "".join(ln + "\n" for ln in lines).encode(), len(lines))
            self._writers.add(writer)
            while self._server is not None:
                raw = await reader.readline()
                if not raw:
                    return
                if raw.strip().upper() == b"* PING":
                    self.stats.pings += 1
                    self._write(writer, f"* PONG {self.heartbeat_ms}\n".encode(), 1)
        except (ConnectionError, asyncio.IncompleteReadError, ValueError):
            pass  # ValueError: a line longer than the stream limit; the agent is confused
        except asyncio.CancelledError:
            pass  # stop(): a handler task that re-raises is logged as an error by asyncio
        finally:
            self._writers.discard(writer)
            self._sessions.discard(task)
            with contextlib.suppress(Exception):
                writer.close()


def lines_text(lines: Iterable[str]) -> str:
    """Lines as they go on the wire."""
    return "".join(line + "\n" for line in lines)
