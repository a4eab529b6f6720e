"""MBAP frame layer over raw sockets: lies, truncation, garbage, timeouts, unit ids, limits.

Every hostile case must end with the connection closed (never wedged) and the server still
answering other clients.
"""

from __future__ import annotations

import random
import socket
import struct
import threading

import pytest

from tests.plc.conftest import RawClient

FC03 = struct.pack(">BHH", 3, 0, 2)


def mbap(pdu: bytes, *, tid: int = 1, pid: int = 0, length: int | None = None, unit: int = 1):
    return struct.pack(">HHHB", tid, pid, len(pdu) + 1 if length is None else length, unit) + pdu


@pytest.fixture
def face(start_face):
    face, plc = start_face(frame_timeout=0.2, idle_timeout=None)
    plc.image.qw[0:2] = [11, -2]
    plc.scan()
    return face


def assert_still_serving(face) -> None:
    other = RawClient(face.bound_port)
    try:
        assert other.request(FC03) == b"\x03\x04\x00\x0b\xff\xfe"
    finally:
        other.close()


CLOSING = [
    ("protocol-id-1", mbap(FC03, pid=1)),
    ("protocol-id-ffff", mbap(FC03, pid=0xFFFF)),
    ("protocol-id-1-header-only", mbap(b"", pid=1, length=6)[:4]),
    ("length-0", mbap(b"", length=0)),
    ("length-1", mbap(b"", length=1)),
    ("length-255-adu-261", mbap(b"\x10" + bytes(253), length=255)),
    ("length-2000-header-only", mbap(b"", length=2000)),
    ("length-ffff", mbap(FC03, length=0xFFFF)),
    ("fc03-truncated-pdu", mbap(b"\x03\x00\x00")),
    ("fc03-pdu-too-long", mbap(FC03 + b"\x00\x00")),
    ("fc01-just-function-code", mbap(b"\x01")),
    ("fc05-short", mbap(b"\x05\x00\x00\xff")),
    ("fc06-long", mbap(b"\x06\x00\x00\x00\x01\x00")),
    ("fc15-byte-count-beyond-frame", mbap(b"\x0f\x00\x00\x00\x10\x02\xff")),
    ("fc16-byte-count-short-of-frame", mbap(b"\x10\x00\x00\x00\x02\x04" + bytes(6))),
    ("fc16-no-byte-count", mbap(b"\x10\x00\x00\x00\x02")),
    ("fc23-truncated", mbap(b"\x17\x00\x00\x00\x01\x00\x64")),
    ("fc43-long", mbap(b"\x2b\x0e\x01\x00\x00")),
    ("http-request", b"GET / HTTP/1.1\r\nHost: x\r\n\r\n"),
    ("tls-client-hello", bytes.fromhex("160301020001000200030301") + bytes(40)),
    ("valid-then-bad-protocol-id", mbap(FC03, tid=9) + mbap(FC03, tid=10, pid=2)),
]


@pytest.mark.parametrize("data", [c[1] for c in CLOSING], ids=[c[0] for c in CLOSING])
def test_malformed_frame_closes_connection(face, raw_clients, data):
    client = raw_clients(face.bound_port)
    before = face.stats.protocol_errors
    client.send(data)
    if data.startswith(mbap(FC03, tid=9)):
        assert client.receive() == (9, 1, b"\x03\x04\x00\x0b\xff\xfe")
    assert client.closed_by_server()
    assert face.stats.protocol_errors == before + 1
    assert_still_serving(face)


TIMING_OUT = [
    ("three-header-bytes", mbap(FC03)[:3]),
    ("header-without-pdu", mbap(FC03)[:7]),
    ("half-a-pdu", mbap(FC03)[:9]),
    ("fc16-missing-data", mbap(b"\x10\x00\x00\x00\x02\x04\x00\x01\x00\x02")[:-2]),
]


