"""The PLC's Modbus TCP face: an asyncio server over the strict MBAP framer and PDU core.

It needs only a way to read the newest scan snapshot and the write queue: it never touches the
live image and never imports the runtime. Each request reads exactly one snapshot; each write
request becomes one batch on the queue, applied whole at the start of the next scan.
"""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import logging
import struct
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Protocol

from plc.image import ImageSize, Snapshot, WriteQueue
from plc.modbus.allowlist import AllowList
from plc.modbus.frame import MAX_ADU, FrameViolation, MbapDecoder, encode
from plc.modbus.map import ModbusMap
from plc.modbus.pdu import (
    GATEWAY_TARGET_FAILED,
    MAX_READ_REGISTERS,
    SERVER_DEVICE_FAILURE,
    DeviceIdentity,
    PduHandler,
    PduSizeError,
)
from plc.runtime.realtime import promote_current_thread

log = logging.getLogger("plc.modbus")
audit = logging.getLogger("plc.modbus.write")

_monotonic = time.monotonic

#: Answer ADU to a register read of n registers: transaction + protocol id (4 bytes as
#: received), length, unit, function, byte count, the registers as IEC INT.
_READ_ANSWER = [None] + [
    struct.Struct(f">4sHBBB{n}h").pack for n in range(1, MAX_READ_REGISTERS + 1)
]

#: Frames a connection may have waiting behind an unanswered write in ack-after-scan mode.
_MAX_BACKLOG = 32


class ScanGateLike(Protocol):
    """What the face needs of a scan gate (plc.runtime.realtime.ScanGate; not imported so
    the face stays independent of the runtime)."""

    step_aside_at: float

    def step_aside(self, now: float) -> bool: ...


@dataclass
class FaceStats:
    """Counters for diagnostics (exposed to status pages; not reset while running)."""

    connections_open: int = 0
    connections_total: int = 0
    connections_refused: int = 0
    connections_evicted: int = 0
    requests: int = 0
    exceptions: int = 0
    write_batches: int = 0
    protocol_errors: int = 0
    frame_timeouts: int = 0
    idle_timeouts: int = 0
    internal_errors: int = 0


