"""A socketcand-compatible TCP server: a CAN bus of this process for masters in another one.

socketcand (linux-can) serves SocketCAN interfaces over TCP in an ASCII protocol, and
python-can ships a client for it (`can.Bus(interface="socketcand", host=..., port=...,
channel=...)`), so a stock `canopen.Network` in another process or on another host can
reach our drives with no SocketCAN, no vcan and no root. The server speaks the part of the
protocol those clients use:

    server: < hi >                      on connect (mode NO_BUS)
    client: < open CHANNEL >            server: < ok >   (mode BCM)
    client: < rawmode >                 server: < ok >   (mode RAW: every bus frame is sent)
    server: < frame ID SECS.USECS DATA >    DATA = the bytes as contiguous hex
    client: < send ID DLC B0 B1 ... >   a frame onto the bus (in BCM and RAW mode)
    client: < echo >                    server: < echo >

An ID of 3 hex digits is an 11-bit identifier, 8 digits a 29-bit one. A command the server
does not know, or a malformed one, is answered `< error TEXT >` before RAW mode and closes
the connection in RAW mode (where python-can would read an error line as an error frame).

Each client gets its own endpoint from `open_endpoint(name)` (a `SimBus` on the hub, or any
python-can bus), so frames it sends reach every other participant but not itself, as on a
real bus. The listening socket binds 127.0.0.1 unless told otherwise: it carries unencrypted
control of the drives.
"""

from __future__ import annotations

import contextlib
import logging
import socket
import threading
import time
from collections import deque
from collections.abc import Callable

import can

from drives.errors import DrivesError

log = logging.getLogger(__name__)

DEFAULT_PORT = 29536  # socketcand's own default
# python-can's client reads the `< ok >` of `rawmode` with one recv() and compares it whole:
# a frame in the same segment would fail its handshake (SavvyCAN hit the same race with
# the real socketcand), so frames start this long after that `< ok >`.
RAW_GRACE_S = 0.2
MAX_LINE = 256  # the longest command is `< send 1FFFFFFF 8 ff ff ff ff ff ff ff ff >`
OUT_QUEUE_LIMIT = 10_000  # frames queued for a client that does not read: then it is dropped


class ProtocolError(DrivesError, ValueError):
    """A command the server cannot take."""


def format_frame(msg: can.Message) -> str:
    """`< frame 185 12.000345 2102E8030000 >` for one received frame."""
    can_id = f"{msg.arbitration_id:08X}" if msg.is_extended_id else f"{msg.arbitration_id:03X}"
    ts = max(0.0, float(msg.timestamp or 0.0))
    secs = int(ts)
    usecs = int(round((ts - secs) * 1e6))
    if usecs >= 1_000_000:
        secs, usecs = secs + 1, usecs - 1_000_000
    return f"< frame {can_id} {secs}.{usecs:06d} {bytes(msg.data).hex().upper()} >"


def parse_send(words: list[str]) -> can.Message:
    """`send ID DLC B0 ...` (the words inside `< >`) -> a frame; ProtocolError if malformed."""
    if len(words) < 3:
        raise ProtocolError("send needs an identifier and a length")
    ident, dlc_text, data_words = words[1], words[2], words[3:]
    try:
        can_id = int(ident, 16)
        dlc = int(dlc_text, 16)
        values = [int(b, 16) for b in data_words]
    except ValueError:
        raise ProtocolError(f"send: not hexadecimal in {' '.join(words[1:])!r}") from None
    if any(not 0 <= b <= 0xFF for b in values):
        raise ProtocolError("send: a data byte above ff")
    data = bytes(values)
    extended = len(ident) > 3
    if can_id > (0x1FFFFFFF if extended else 0x7FF) or can_id < 0:
        raise ProtocolError(f"send: identifier {ident} out of range")
    if not 0 <= dlc <= 8 or dlc != len(data):
        raise ProtocolError(f"send: length {dlc_text} does not match {len(data)} data bytes")
    return can.Message(arbitration_id=can_id, is_extended_id=extended, data=data)