@pytest.mark.parametrize("data", [c[1] for c in TIMING_OUT], ids=[c[0] for c in TIMING_OUT])
def test_partial_frame_times_out(face, raw_clients, data):
    client = raw_clients(face.bound_port)
    client.send(data)
    assert client.closed_by_server()  # frame_timeout 0.2 s, socket timeout 3 s
    assert face.stats.frame_timeouts == 1
    assert_still_serving(face)


def test_idle_connection_is_closed(start_face, raw_clients):
    face, _ = start_face(idle_timeout=0.2)
    client = raw_clients(face.bound_port)
    assert client.request(FC03) == b"\x03\x04\x00\x00\x00\x00"
    assert client.closed_by_server()
    assert face.stats.idle_timeouts == 1


def test_frame_trickled_byte_by_byte_is_answered(face, raw_clients):
    client = raw_clients(face.bound_port)
    for b in mbap(FC03, tid=77):
        client.send(bytes((b,)))
    assert client.receive() == (77, 1, b"\x03\x04\x00\x0b\xff\xfe")


def test_two_frames_in_one_segment_answered_in_order(face, raw_clients):
    client = raw_clients(face.bound_port)
    client.send(mbap(FC03, tid=1) + mbap(b"\x03\x00\x01\x00\x01", tid=2))
    assert client.receive() == (1, 1, b"\x03\x04\x00\x0b\xff\xfe")
    assert client.receive() == (2, 1, b"\x03\x02\xff\xfe")


def test_hundred_pipelined_requests(face, raw_clients):
    client = raw_clients(face.bound_port)
    client.send(b"".join(mbap(FC03, tid=t) for t in range(100)))
    assert [client.receive()[0] for _ in range(100)] == list(range(100))


def test_frame_split_across_header_boundary(face, raw_clients):
    client = raw_clients(face.bound_port)
    frame = mbap(FC03, tid=5)
    client.send(frame[:5])
    client.send(frame[5:] + mbap(FC03, tid=6)[:2])
    assert client.receive()[0] == 5
    client.send(mbap(FC03, tid=6)[2:])
    assert client.receive()[0] == 6


@pytest.mark.parametrize("unit", [0, 1, 7, 247, 255])
def test_any_unit_id_is_served_and_echoed_by_default(face, raw_clients, unit):
    client = raw_clients(face.bound_port)
    assert client.request(FC03, unit=unit) == b"\x03\x04\x00\x0b\xff\xfe"


@pytest.mark.parametrize(
    ("unit", "expected"),
    [(1, b"\x03\x04\x00\x00\x00\x00"), (255, b"\x03\x04\x00\x00\x00\x00"), (7, b"\x83\x0b")],
)
def test_configured_unit_id(start_face, raw_clients, unit, expected):
    face, _ = start_face(unit_id=1)
    assert raw_clients(face.bound_port).request(FC03, unit=unit) == expected


def test_max_connections_evicts_the_idlest(start_face, raw_clients):
    """At the limit a newcomer is admitted and the least recently active connection goes
    (tests/plc/test_modbus_connection_limits.py has the per-address cases)."""
    face, _ = start_face(max_connections=3)
    clients = [raw_clients(face.bound_port) for _ in range(3)]
    for c in clients:  # clients[0] is now the least recently active
        assert c.request(FC03) == b"\x03\x04\x00\x00\x00\x00"
    extra = raw_clients(face.bound_port)
    assert extra.request(FC03) == b"\x03\x04\x00\x00\x00\x00"
    assert clients[0].closed_by_server()
    assert face.stats.connections_evicted == 1
    assert face.stats.connections_refused == 0
    assert clients[1].request(FC03) == b"\x03\x04\x00\x00\x00\x00"


