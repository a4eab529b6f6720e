"""Modbus conformance table: one request PDU -> the exact response PDU and the queued batch.

Raw frames over a real socket against a live ModbusFace, so that every byte of every answer
(function code echo, exception code, byte counts, bit order) is pinned down. Check order is
the spec's: 01 (function) -> 03 (quantity / byte count / value) -> 02 (address, allow-list).
"""

from __future__ import annotations

import struct

import pytest

from plc.image import ImageSize, Write
from plc.modbus import ModbusFace
from tests.plc.conftest import FakeScan, RawClient

SIZE = ImageSize(ix=4096, qx=4096, mx=1024, iw=1024, qw=1024, mw=1024)
WRITABLE = "coil:0-1999,%MX0.0-%MX0.7,hr:0-9,hr:100-299,hr:1020-1023,%MW0-%MW99"


def _fill(img) -> None:
    img.qx[:] = [i % 3 == 0 for i in range(SIZE.qx)]
    img.ix[:] = [i % 2 == 1 for i in range(SIZE.ix)]
    img.mx[:] = [i % 5 == 0 for i in range(SIZE.mx)]
    img.iw[:] = [i * 30 - 15000 for i in range(SIZE.iw)]
    img.qw[:] = [i - 512 for i in range(SIZE.qw)]
    img.mw[:] = [2000 + i for i in range(SIZE.mw)]


def _ref(table: str, address: int) -> int:
    """Oracle for the map: value at a Modbus address, written out independently of plc.modbus."""
    if table == "coil":
        return int(address % 3 == 0) if address < 4096 else int((address - 8192) % 5 == 0)
    if table == "di":
        return address % 2
    if table == "ir":
        return address * 30 - 15000
    return address - 512 if address < 1024 else 2000 + address - 1024


