"""The agent's SHDR connections: one asyncio client per machine adapter.

Each connection reads the adapter's lines into the `Agent`, and supervises it the way the
reference agent does:

- on connect it sends `* PING`; an adapter that answers `* PONG <ms>` gets a `* PING` every
  <ms>, and if nothing (data or PONG) arrives for two heartbeats the connection is dropped;
  an adapter that never answers PONG is only dropped after `legacy_timeout_s`;
- a dropped or refused connection makes every data item of the device UNAVAILABLE (once)
  and is retried every `reconnect_interval_s`.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from dataclasses import dataclass

from cnc.faces.loop_thread import LoopThread
from mtconnect.agent import Agent

log = logging.getLogger(__name__)

DEFAULT_RECONNECT_INTERVAL_S = 10.0  # cppagent ReconnectInterval
DEFAULT_LEGACY_TIMEOUT_S = 600.0  # cppagent LegacyTimeout
MAX_LINE = 1 << 16


@dataclass
class ConnectionStats:
    attempts: int = 0
    connects: int = 0
    disconnects: int = 0
    lines: int = 0
    heartbeat_timeouts: int = 0
    bad_lines: int = 0


class AdapterConnection:
    """Keeps `agent` fed from the SHDR adapter of `device` at host:port."""

    def __init__(
        self,
        agent: Agent,
        device: str,
        host: str,
        port: int,
        *,
        reconnect_interval_s: float = DEFAULT_RECONNECT_INTERVAL_S,
        legacy_timeout_s: float = DEFAULT_LEGACY_TIMEOUT_S,
        connect_timeout_s: float = 5.0,
    ) -> None:
        agent.device(device)  # fail now, not on the first line
        self.agent, self.device = agent, device
        self.host, self.port = host, port
        self.reconnect_interval_s = reconnect_interval_s
        self.legacy_timeout_s = legacy_timeout_s
        self.connect_timeout_s = connect_timeout_s
        self.heartbeat_ms: int | None = None
        self.connected = False
        self.stats = ConnectionStats()
        self._task: asyncio.Task | None = None
        self._stopping = False

    def start(self) -> asyncio.Task:
        """Start supervising on the running loop."""
        if self._task is None:
            self._task = asyncio.get_running_loop().create_task(
                self._run(), name=f"shdr:{self.device}"
            )
        return self._task

    async def stop(self) -> None:
        self._stopping = True
        task, self._task = self._task, None
        # Python 3.11's wait_for can swallow a cancel that races with its inner future, so
        # cancel until the task is really done.
        while task is not None and not task.done():
            task.cancel()
            await asyncio.wait({task}, timeout=0.1)

    async def _run(self) -> None:
        while not self._stopping:
            self.stats.attempts += 1
            try:
                await self._session()
            except asyncio.CancelledError:
                raise
            except (OSError, TimeoutError, asyncio.IncompleteReadError, ValueError) as exc:
                log.info("%s: SHDR connection %s:%s: %s", self.device, self.host, self.port, exc)
            except Exception:  # a bug must cost a reconnect, never the agent
                log.exception("%s: SHDR connection failed", self.device)
            finally:
                if self.connected:
                    self.connected = False
                    self.stats.disconnects += 1
                self.agent.disconnected(self.device)
            await asyncio.sleep(self.reconnect_interval_s)

    async def _session(self) -> None:
        reader, writer = await asyncio.wait_for(
            asyncio.open_connection(self.host, self.port, limit=MAX_LINE),
            self.connect_timeout_s,
        )
        pinger: asyncio.Task | None = None
        try:
            self.connected = True
            self.heartbeat_ms = None
            self.stats.connects += 1
            self.agent.connected(self.device)
            writer.write(b"* PING\n")
            await writer.drain()
            while True:
                timeout = (
                    2 * self.heartbeat_ms / 1000.0 if self.heartbeat_ms else self.legacy_timeout_s
                )
                try:
                    raw = await asyncio.wait_for(reader.readline(), timeout)
                except TimeoutError:
                    self.stats.heartbeat_timeouts += 1
                    log.warning(
                        "%s: no data for %.3f s (two heartbeats); dropping", self.device, timeout
                    )
                    return
                if not raw:
                    return  # the adapter closed
                line = raw.decode("utf-8", "replace").strip()
                if not line:
                    continue
                if line.startswith("*"):
                    hb = _pong(line)
                    if hb is not None and self.heartbeat_ms is None:
                        self.heartbeat_ms = hb
                        pinger = asyncio.create_task(self._ping(writer, hb))
                    continue  # other `* key: value` commands are informative here
                self.stats.lines += 1
                try:
                    self.agent.ingest_line(self.device, line)
                except Exception:  # malformed data must not kill the connection
                    self.stats.bad_lines += 1
                    log.exception("%s: bad SHDR line %r", self.device, line[:200])
        finally:
            if pinger is not None:
                pinger.cancel()
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await pinger
            with contextlib.suppress(Exception):
                writer.close()

    async def _ping(self, writer: asyncio.StreamWriter, heartbeat_ms: int) -> None:
        while True:
            await asyncio.sleep(heartbeat_ms / 1000.0)
            writer.write(b"* PING\n")
            await writer.drain()


def _pong(line: str) -> int | None:
    parts = line.split()
    if len(parts) >= 3 and parts[0] == "*" and parts[1].upper() == "PONG":
        try:
            ms = int(parts[2])
        except ValueError:
            return None
        return ms if ms > 0 else None
    return None


async def connect_cell(
    agent: Agent, cell, ports: dict[str, int] | None = None, **kwargs
) -> list[AdapterConnection]:
    """Start a connection to every machine of a `CellConfig` whose SHDR face is on.

    `ports` overrides configured ports (machines bound to port 0 report their real one).
    """
    out = []
    for name, machine in cell.machines.items():
        port = (ports or {}).get(name, machine.ports.shdr)
        if not port:
            continue
        conn = AdapterConnection(agent, name, machine.ports.host, port, **kwargs)
        conn.start()
        out.append(conn)
    return out


class AgentConnections:
    """The agent's adapter connections on their own event-loop thread: the shell the cell
    server starts and stops. `endpoints` maps device name -> (host, port)."""

    def __init__(self, agent: Agent, endpoints: dict[str, tuple[str, int]], **kwargs) -> None:
        for name in endpoints:
            agent.device(name)
        self.agent = agent
        self.endpoints = dict(endpoints)
        self.kwargs = kwargs
        self.connections: dict[str, AdapterConnection] = {}
        self._thread = None

    @classmethod
    def for_cell(
        cls, agent: Agent, cell, ports: dict[str, int] | None = None, **kwargs
    ) -> AgentConnections:
        """Endpoints from a `CellConfig` (machines whose SHDR face is on); `ports` overrides
        configured ports (a machine bound to port 0 reports its real one)."""
        endpoints = {}
        for name, machine in cell.machines.items():
            port = (ports or {}).get(name, machine.ports.shdr)
            if port:
                endpoints[name] = (machine.ports.host, port)
        return cls(agent, endpoints, **kwargs)

    def start(self) -> AgentConnections:
        if self._thread is not None:
            return self
        self._thread = LoopThread("mtconnect-agent").start()

        async def go() -> None:
            for name, (host, port) in self.endpoints.items():
                conn = AdapterConnection(self.agent, name, host, port, **self.kwargs)
                conn.start()
                self.connections[name] = conn

        self._thread.run(go)
        return self

    def stop(self) -> None:
        thread, self._thread = self._thread, None
        if thread is None:
            return

        async def halt() -> None:
            for conn in self.connections.values():
                await conn.stop()

        thread.run(halt)
        thread.stop()
        self.connections.clear()