class _Client:
    """One TCP connection: its endpoint on the bus and the frames queued for it."""

    def __init__(self, server: SocketcandServer, conn: socket.socket, peer: str) -> None:
        self.server = server
        self.conn = conn
        self.peer = peer
        self.bus: can.BusABC | None = None
        self.raw_from = 0.0  # monotonic time from which frames are forwarded (0 = not raw)
        self.out: deque[str] = deque()
        self.cond = threading.Condition()
        self.closed = False

    # -- bus -> client ---------------------------------------------------------------------
    def deliver(self, msg: can.Message) -> None:
        if not self.raw_from or msg.is_error_frame:
            return
        with self.cond:
            if len(self.out) >= OUT_QUEUE_LIMIT:
                self.closed = True  # a client that stopped reading: drop it, not the bus
            else:
                self.out.append(format_frame(msg))
            self.cond.notify()

    def writer(self) -> None:
        try:
            while True:
                with self.cond:
                    while not self.out and not self.closed:
                        self.cond.wait(0.5)
                    if self.closed:
                        return
                    wait = self.raw_from - time.monotonic()
                    if wait > 0:
                        self.cond.wait(wait)
                        continue
                    batch = "".join(self.out)
                    self.out.clear()
                self.conn.sendall(batch.encode("ascii"))
        except OSError:
            pass
        finally:
            self.close()

    def pump(self) -> None:
        """Receive loop for a bus without synchronous listeners (python-can virtual, real)."""
        bus = self.bus
        while not self.closed and bus is not None:
            try:
                msg = bus.recv(0.2)
            except (can.CanError, OSError):
                break
            if msg is not None:
                self.deliver(msg)

    # -- client -> server ------------------------------------------------------------------
    def reply(self, text: str) -> None:
        self.conn.sendall(f"< {text} >".encode("ascii"))

    def command(self, words: list[str]) -> None:
        verb = words[0] if words else ""
        if verb == "echo":
            self.reply("echo")
        elif self.bus is None:
            if verb != "open":
                raise ProtocolError(f"{verb or 'an empty command'} before open")
            if len(words) != 2 or words[1] != self.server.channel:
                raise ProtocolError(f"could not open bus {' '.join(words[1:])!r}")
            self.bus = self.server.attach(self)
            self.reply("ok")
        elif verb == "rawmode":
            self.reply("ok")
            self.raw_from = time.monotonic() + RAW_GRACE_S
        elif verb == "bcmmode":
            self.raw_from = 0.0
            self.reply("ok")
        elif verb == "send":
            self.server.frames_in += 1
            try:
                self.bus.send(parse_send(words))
            except can.CanError as exc:
                raise ProtocolError(f"send: {exc}") from None
        else:
            raise ProtocolError(f"unknown command {verb!r}")

    def serve(self) -> None:
        buf = b""
        try:
            self.reply("hi")
            while not self.closed:
                chunk = self.conn.recv(4096)
                if not chunk:
                    return
                buf += chunk
                while True:
                    start, end = buf.find(b"<"), buf.find(b">")
                    if end < 0:
                        if len(buf) > MAX_LINE:
                            raise ProtocolError("a command longer than 256 bytes")
                        break
                    line, buf = buf[start + 1 if 0 <= start < end else 0 : end], buf[end + 1 :]
                    try:
                        words = line.decode("ascii").split()
                    except UnicodeDecodeError:
                        raise ProtocolError("a non-ASCII byte in a command") from None
                    self.command(words)
        except ProtocolError as exc:
            log.info("socketcand %s: %s", self.peer, exc)
            if not self.raw_from:
                with contextlib.suppress(OSError):
                    self.reply(f"error {exc}")
        except OSError:
            pass
        finally:
            self.close()

    def close(self) -> None:
        with self.cond:
            self.closed = True
            self.cond.notify_all()
            bus, self.bus = self.bus, None
        with contextlib.suppress(OSError):
            self.conn.close()
        self.server.detach(self, bus)


class SocketcandServer:
    """Serve a CAN bus to socketcand clients.

    `open_endpoint(name)` returns a new python-can bus attached to the served bus for one
    client (`hub.endpoint` for the simulator). `channel` is the name clients `open`.
    """

    def __init__(
        self,
        open_endpoint: Callable[[str], can.BusABC],
        channel: str,
        *,
        host: str = "127.0.0.1",
        port: int = DEFAULT_PORT,
        max_clients: int = 8,
    ) -> None:
        self.open_endpoint = open_endpoint
        self.channel = channel
        self.max_clients = max_clients
        self._sock = socket.create_server((host, port), reuse_port=False)
        self._sock.settimeout(0.2)
        self.address: tuple[str, int] = self._sock.getsockname()[:2]
        self._clients: set[_Client] = set()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.frames_in = 0

    def start(self) -> SocketcandServer:
        self._thread = threading.Thread(target=self._accept, name="socketcand", daemon=True)
        self._thread.start()
        return self

    def _accept(self) -> None:
        while not self._stop.is_set():
            try:
                conn, addr = self._sock.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            client = _Client(self, conn, f"{addr[0]}:{addr[1]}")
            with self._lock:
                full = len(self._clients) >= self.max_clients
                if not full:
                    self._clients.add(client)
            if full:
                try:
                    conn.sendall(b"< error too many clients >")
                finally:
                    conn.close()
                continue
            threading.Thread(target=client.serve, name=f"socketcand {client.peer}").start()
            threading.Thread(target=client.writer, name=f"socketcand-tx {client.peer}").start()

    def attach(self, client: _Client) -> can.BusABC:
        bus = self.open_endpoint(f"socketcand {client.peer}")
        add_listener = getattr(bus, "add_listener", None)
        if add_listener is not None:
            add_listener(client.deliver)  # the simulator's endpoints deliver synchronously
        else:
            threading.Thread(target=client.pump, name=f"socketcand-rx {client.peer}").start()
        return bus

    def detach(self, client: _Client, bus: can.BusABC | None) -> None:
        with self._lock:
            self._clients.discard(client)
        if bus is not None:
            bus.shutdown()

    @property
    def clients(self) -> int:
        with self._lock:
            return len(self._clients)

    def close(self) -> None:
        self._stop.set()
        self._sock.close()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        with self._lock:
            clients = list(self._clients)
        for client in clients:
            client.close()


def parse_address(text: str) -> tuple[str, int]:
    """`HOST:PORT`, `:PORT` or `PORT` (host 127.0.0.1) -> (host, port); ValueError if not."""
    host, _, port_text = text.rpartition(":")
    try:
        port = int(port_text)
    except ValueError:
        raise ValueError(f"socketcand address {text!r}: the port is not a number") from None
    if not 0 <= port <= 65535:
        raise ValueError(f"socketcand address {text!r}: port out of range")
    return (host.strip("[]") or "127.0.0.1", port)
