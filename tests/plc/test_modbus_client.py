"""The well-formed side with a real pymodbus client, and the write path through the scan."""

from __future__ import annotations

import asyncio
import select
import struct
import time

import pytest
from pymodbus.client import AsyncModbusTcpClient, ModbusTcpClient

from plc.image import ImageSize
from plc.modbus import ModbusFace
from tests.plc.conftest import FakeScan

WRITABLE = "coil:0-15,%MX0.0-%MX1.7,hr:0-9,%MW0-%MW99"


@pytest.fixture
def face_and_plc(start_face):
    face, plc = start_face(writable=WRITABLE)
    img = plc.image
    img.qx[0:4] = [True, False, True, True]
    img.ix[0:3] = [False, True, True]
    img.iw[0:3] = [-1, 0, 32767]
    img.qw[0:3] = [-32768, 5, 6]
    img.mw[0] = 4242
    img.mx[3] = True
    plc.scan()
    return face, plc


@pytest.fixture
def client(face_and_plc):
    face, _ = face_and_plc
    c = ModbusTcpClient("127.0.0.1", port=face.bound_port, timeout=3, retries=0)
    assert c.connect()
    yield c
    c.close()


def test_read_coils(client):
    assert client.read_coils(0, count=4).bits[:4] == [True, False, True, True]


def test_read_mx_coils_at_offset_8192(client):
    assert client.read_coils(8192, count=8).bits == [False] * 3 + [True] + [False] * 4


def test_read_discrete_inputs(client):
    assert client.read_discrete_inputs(0, count=3).bits[:3] == [False, True, True]


def test_read_input_registers_two_complement(client):
    assert client.read_input_registers(0, count=3).registers == [0xFFFF, 0, 0x7FFF]


def test_read_holding_registers_qw_and_mw(client):
    assert client.read_holding_registers(0, count=3).registers == [0x8000, 5, 6]
    assert client.read_holding_registers(1024, count=1).registers == [4242]


def test_write_coil_visible_after_one_scan(client, face_and_plc):
    _, plc = face_and_plc
    r = client.write_coil(1, True)
    assert not r.isError() and r.bits[0] is True
    assert client.read_coils(1, count=1).bits[0] is False  # queued, not yet applied
    plc.scan()
    assert client.read_coils(1, count=1).bits[0] is True
    assert plc.image.qx[1] is True


def test_write_register_echo_and_sign(client, face_and_plc):
    _, plc = face_and_plc
    r = client.write_register(2, 0xFFFF)
    assert not r.isError() and r.registers == [0xFFFF]
    plc.scan()
    assert plc.image.qw[2] == -1


def test_write_coils_and_registers(client, face_and_plc):
    _, plc = face_and_plc
    assert not client.write_coils(8, [True, True, False, True]).isError()
    assert not client.write_registers(1024 + 10, [1, 2, 3]).isError()
    plc.scan()
    assert plc.image.qx[8:12] == [True, True, False, True]
    assert plc.image.mw[10:13] == [1, 2, 3]


def test_readwrite_registers(client, face_and_plc):
    _, plc = face_and_plc
    r = client.readwrite_registers(read_address=0, read_count=2, write_address=1030, values=[9, 8])
    assert r.registers == [0x8000, 5]
    plc.scan()
    assert client.read_holding_registers(1030, count=2).registers == [9, 8]


def test_write_spanning_two_areas_is_one_batch_applied_at_once(start_face):
    face, plc = start_face(writable="hr:1020-1030")
    with ModbusTcpClient("127.0.0.1", port=face.bound_port, retries=0) as c:
        assert not c.write_registers(1022, [1, 2, 3, 4]).isError()
    [batch] = plc.scan()
    assert [(w.area, w.index, w.values) for w in batch] == [("QW", 1022, (1, 2)), ("MW", 0, (3, 4))]
    assert plc.snap.qw[1022:] == (1, 2) and plc.snap.mw[:2] == (3, 4)


def test_device_information_vendor(client):
    r = client.read_device_information()
    assert r.information[0] == b"fmscell"


@pytest.mark.parametrize(
    ("call", "code"),
    [
        (lambda c: c.read_holding_registers(5000, count=1), 2),
        (lambda c: c.read_coils(1024, count=1), 2),
        (lambda c: c.write_register(50, 1), 2),
        (lambda c: c.write_coil(16, True), 2),
        (lambda c: c.write_registers(8, [1, 2, 3]), 2),
        (lambda c: c.read_input_registers(1024, count=1), 2),
    ],
    ids=["read-unmapped", "read-coil-gap", "fc06-ro", "fc05-ro", "fc16-partly-ro", "ir-end"],
)
def test_exceptions_seen_by_pymodbus(client, call, code):
    r = call(client)
    assert r.isError() and r.exception_code == code


