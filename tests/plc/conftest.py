"""Fixtures for the Modbus face: a fake scan loop driven explicitly, and raw MBAP sockets."""

from __future__ import annotations

import socket
import struct
from collections.abc import Callable, Iterator

import pytest

from plc.image import ImageSize, ProcessImage, Snapshot, WriteQueue


class FakeScan:
    """The runtime's contract in miniature: drain the queue, run `logic`, publish a snapshot."""

    def __init__(self, size: ImageSize | None = None) -> None:
        self.image = ProcessImage(size)
        self.queue = WriteQueue()
        self.scans = 0
        self.snap = self.image.snapshot(0)

    def get_snapshot(self) -> Snapshot:
        return self.snap

    def scan(self, logic: Callable[[ProcessImage], None] | None = None) -> list:
        batches = self.queue.drain()
        for batch in batches:
            for write in batch:
                self.image.apply(write)
        if logic is not None:
            logic(self.image)
        self.scans += 1
        self.snap = self.image.snapshot(self.scans)
        return batches


class RawClient:
    """A Modbus/TCP client on a bare socket, for frames no real client would send."""

    def __init__(self, port: int, timeout: float = 3.0) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=timeout)
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.tid = 0

    def send(self, data: bytes) -> None:
        self.sock.sendall(data)

    def frame(self, pdu: bytes, unit: int = 1, pid: int = 0, length: int | None = None) -> bytes:
        self.tid = (self.tid + 1) & 0xFFFF
        n = len(pdu) + 1 if length is None else length
        return struct.pack(">HHHB", self.tid, pid, n, unit) + pdu

    def request(self, pdu: bytes, unit: int = 1) -> bytes:
        """Send one frame, return the response PDU (checking tid and unit echo)."""
        self.send(self.frame(pdu, unit))
        tid, unit_back, body = self.receive()
        assert tid == self.tid and unit_back == unit
        return body

    def receive(self) -> tuple[int, int, bytes]:
        header = self._exactly(7)
        tid, pid, length, unit = struct.unpack(">HHHB", header)
        assert pid == 0 and 2 <= length <= 254
        return tid, unit, self._exactly(length - 1)

    def _exactly(self, n: int) -> bytes:
        data = b""
        while len(data) < n:
            chunk = self.sock.recv(n - len(data))
            if not chunk:
                raise ConnectionError(f"closed after {len(data)} of {n} bytes")
            data += chunk
        return data

    def closed_by_server(self) -> bool:
        """True when the server closes without sending anything (waits up to the timeout)."""
        try:
            return self.sock.recv(1) == b""
        except ConnectionResetError:
            return True
        except TimeoutError:
            return False

    def close(self) -> None:
        self.sock.close()


@pytest.fixture
def fake_scan() -> FakeScan:
    return FakeScan()


@pytest.fixture
def start_face() -> Iterator[Callable[..., tuple]]:
    """Factory: start_face(size=None, **face_kwargs) -> (face, FakeScan); all stopped after."""
    from plc.modbus import ModbusFace

    faces = []

    def start(size: ImageSize | None = None, plc: FakeScan | None = None, **kwargs):
        plc = plc or FakeScan(size)
        kwargs.setdefault("port", 0)
        face = ModbusFace(plc.get_snapshot, plc.queue, plc.image.size, **kwargs)
        face.start_in_thread()
        faces.append(face)
        return face, plc

    yield start
    for face in faces:
        face.stop_thread()


@pytest.fixture
def raw_clients() -> Iterator[Callable[..., RawClient]]:
    clients: list[RawClient] = []

    def connect(port: int, timeout: float = 3.0) -> RawClient:
        c = RawClient(port, timeout)
        clients.append(c)
        return c

    yield connect
    for c in clients:
        c.close()