def bits_field(table: str, address: int, count: int) -> bytes:
    out = bytearray((count + 7) // 8)
    for k in range(count):
        if _ref(table, address + k):
            out[k // 8] |= 1 << (k % 8)
    return bytes(out)


def regs_field(table: str, address: int, count: int) -> bytes:
    return b"".join(struct.pack(">H", _ref(table, address + k) & 0xFFFF) for k in range(count))


def rd(fc: int, address: int, count: int) -> bytes:
    return struct.pack(">BHH", fc, address, count)


def read_ok(fc: int, address: int, count: int) -> bytes:
    table = {1: "coil", 2: "di", 3: "hr", 4: "ir"}[fc]
    data = bits_field(table, address, count) if fc <= 2 else regs_field(table, address, count)
    return bytes((fc, len(data))) + data


def exc(fc: int, code: int) -> bytes:
    return bytes((fc | 0x80, code))


def fc05(address: int, value: int) -> bytes:
    return struct.pack(">BHH", 5, address, value)


def fc06(address: int, value: int) -> bytes:
    return struct.pack(">BHH", 6, address, value)


def fc15(address: int, bits: list[int], count: int | None = None, bc: int | None = None) -> bytes:
    data = bytearray((len(bits) + 7) // 8)
    for k, b in enumerate(bits):
        data[k // 8] |= b << (k % 8)
    count = len(bits) if count is None else count
    bc = len(data) if bc is None else bc
    return struct.pack(">BHHB", 15, address, count, bc) + bytes(data)


def fc16(address: int, values: list[int], count: int | None = None, bc: int | None = None):
    count = len(values) if count is None else count
    bc = 2 * len(values) if bc is None else bc
    return struct.pack(f">BHHB{len(values)}H", 16, address, count, bc, *values)


def fc23(ra: int, rc: int, wa: int, values: list[int], wc: int | None = None):
    wc = len(values) if wc is None else wc
    return struct.pack(f">BHHHHB{len(values)}H", 23, ra, rc, wa, wc, 2 * len(values), *values)


def echo(pdu: bytes) -> bytes:
    return pdu


def head(pdu: bytes) -> bytes:
    return pdu[:5]


W = Write
ALT = [k % 2 for k in range(1968)]

# (id, request PDU, expected response PDU, expected write batch or None)
CASES = [
    # --- FC01 read coils -----------------------------------------------------------------
    ("fc01-one", rd(1, 0, 1), read_ok(1, 0, 1), None),
    ("fc01-ten-odd-start", rd(1, 7, 10), read_ok(1, 7, 10), None),
    ("fc01-max-2000", rd(1, 0, 2000), read_ok(1, 0, 2000), None),
    ("fc01-2001-is-03", rd(1, 0, 2001), exc(1, 3), None),
    ("fc01-zero-is-03", rd(1, 0, 0), exc(1, 3), None),
    ("fc01-last-qx", rd(1, 4095, 1), read_ok(1, 4095, 1), None),
    ("fc01-gap-after-qx-is-02", rd(1, 4096, 1), exc(1, 2), None),
    ("fc01-crossing-into-gap-is-02", rd(1, 4090, 10), exc(1, 2), None),
    ("fc01-mx-first", rd(1, 8192, 16), read_ok(1, 8192, 16), None),
    ("fc01-mx-last", rd(1, 9215, 1), read_ok(1, 9215, 1), None),
    ("fc01-after-mx-is-02", rd(1, 9216, 1), exc(1, 2), None),
    ("fc01-top-address-is-02", rd(1, 65535, 1), exc(1, 2), None),
    ("fc01-zero-and-unmapped-is-03-first", rd(1, 5000, 0), exc(1, 3), None),
    # --- FC02 read discrete inputs -------------------------------------------------------
    ("fc02-one", rd(2, 1, 1), read_ok(2, 1, 1), None),
    ("fc02-max-2000-to-end", rd(2, 2096, 2000), read_ok(2, 2096, 2000), None),
    ("fc02-one-past-end-is-02", rd(2, 2097, 2000), exc(2, 2), None),
    ("fc02-2001-is-03", rd(2, 0, 2001), exc(2, 3), None),
    ("fc02-zero-is-03", rd(2, 0, 0), exc(2, 3), None),
    # --- FC03 read holding registers -----------------------------------------------------
    ("fc03-one-negative-int", rd(3, 0, 1), read_ok(3, 0, 1), None),
    ("fc03-max-125", rd(3, 0, 125), read_ok(3, 0, 125), None),
    ("fc03-126-is-03", rd(3, 0, 126), exc(3, 3), None),
    ("fc03-zero-is-03", rd(3, 0, 0), exc(3, 3), None),
    ("fc03-qw-into-mw", rd(3, 1020, 10), read_ok(3, 1020, 10), None),
    ("fc03-last-mw", rd(3, 2047, 1), read_ok(3, 2047, 1), None),
    ("fc03-past-mw-is-02", rd(3, 2048, 1), exc(3, 2), None),
    ("fc03-crossing-end-is-02", rd(3, 2040, 10), exc(3, 2), None),
    ("fc03-top-address-is-02", rd(3, 65535, 2), exc(3, 2), None),
    ("fc03-126-and-unmapped-is-03-first", rd(3, 60000, 126), exc(3, 3), None),
    # --- FC04 read input registers -------------------------------------------------------
    ("fc04-one", rd(4, 0, 1), read_ok(4, 0, 1), None),
    ("fc04-max-125-to-end", rd(4, 899, 125), read_ok(4, 899, 125), None),
    ("fc04-one-past-end-is-02", rd(4, 900, 125), exc(4, 2), None),
    ("fc04-126-is-03", rd(4, 0, 126), exc(4, 3), None),
    ("fc04-zero-is-03", rd(4, 0, 0), exc(4, 3), None),
    # --- FC05 write single coil ----------------------------------------------------------
    ("fc05-on", fc05(3, 0xFF00), fc05(3, 0xFF00), (W("QX", 3, (1,)),)),
    ("fc05-off", fc05(0, 0x0000), fc05(0, 0x0000), (W("QX", 0, (0,)),)),
    ("fc05-value-1234-is-03", fc05(3, 0x1234), exc(5, 3), None),
    ("fc05-value-0001-is-03", fc05(3, 0x0001), exc(5, 3), None),
    ("fc05-value-00ff-is-03", fc05(3, 0x00FF), exc(5, 3), None),
    ("fc05-mx-writable", fc05(8197, 0xFF00), fc05(8197, 0xFF00), (W("MX", 5, (1,)),)),
    ("fc05-mx-read-only-is-02", fc05(8200, 0xFF00), exc(5, 2), None),
    ("fc05-qx-read-only-is-02", fc05(2000, 0xFF00), exc(5, 2), None),
    ("fc05-unmapped-is-02", fc05(5000, 0xFF00), exc(5, 2), None),
    ("fc05-bad-value-unmapped-is-03-first", fc05(5000, 0x1234), exc(5, 3), None),
    ("fc05-last-writable", fc05(1999, 0xFF00), fc05(1999, 0xFF00), (W("QX", 1999, (1,)),)),
    ("fc05-top-address-is-02", fc05(65535, 0xFF00), exc(5, 2), None),
    # --- FC06 write single register ------------------------------------------------------
    ("fc06-last-writable-qw", fc06(9, 3), fc06(9, 3), (W("QW", 9, (3,)),)),
    ("fc06-top-address-is-02", fc06(65535, 3), exc(6, 2), None),
    ("fc06-ffff-is-minus-one", fc06(5, 0xFFFF), fc06(5, 0xFFFF), (W("QW", 5, (-1,)),)),
    ("fc06-8000-is-int-min", fc06(0, 0x8000), fc06(0, 0x8000), (W("QW", 0, (-32768,)),)),
    ("fc06-mw0", fc06(1024, 1234), fc06(1024, 1234), (W("MW", 0, (1234,)),)),
    ("fc06-read-only-qw-is-02", fc06(10, 1), exc(6, 2), None),
    ("fc06-read-only-mw-is-02", fc06(1124, 1), exc(6, 2), None),
    ("fc06-unmapped-is-02", fc06(3000, 1), exc(6, 2), None),
    # --- FC15 write multiple coils -------------------------------------------------------
    ("fc15-sixteen", fc15(0, ALT[:16]), head(fc15(0, ALT[:16])), (W("QX", 0, tuple(ALT[:16])),)),
    ("fc15-odd-count", fc15(5, [1, 1, 0]), head(fc15(5, [1, 1, 0])), (W("QX", 5, (1, 1, 0)),)),
    ("fc15-max-1968", fc15(0, ALT), head(fc15(0, ALT)), (W("QX", 0, tuple(ALT)),)),
    ("fc15-1969-is-03", fc15(0, ALT[:1968], count=1969), exc(15, 3), None),
    ("fc15-zero-is-03", fc15(0, [], count=0), exc(15, 3), None),
    ("fc15-byte-count-lies-is-03", fc15(0, ALT[:16] + [0] * 8, count=16), exc(15, 3), None),
    ("fc15-partly-read-only-is-02", fc15(1990, ALT[:20]), exc(15, 2), None),
    ("fc15-unmapped-is-02", fc15(5000, ALT[:8]), exc(15, 2), None),
    ("fc15-last-writable", fc15(1999, [1]), head(fc15(1999, [1])), (W("QX", 1999, (1,)),)),
    ("fc15-wraps-past-65535-is-02", fc15(65535, [1, 1]), exc(15, 2), None),
    # --- FC16 write multiple registers ---------------------------------------------------
    ("fc16-crossing-allow-list-end-is-02", fc16(9, [1, 2]), exc(16, 2), None),
    ("fc16-wraps-past-65535-is-02", fc16(65535, [1, 2]), exc(16, 2), None),
    ("fc16-two", fc16(0, [1, 0xFFFE]), head(fc16(0, [1, 2])), (W("QW", 0, (1, -2)),)),
    (
        "fc16-max-123",
        fc16(100, list(range(123))),
        head(fc16(100, list(range(123)))),
        (W("QW", 100, tuple(range(123))),),
    ),
    ("fc16-124-is-03", fc16(100, list(range(123)), count=124), exc(16, 3), None),
    ("fc16-zero-is-03", fc16(0, [], count=0), exc(16, 3), None),
    ("fc16-byte-count-lies-is-03", fc16(0, [1, 2, 3], count=2), exc(16, 3), None),
    (
        "fc16-qw-into-mw-one-batch",
        fc16(1022, [7, 8, 9, 10]),
        head(fc16(1022, [7, 8, 9, 10])),
        (W("QW", 1022, (7, 8)), W("MW", 0, (9, 10))),
    ),
    ("fc16-partly-read-only-is-02", fc16(8, [1, 2, 3]), exc(16, 2), None),
    ("fc16-unmapped-is-02", fc16(4000, [1]), exc(16, 2), None),
    # --- FC23 read/write multiple registers ----------------------------------------------
    (
        "fc23-reads-this-scan",
        fc23(0, 4, 100, [5, 6]),
        read_ok(3, 0, 4).replace(b"\x03", b"\x17", 1),
        (W("QW", 100, (5, 6)),),
    ),
    (
        "fc23-max-125-read-121-write",
        fc23(1, 125, 100, list(range(121))),
        read_ok(3, 1, 125).replace(b"\x03", b"\x17", 1),
        (W("QW", 100, tuple(range(121))),),
    ),
    ("fc23-read-126-is-03", fc23(0, 126, 100, [1]), exc(23, 3), None),
    ("fc23-write-122-is-03", fc23(0, 1, 100, list(range(121)), wc=122), exc(23, 3), None),
    ("fc23-read-zero-is-03", fc23(0, 0, 100, [1]), exc(23, 3), None),
    ("fc23-write-read-only-is-02", fc23(0, 1, 10, [1]), exc(23, 2), None),
    ("fc23-read-unmapped-is-02", fc23(3000, 1, 100, [1]), exc(23, 2), None),
    # --- unsupported functions -----------------------------------------------------------
    ("fc07-is-01", b"\x07", exc(7, 1), None),
    ("fc08-diagnostics-is-01", b"\x08\x00\x00\x12\x34", exc(8, 1), None),
    ("fc22-mask-write-is-01", b"\x16\x00\x00\xff\xff\x00\x00", exc(0x16, 1), None),
    ("fc41-openplc-debug-is-01", b"\x41\x00", exc(0x41, 1), None),
    ("fc00-is-01", b"\x00\x00\x00", exc(0, 1), None),
    ("fc-high-bit-is-01", b"\x83\x00\x00\x00\x01", exc(0x83, 1), None),
    ("fc43-mei13-canopen-is-01", b"\x2b\x0d\x00\x00", exc(0x2B, 1), None),
    # --- FC43/14 read device identification ----------------------------------------------
    (
        "fc43-basic",
        b"\x2b\x0e\x01\x00",
        b"\x2b\x0e\x01\x82\x00\x00\x03" + b"\x00\x07fmscell\x01\x0fFMSCELL-SOFTPLC\x02\x030.1",
        None,
    ),
    (
        "fc43-individual-vendor",
        b"\x2b\x0e\x04\x00",
        b"\x2b\x0e\x04\x82\x00\x00\x01\x00\x07fmscell",
        None,
    ),
    ("fc43-individual-unknown-object-is-02", b"\x2b\x0e\x04\x50", exc(0x2B, 2), None),
    ("fc43-bad-read-code-is-03", b"\x2b\x0e\x05\x00", exc(0x2B, 3), None),
]


@pytest.fixture(scope="module")
def conformance_face():
    plc = FakeScan(SIZE)
    _fill(plc.image)
    plc.scan()
    face = ModbusFace(plc.get_snapshot, plc.queue, SIZE, port=0, writable=WRITABLE)
    face.start_in_thread()
    client = RawClient(face.bound_port)
    yield client, plc
    client.close()
    face.stop_thread()


def test_table_is_big_enough():
    assert len(CASES) >= 60
    assert len({c[0] for c in CASES}) == len(CASES)


@pytest.mark.parametrize(
    ("request_pdu", "expected", "batch"), [c[1:] for c in CASES], ids=[c[0] for c in CASES]
)
def test_conformance(conformance_face, request_pdu, expected, batch):
    client, plc = conformance_face
    plc.queue.drain()
    assert client.request(request_pdu) == expected
    queued = plc.queue.drain()
    assert queued == ([batch] if batch is not None else [])


def test_fc43_regular_lists_all_seven_objects(conformance_face):
    client, _ = conformance_face
    resp = client.request(b"\x2b\x0e\x02\x00")
    assert resp[:7] == b"\x2b\x0e\x02\x82\x00\x00\x07"
    ids, off = [], 7
    while off < len(resp):
        ids.append(resp[off])
        off += 2 + resp[off + 1]
    assert ids == list(range(7))


def test_fc43_stream_from_out_of_range_object_restarts_at_zero(conformance_face):
    client, _ = conformance_face
    assert client.request(b"\x2b\x0e\x01\x05")[6:9] == b"\x03\x00\x07"