def test_refused_writes_never_change_read_only_values(client, face_and_plc):
    _, plc = face_and_plc
    before = plc.snap
    for _ in range(20):
        client.write_register(9 + 1, 1)  # hr 10: read-only
        client.write_registers(1024 + 99, [1, 2])  # %MW99 writable, %MW100 not
        client.write_coil(16, True)
        client.write_coils(14, [True] * 4)
        client.write_coil(8192 + 16, True)  # %MX2.0
        client.readwrite_registers(read_address=0, read_count=1, write_address=9, values=[1, 1])
    assert plc.queue.drain() == []
    plc.scan()
    after = plc.snap
    assert (after.qx, after.mx, after.qw, after.mw) == (before.qx, before.mx, before.qw, before.mw)


def test_async_client_against_async_face():
    plc = FakeScan(ImageSize(qw=16, mw=16, qx=16, mx=16, ix=16, iw=16))
    plc.image.qw[0] = 123
    plc.scan()

    async def run() -> list[int]:
        async with ModbusFace(plc.get_snapshot, plc.queue, plc.image.size, port=0) as face:
            client = AsyncModbusTcpClient("127.0.0.1", port=face.bound_port, retries=0)
            await client.connect()
            try:
                r = await client.read_holding_registers(0, count=2)
                bad = await client.read_holding_registers(16, count=1)  # %QW16: none with qw=16
                assert bad.isError() and bad.exception_code == 2
                return r.registers
            finally:
                client.close()

    assert asyncio.run(run()) == [123, 0]


def _answer_ready(sock, timeout: float) -> bool:
    return bool(select.select([sock], [], [], timeout)[0])


def _wait_queued(face, batches: int) -> None:
    """Synchronise with the server thread (not with a simulation): the write is queued."""
    deadline = time.monotonic() + 3
    while face.stats.write_batches < batches:
        assert time.monotonic() < deadline, "write never queued"
        time.sleep(0.001)


def test_ack_after_scan_answers_only_once_applied(start_face, raw_clients):
    face, plc = start_face(writable="hr:0-9", ack_after_scan=True)
    c = raw_clients(face.bound_port)
    c.send(c.frame(struct.pack(">BHH", 6, 3, 77)))
    c.send(c.frame(struct.pack(">BHH", 3, 3, 1)))  # queued behind the write, answered after
    _wait_queued(face, 1)
    assert not _answer_ready(c.sock, 0.05)
    plc.scan()
    plc.scan()
    assert c.receive()[2] == struct.pack(">BHH", 6, 3, 77)
    assert c.receive()[2] == b"\x03\x02\x00\x4d"  # reads the applied value
    assert plc.image.qw[3] == 77


def test_ack_after_scan_fc23_reads_after_write(start_face, raw_clients):
    face, plc = start_face(writable="hr:0-9", ack_after_scan=True)
    c = raw_clients(face.bound_port)
    c.send(c.frame(struct.pack(">BHHHHBH", 23, 0, 1, 0, 1, 2, 55)))
    _wait_queued(face, 1)
    plc.scan()
    plc.scan()
    assert c.receive()[2] == b"\x17\x02\x00\x37"


def test_ack_after_scan_without_scans_is_exception_04(start_face, raw_clients):
    face, plc = start_face(writable="hr:0-9", ack_after_scan=True, ack_timeout=0.05)
    c = raw_clients(face.bound_port)
    assert c.request(struct.pack(">BHH", 6, 0, 1)) == b"\x86\x04"
    assert len(plc.queue.drain()) == 1  # still queued: the PLC applies it when it scans


def test_stop_while_a_write_waits_for_its_scan(start_face, raw_clients):
    face, plc = start_face(writable="hr:0-9", ack_after_scan=True, ack_timeout=30)
    c = raw_clients(face.bound_port)
    c.send(c.frame(struct.pack(">BHH", 6, 0, 1)))
    _wait_queued(face, 1)
    face.stop_thread()  # must not hang on the waiting answer
    assert c.closed_by_server()
    assert face._tasks == set()


def test_failing_snapshot_source_costs_one_answer_not_the_server(start_face, raw_clients):
    plc = FakeScan()
    calls = {"n": 0}

    def flaky():
        calls["n"] += 1
        if calls["n"] == 2:  # the first call is the start-up size check
            raise RuntimeError("image lock lost")
        return plc.snap

    face = ModbusFace(flaky, plc.queue, port=0)
    with face:
        c = raw_clients(face.bound_port)
        assert c.request(b"\x03\x00\x00\x00\x01") == b"\x83\x04"
        assert c.request(b"\x03\x00\x00\x00\x01") == b"\x03\x02\x00\x00"
        assert face.stats.internal_errors == 1