class ModbusFace:
    """Modbus TCP server on a PLC's process image.

    `get_snapshot` returns the newest published scan snapshot; `writes` receives one batch
    per write request. `writable` (an AllowList or its string form) lists what clients may
    write; everything else is read-only. Port 0 binds an ephemeral port (see `bound_port`).

    Timeouts: a connection holding part of a frame for `frame_timeout` seconds, or silent
    for `idle_timeout` seconds (None: never), is closed.

    Connection limits: at most `max_connections` clients at once, and at most
    `max_connections_per_client` from one source address. A new connection that would break
    a limit is admitted and the least recently active connection makes room for it: the
    newcomer's own address's at the per-address limit, else one of the address holding the
    most connections. So idle connections never lock the face (a new client, e.g. the host's
    remote panel on its fresh connection per command, always gets in); only a connection
    with a write answer outstanding is never evicted, and if every candidate has one, the
    newcomer is refused.

    `allowed_clients` (IP addresses or networks, e.g. ["127.0.0.1", "10.1.0.0/16"]) refuses
    connections from any other source address; None accepts every client.

    Unit id: with `unit_id=None` (default) every unit id is served and echoed, as a Modbus/TCP
    end device does. With `unit_id=N` only N and 0xFF are served; others get exception 0x0B.

    Write responses are sent when the batch is queued (`ack_after_scan=False`), or once a scan
    that certainly applied it has published (`ack_after_scan=True`, at most two scans later;
    exception 04 if that takes longer than `ack_timeout`, the batch then stays queued).

    `scan_gate` (a PLC runner's `gate`, e.g. `RealtimeRunner.gate`): when a request arrives
    within the gate's guard before a scan deadline, the face first waits, without the GIL,
    until that scan has published (bounded by the gate), so that a busy face is not holding
    the GIL when the scan thread of the same process wakes. None: never wait.
    """

    def __init__(
        self,
        get_snapshot: Callable[[], Snapshot],
        writes: WriteQueue,
        size: ImageSize | None = None,
        *,
        host: str = "127.0.0.1",
        port: int = 5020,
        writable: AllowList | str | None = None,
        mb_map: ModbusMap | None = None,
        unit_id: int | None = None,
        max_connections: int = 16,
        max_connections_per_client: int = 8,
        frame_timeout: float = 5.0,
        idle_timeout: float | None = 120.0,
        ack_after_scan: bool = False,
        ack_timeout: float = 1.0,
        identity: DeviceIdentity | None = None,
        allowed_clients: Iterable[str] | None = None,
        scan_gate: ScanGateLike | None = None,
    ) -> None:
        if mb_map is None:
            mb_map = ModbusMap(size)
        elif size is not None and size != mb_map.size:
            raise ValueError("ModbusFace: size and mb_map.size disagree")
        if not isinstance(writable, AllowList):
            writable = AllowList.parse(writable)
        if unit_id is not None and not 0 <= unit_id <= 255:
            raise ValueError(f"ModbusFace: unit_id {unit_id} outside 0..255")
        if max_connections < 1:
            raise ValueError("ModbusFace: max_connections must be >= 1")
        if max_connections_per_client < 1:
            raise ValueError("ModbusFace: max_connections_per_client must be >= 1")
        if frame_timeout <= 0 or (idle_timeout is not None and idle_timeout <= 0):
            raise ValueError("ModbusFace: timeouts must be > 0")
        self.get_snapshot = get_snapshot
        self.writes = writes
        self.map = mb_map
        self.writable = writable
        self.handler = PduHandler(mb_map, writable.resolve(mb_map), identity)
        # FC03/FC04 fast path: (first address, end, snapshot attribute) per area of the table
        self._read_segments = {
            fc: tuple((s.start, s.end, s.area.lower()) for s in mb_map.segments(table))
            for fc, table in ((0x03, "hr"), (0x04, "ir"))
        }
        self.host = host
        self.port = port
        self.unit_id = unit_id
        self.max_connections = max_connections
        self.max_connections_per_client = min(max_connections_per_client, max_connections)
        self.frame_timeout = frame_timeout
        self.idle_timeout = idle_timeout
        self.ack_after_scan = ack_after_scan
        self.ack_timeout = ack_timeout
        try:
            self.allowed_clients = (
                None
                if allowed_clients is None
                else tuple(ipaddress.ip_network(c, strict=False) for c in allowed_clients)
            )
        except ValueError as e:
            raise ValueError(f"ModbusFace: allowed_clients: {e}") from None
        self.scan_gate = scan_gate
        #: the face thread's scheduling once `start_in_thread` ran, e.g. "SCHED_FIFO 10"
        self.thread_scheduling = "not started in a thread"
        self.stats = FaceStats()
        self._server: asyncio.Server | None = None
        self._sweeper: asyncio.Task | None = None
        self._connections: set[_Connection] = set()
        self._tasks: set[asyncio.Task] = set()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None

    @property
    def bound_port(self) -> int:
        """The TCP port actually bound (differs from `port` when port was 0)."""
        if self._server is None or not self._server.sockets:
            raise RuntimeError("ModbusFace is not started")
        return self._server.sockets[0].getsockname()[1]

    # -- asyncio ----------------------------------------------------------------------

    async def start(self) -> None:
        """Bind and serve on the running event loop."""
        if self._server is not None:
            raise RuntimeError("ModbusFace already started")
        self._check_snapshot_fits()
        self._loop = loop = asyncio.get_running_loop()
        self._server = await loop.create_server(
            lambda: _Connection(self), self.host, self.port, reuse_address=True
        )
        self._sweeper = loop.create_task(self._sweep())
        log.info(
            "Modbus TCP face on %s:%d (writable: %s)", self.host, self.bound_port, self.writable
        )

    def _check_snapshot_fits(self) -> None:
        """Refuse to serve a map larger than the image: it would answer short data."""
        snap = self.get_snapshot()
        for table in ("coil", "di", "ir", "hr"):
            for seg in self.map.segments(table):
                have = len(snap.area(seg.area))
                if have < seg.count:
                    raise ValueError(
                        f"ModbusFace: snapshot %{seg.area} has {have} entries but the map "
                        f"serves {seg.count}; pass the image's ImageSize"
                    )

    async def stop(self) -> None:
        """Stop listening and close every client connection."""
        server, self._server = self._server, None
        if server is None:
            return
        server.close()
        if self._sweeper is not None:
            self._sweeper.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._sweeper
            self._sweeper = None
        for conn in list(self._connections):
            conn.close()
        for task in list(self._tasks):
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        await server.wait_closed()
        for _ in range(3):  # let the transports deliver connection_lost before the loop stops
            await asyncio.sleep(0)

    async def __aenter__(self) -> ModbusFace:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()

    # -- thread-hosted, for synchronous callers ---------------------------------------

    def start_in_thread(self, rt_priority: int = 0) -> ModbusFace:
        """Serve from a daemon thread with its own event loop; returns once bound.

        `rt_priority` 1..99 asks SCHED_FIFO for that thread: give it one *below* the PLC
        scan thread's, so the scan still preempts it, while ordinary processes no longer
        deschedule the face in the middle of a request, holding the GIL the scan needs
        (docs/ladder.md, "Staying on time"). Refused (no CAP_SYS_NICE), the face runs with
        ordinary scheduling and `thread_scheduling` says why. 0 (default): ordinary.
        """
        if self._thread is not None:
            raise RuntimeError("ModbusFace already started in a thread")
        if not 0 <= rt_priority <= 99:
            raise ValueError(f"ModbusFace: rt_priority {rt_priority} outside 0..99 (0 = off)")
        ready = threading.Event()
        failure: list[BaseException] = []
        loop = asyncio.new_event_loop()

        def run() -> None:
            asyncio.set_event_loop(loop)
            granted, self.thread_scheduling = promote_current_thread(rt_priority)
            if rt_priority and not granted:
                log.warning("Modbus face thread: %s", self.thread_scheduling)
            try:
                loop.run_until_complete(self.start())
            except BaseException as e:  # noqa: BLE001 - handed to the caller below
                failure.append(e)
                ready.set()
                loop.close()
                return
            ready.set()
            loop.run_forever()
            loop.run_until_complete(loop.shutdown_asyncgens())
            loop.close()

        self._thread = threading.Thread(target=run, name="modbus-face", daemon=True)
        self._thread.start()
        ready.wait()
        if failure:
            self._thread.join()
            self._thread = None
            raise failure[0]
        return self

    def stop_thread(self, timeout: float = 5.0) -> None:
        """Stop a face started with `start_in_thread` and join its thread."""
        thread, self._thread = self._thread, None
        if thread is None:
            return
        loop = self._loop
        assert loop is not None
        asyncio.run_coroutine_threadsafe(self.stop(), loop).result(timeout)
        loop.call_soon_threadsafe(loop.stop)
        thread.join(timeout)

    def __enter__(self) -> ModbusFace:
        return self.start_in_thread()

    def __exit__(self, *exc: object) -> None:
        self.stop_thread()

    # -- internals ----------------------------------------------------------------------

    async def _sweep(self) -> None:
        """Close connections stuck on a partial frame or idle too long."""
        limits = [self.frame_timeout] + ([self.idle_timeout] if self.idle_timeout else [])
        tick = max(0.005, min(limits) / 4)
        while True:
            await asyncio.sleep(tick)
            now = _monotonic()
            for conn in list(self._connections):
                if conn.partial_since is not None and now - conn.partial_since > self.frame_timeout:
                    self.stats.frame_timeouts += 1
                    log.info("%s: partial frame for %.3g s, closing", conn.peer, self.frame_timeout)
                    conn.close()
                elif self.idle_timeout and now - conn.last_rx > self.idle_timeout:
                    self.stats.idle_timeouts += 1
                    log.info("%s: idle for %.3g s, closing", conn.peer, self.idle_timeout)
                    conn.close()

    def _make_room(self, newcomer: _Connection) -> bool:
        """Evict one connection if `newcomer` would break a limit; False: no room (every
        candidate has a write answer outstanding), refuse the newcomer."""
        conns = self._connections
        same = [c for c in conns if c.address == newcomer.address]
        if len(same) >= self.max_connections_per_client:
            candidates = same
        elif len(conns) >= self.max_connections:
            # the address holding the most connections gives one up: one busy HMI host
            # cannot starve the others, and a single flooding address pays for itself
            held: dict[str, int] = {}
            for c in conns:
                held[c.address] = held.get(c.address, 0) + 1
            most = max(held.values())
            candidates = [c for c in conns if held[c.address] == most]
        else:
            return True
        evictable = [c for c in candidates if not c._waiting]
        if not evictable:
            return False
        victim = min(evictable, key=_Connection.last_active)
        conns.discard(victim)
        self.stats.connections_open -= 1
        self.stats.connections_evicted += 1
        log.warning(
            "%s: evicted (idle %.3g s) to admit %s",
            victim.peer,
            _monotonic() - victim.last_active(),
            newcomer.peer,
        )
        victim.close()
        return True


