"""Connection limits of the Modbus face: idle connections never lock it (issue 14, item 7).

Real sockets from distinct loopback source addresses (127.0.0.x, all routed to lo on Linux)
play several hosts; the host's remote panel is a real pymodbus client on a fresh connection.
"""

from __future__ import annotations

import socket
import struct
import time

import pytest
from pymodbus.client import ModbusTcpClient

from tests.plc.conftest import RawClient

FC03 = struct.pack(">BHH", 3, 0, 2)
OK = b"\x03\x04\x00\x00\x00\x00"


class BoundRawClient(RawClient):
    """A RawClient whose socket leaves from a chosen loopback address."""

    def __init__(self, port: int, source: str, timeout: float = 3.0) -> None:
        self.sock = socket.create_connection(
            ("127.0.0.1", port), timeout=timeout, source_address=(source, 0)
        )
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.tid = 0


@pytest.fixture
def hosts():
    opened: list[RawClient] = []

    def connect(port: int, source: str = "127.0.0.1") -> RawClient:
        c = BoundRawClient(port, source)
        opened.append(c)
        return c

    yield connect
    for c in opened:
        c.close()


def panel_reads(port: int) -> list[int]:
    """What the host's remote panel does per command: a fresh pymodbus connection."""
    client = ModbusTcpClient("127.0.0.1", port=port, timeout=3, retries=0)
    try:
        assert client.connect()
        rr = client.read_holding_registers(0, count=2)
        assert not rr.isError(), rr
        return rr.registers
    finally:
        client.close()


def served(client: RawClient, expected: bytes = OK) -> bool:
    try:
        return client.request(FC03) == expected
    except (ConnectionError, OSError):
        return False


def test_sixteen_idle_connections_do_not_lock_out_the_panel(start_face, hosts):
    """The reported lockout: 16 idle connections (the default total), then the panel."""
    face, plc = start_face(max_connections_per_client=16)
    plc.image.qw[0:2] = [7, 9]
    plc.scan()
    idle = [hosts(face.bound_port) for _ in range(16)]
    for c in idle:  # really held by the face before the panel comes
        assert c.request(FC03) == b"\x03\x04\x00\x07\x00\x09"
    assert panel_reads(face.bound_port) == [7, 9]
    assert face.stats.connections_refused == 0
    assert face.stats.connections_evicted == 1
    # the idlest one (the first to have been served) made room
    assert idle[0].closed_by_server()
    assert served(idle[15], b"\x03\x04\x00\x07\x00\x09")


def test_per_address_limit_evicts_that_address_own_idlest(start_face, hosts):
    face, _ = start_face(max_connections=16, max_connections_per_client=4)
    flood = [hosts(face.bound_port, "127.0.0.2") for _ in range(4)]
    others = [hosts(face.bound_port, f"127.0.0.{3 + i}") for i in range(3)]
    for c in flood + others:
        assert c.request(FC03) == OK
    newcomer = hosts(face.bound_port, "127.0.0.2")
    assert newcomer.request(FC03) == OK
    assert flood[0].closed_by_server()  # its own oldest, not another host's
    assert all(served(c) for c in others)
    assert all(served(c) for c in flood[1:])
    assert face.stats.connections_evicted == 1
    assert face.stats.connections_open == 4 + 3


def test_total_limit_takes_from_the_address_holding_most(start_face, hosts):
    face, _ = start_face(max_connections=6, max_connections_per_client=4)
    quiet = [hosts(face.bound_port, "127.0.0.3"), hosts(face.bound_port, "127.0.0.4")]
    busy = [hosts(face.bound_port, "127.0.0.2") for _ in range(4)]
    for c in quiet + busy:  # the quiet hosts are the least recently active
        assert c.request(FC03) == OK
    assert panel_reads(face.bound_port) == [0, 0]  # from 127.0.0.1, a fifth address
    assert busy[0].closed_by_server()
    assert all(served(c) for c in quiet)
    assert face.stats.connections_open <= 6
    assert face.stats.connections_refused == 0


def test_panel_commands_keep_working_against_a_renewing_holder(start_face, hosts):
    """A holder that keeps its 16 connections alive (renewing them) cannot lock the panel
    out: every fresh panel connection gets in, many times over."""
    face, _ = start_face()
    holders = [hosts(face.bound_port, f"127.0.0.{2 + i % 4}") for i in range(16)]
    for round_ in range(5):
        for c in holders:
            served(c)  # renewal; evicted ones just fail
        assert panel_reads(face.bound_port) == [0, 0], round_
    assert face.stats.connections_refused == 0
    assert face.stats.connections_open <= 16


def test_refused_only_when_every_candidate_awaits_a_write_answer(start_face, hosts):
    """Connections with a write answer outstanding are never evicted (ack_after_scan and
    no scan running): the newcomer is then refused, the total limit holds."""
    face, _ = start_face(
        max_connections=2, ack_after_scan=True, ack_timeout=30.0, writable="%QW0-%QW9"
    )
    writers = [hosts(face.bound_port, f"127.0.0.{2 + i}") for i in range(2)]
    for c in writers:
        c.send(c.frame(struct.pack(">BHH", 6, 0, 1)))
    # both writes are queued and unanswered (no scan runs); wait until the face saw them
    deadline = time.monotonic() + 10.0
    while not (len(face._connections) == 2 and all(c._waiting for c in face._connections)):
        assert time.monotonic() < deadline, "the face never took the two writes"
        time.sleep(0.002)
    late = hosts(face.bound_port, "127.0.0.5")
    assert late.closed_by_server()
    assert face.stats.connections_refused == 1
    assert face.stats.connections_evicted == 0


def test_per_client_limit_validated():
    from plc.image import ImageSize, WriteQueue
    from plc.modbus import ModbusFace

    with pytest.raises(ValueError, match="max_connections_per_client"):
        ModbusFace(lambda: None, WriteQueue(), ImageSize(), max_connections_per_client=0)