def test_sixteen_concurrent_clients(start_face):
    face, plc = start_face(max_connections_per_client=16)
    plc.image.qw[0:2] = [1, 2]
    plc.scan()
    errors: list[BaseException] = []

    def work() -> None:
        try:
            c = RawClient(face.bound_port)
            for _ in range(50):
                assert c.request(FC03) == b"\x03\x04\x00\x01\x00\x02"
            c.close()
        except BaseException as e:  # noqa: BLE001 - reported by the main thread
            errors.append(e)

    threads = [threading.Thread(target=work) for _ in range(16)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    assert face.stats.requests == 16 * 50


def test_garbage_client_does_not_disturb_a_working_one(face, raw_clients):
    good = raw_clients(face.bound_port)
    assert good.request(FC03) == b"\x03\x04\x00\x0b\xff\xfe"
    rng = random.Random(1)
    for _ in range(5):
        bad = raw_clients(face.bound_port)
        bad.send(b"\x00\x01\x99" + rng.randbytes(300))
        assert bad.closed_by_server()
        assert good.request(FC03) == b"\x03\x04\x00\x0b\xff\xfe"


def test_client_that_never_reads_does_not_block_others(start_face, raw_clients):
    face, _ = start_face()
    hog = raw_clients(face.bound_port)
    hog.sock.setblocking(False)
    burst = b"".join(mbap(b"\x03\x00\x00\x00\x7d", tid=t) for t in range(2000))
    try:
        for _ in range(20):
            hog.sock.send(burst)
    except BlockingIOError:
        pass  # the server stopped reading this client: backpressure, bounded memory
    assert raw_clients(face.bound_port).request(FC03) == b"\x03\x04\x00\x00\x00\x00"


def test_hostile_fuzz_never_wedges_and_never_writes(start_face):
    """Random PDUs behind valid headers: each gets an answer with its tid or a close."""
    _fuzz(start_face, frames=400, seed=1234)


@pytest.mark.soak
def test_hostile_fuzz_soak(start_face):
    """The long run (pytest -m soak): 100k frames, same rules."""
    _fuzz(start_face, frames=100_000, seed=99)


def _fuzz(start_face, frames: int, seed: int) -> None:
    face, plc = start_face()  # read-only
    rng = random.Random(seed)
    fcs = [1, 2, 3, 4, 5, 6, 15, 16, 23, 43, 8, 0x41, 0x80, 0xFF]
    client = RawClient(face.bound_port, timeout=3.0)
    answered = closed = 0
    for tid16 in range(frames):
        tid = tid16 & 0xFFFF
        n = rng.choice([1, 2, 4, 5, 6, 7, 10, rng.randint(1, 253)])
        pdu = bytes([rng.choice(fcs)]) + rng.randbytes(n - 1)
        try:
            client.send(mbap(pdu, tid=tid, unit=rng.randint(0, 255)))
            got_tid, _, resp = client.receive()
            assert got_tid == tid
            assert resp[0] in (pdu[0], pdu[0] | 0x80)
            answered += 1
        except (ConnectionError, BrokenPipeError):
            closed += 1
            client.close()
            client = RawClient(face.bound_port)
    client.close()
    assert answered > frames // 8 and closed > frames // 8
    assert plc.queue.drain() == []
    assert face.stats.internal_errors == 0
    assert_still_serving_plain(face)


def assert_still_serving_plain(face) -> None:
    c = RawClient(face.bound_port)
    assert c.request(FC03) == b"\x03\x04\x00\x00\x00\x00"
    c.close()


def test_binds_loopback_by_default(start_face):
    face, _ = start_face()
    assert face.host == "127.0.0.1"
    with socket.create_connection(("127.0.0.1", face.bound_port), timeout=1):
        pass


@pytest.mark.parametrize(
    ("allowed", "served"),
    [(["127.0.0.1"], True), (["127.0.0.0/8", "::1"], True), (["10.0.0.0/8"], False), ([], False)],
)
def test_allowed_clients(start_face, raw_clients, allowed, served):
    face, _ = start_face(allowed_clients=allowed)
    client = raw_clients(face.bound_port)
    if served:
        assert client.request(FC03) == b"\x03\x04\x00\x00\x00\x00"
    else:
        assert client.closed_by_server()
        assert face.stats.connections_refused == 1


def test_allowed_clients_typo_is_an_error(start_face):
    with pytest.raises(ValueError, match="allowed_clients"):
        start_face(allowed_clients=["127.0.0.300"])