def _peer_allowed(peer, networks) -> bool:
    try:
        address = ipaddress.ip_address(peer[0])
    except (TypeError, ValueError, IndexError):
        return False
    return any(address in net for net in networks)


class _Connection(asyncio.Protocol):
    """One client. Frames are answered in arrival order."""

    def __init__(self, face: ModbusFace) -> None:
        self.face = face
        self.stats = face.stats
        self.handler = face.handler
        self.get_snapshot = face.get_snapshot
        self.writes = face.writes
        self.unit_id = face.unit_id
        self.decoder = MbapDecoder()
        self.transport: asyncio.Transport | None = None
        self.peer = "?"
        self.address = "?"
        self.last_rx = 0.0
        self.partial_since: float | None = None
        self.closed = False
        self._backlog: deque = deque()
        self._waiting = False  # ack-after-scan: a write response is outstanding
        self._write_paused = False
        self._fast = not face.ack_after_scan
        self._read_segments = face._read_segments
        self._gate = face.scan_gate
        self._loop = asyncio.get_running_loop()

    # -- asyncio.Protocol -------------------------------------------------------------

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = transport  # type: ignore[assignment]
        peer = transport.get_extra_info("peername")
        self.peer = f"{peer[0]}:{peer[1]}" if peer else "?"
        self.address = str(peer[0]) if peer else "?"
        self.last_rx = _monotonic()
        face = self.face
        if face.allowed_clients is not None and not _peer_allowed(peer, face.allowed_clients):
            self.stats.connections_refused += 1
            log.warning("%s: refused, not in allowed_clients", self.peer)
            self.closed = True
            transport.close()
            return
        if not face._make_room(self):
            self.stats.connections_refused += 1
            log.warning(
                "%s: refused, %d connections open, each awaiting a write answer",
                self.peer,
                len(face._connections),
            )
            self.closed = True
            transport.close()
            return
        face._connections.add(self)
        self.stats.connections_open += 1
        self.stats.connections_total += 1

    def last_active(self) -> float:
        """When this client last completed a request (or connected): a trickled partial
        frame does not count as activity."""
        return self.partial_since if self.partial_since is not None else self.last_rx

    def connection_lost(self, exc: Exception | None) -> None:
        if self in self.face._connections:
            self.face._connections.discard(self)
            self.stats.connections_open -= 1
        self.closed = True
        self._backlog.clear()

    def pause_writing(self) -> None:
        # The client does not read its answers: stop reading its requests (bounded memory).
        self._write_paused = True
        self._update_reading()

    def resume_writing(self) -> None:
        self._write_paused = False
        self._update_reading()

    def data_received(self, data: bytes) -> None:
        if self.closed:
            return
        self.last_rx = now = _monotonic()
        gate = self._gate
        if gate is not None and now >= gate.step_aside_at:
            gate.step_aside(now)  # let the due scan have the GIL; answer right after it
        n = len(data)
        # Fast path, the normal case of a polling client: exactly one whole, well-formed
        # frame at a frame boundary. Anything else takes the general decoder below.
        if (
            self._fast
            and self.partial_since is None
            and 8 <= n <= MAX_ADU
            and not (data[2] or data[3])
            and (data[4] << 8 | data[5]) == n - 6
        ):
            if n == 12 and (answer := self._read_registers_fast(data)) is not None:
                self.stats.requests += 1
                self.transport.write(answer)
                return
            try:
                response, _ = self._answer(data[6], data[7:])
            except PduSizeError as e:
                self._violation(str(e))
                return
            self.transport.write(
                data[:4] + (len(response) + 1).to_bytes(2, "big") + data[6:7] + response
            )
            return
        try:
            frames = self.decoder.feed(data)
        except FrameViolation as e:
            if e.frames and not self._waiting:
                self._serve(e.frames)
            self._violation(str(e))
            return
        if self.decoder.pending:
            if self.partial_since is None:
                self.partial_since = now
        else:
            self.partial_since = None
        if not frames:
            return
        if self._waiting:
            self._backlog.extend(frames)
            self._update_reading()
            return
        self._serve(frames)

    def _read_registers_fast(self, data: bytes) -> bytes | None:
        """The whole answer ADU to a plain FC03/FC04 request inside one image area, or None
        to take the general path (exceptions, area crossings, unit filter, odd values).

        A polling HMI sends little else, so this skips the PDU dispatch and packs the MBAP
        header and the registers with one precompiled struct per register count."""
        segments = self._read_segments.get(data[7])
        if segments is None:
            return None
        unit = data[6]
        if self.unit_id is not None and unit != self.unit_id and unit != 0xFF:
            return None
        address = data[8] << 8 | data[9]
        count = data[10] << 8 | data[11]
        if not 1 <= count <= MAX_READ_REGISTERS:
            return None
        for start, end, attr in segments:
            if start <= address and address + count <= end:
                i = address - start
                try:
                    words = getattr(self.get_snapshot(), attr)[i : i + count]
                    if len(words) != count:  # snapshot smaller than the map: general path
                        return None
                    return _READ_ANSWER[count](
                        data[:4], 3 + 2 * count, unit, data[7], 2 * count, *words
                    )
                except struct.error:  # a value outside INT: the general path wraps or refuses
                    return None
                except Exception:  # a bug must cost one answer, never the server
                    self.stats.internal_errors += 1
                    self.stats.exceptions += 1
                    log.exception("%s: internal error on PDU %s", self.peer, data[7:].hex())
                    return encode(
                        data[0] << 8 | data[1], unit, bytes((data[7] | 0x80, SERVER_DEVICE_FAILURE))
                    )
        return None

    # -- serving ------------------------------------------------------------------------

    def _serve(self, frames) -> None:
        out = []
        ack_after_scan = self.face.ack_after_scan
        frames = deque(frames)
        while frames:
            tid, unit, pdu = frames.popleft()
            try:
                response, batch = self._answer(unit, pdu)
            except PduSizeError as e:
                if out:
                    self.transport.write(b"".join(out))
                self._violation(str(e))
                return
            if batch is not None and ack_after_scan:
                if out:
                    self.transport.write(b"".join(out))
                self._backlog.extend(frames)
                self._waiting = True
                self._update_reading()
                task = self._loop.create_task(self._answer_after_scan(tid, unit, pdu))
                self.face._tasks.add(task)
                task.add_done_callback(self.face._tasks.discard)
                return
            out.append(encode(tid, unit, response))
        if out:
            self.transport.write(out[0] if len(out) == 1 else b"".join(out))

    def _answer(self, unit: int, pdu: bytes):
        stats = self.stats
        stats.requests += 1
        if self.unit_id is not None and unit != self.unit_id and unit != 0xFF:
            stats.exceptions += 1
            return bytes((pdu[0] | 0x80, GATEWAY_TARGET_FAILED)), None
        try:
            response, batch = self.handler.handle(pdu, self.get_snapshot())
            if batch is not None:
                self.writes.put(batch)
        except PduSizeError:
            raise
        except Exception:  # a bug must cost one answer, never the server
            stats.internal_errors += 1
            log.exception("%s: internal error on PDU %s", self.peer, pdu.hex())
            response, batch = bytes((pdu[0] | 0x80, SERVER_DEVICE_FAILURE)), None
        if response[0] & 0x80:
            stats.exceptions += 1
        elif batch is not None:
            stats.write_batches += 1
            if audit.isEnabledFor(logging.INFO):
                audit.info(
                    "%s unit %d fc %d: %s",
                    self.peer,
                    unit,
                    pdu[0],
                    "; ".join(f"%{w.area}[{w.index}]={list(w.values)}" for w in batch),
                )
        return response, batch

    async def _answer_after_scan(self, tid: int, unit: int, pdu: bytes) -> None:
        """Wait until a scan that certainly applied the batch has published, then answer.

        The scan that published snapshot M (read after the put) may be followed by scan M+1
        that drained the queue just before the put; scan M+2 drains after it. So M+2 is the
        first snapshot sure to include the batch.
        """
        try:
            response = await self._response_after_scan(pdu)
        except Exception:  # a failing snapshot source must not leave the client waiting
            self.stats.internal_errors += 1
            log.exception("%s: waiting for the scan failed", self.peer)
            response = bytes((pdu[0] | 0x80, SERVER_DEVICE_FAILURE))
        if self.closed:
            return
        self.transport.write(encode(tid, unit, response))
        self._waiting = False
        backlog = list(self._backlog)
        self._backlog.clear()
        self._update_reading()
        if backlog:
            self._serve(backlog)

    async def _response_after_scan(self, pdu: bytes) -> bytes:
        get = self.get_snapshot
        target = get().scan + 2
        deadline = _monotonic() + self.face.ack_timeout
        while (snap := get()).scan < target:
            if _monotonic() > deadline or self.closed:
                self.stats.exceptions += 1
                return bytes((pdu[0] | 0x80, SERVER_DEVICE_FAILURE))
            await asyncio.sleep(0.0005)
        if pdu[0] == 0x17:  # FC23's read half shows the image after its write
            return self.handler.handle(pdu, snap)[0]
        return pdu if pdu[0] in (0x05, 0x06) else pdu[:5]

    def _update_reading(self) -> None:
        if self.closed or self.transport is None:
            return
        if self._write_paused or len(self._backlog) > _MAX_BACKLOG:
            self.transport.pause_reading()
        else:
            self.transport.resume_reading()

    def _violation(self, reason: str) -> None:
        self.stats.protocol_errors += 1
        log.warning("%s: %s; closing the connection", self.peer, reason)
        self.close()

    def close(self) -> None:
        if not self.closed and self.transport is not None:
            self.closed = True
            self.transport.close()
