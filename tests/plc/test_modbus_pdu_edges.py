"""PDU edge cases a mutation run found untested: an FC23 byte count that lies, FC43 read
device identification starting from the last object, requests ending at address 65535."""

from __future__ import annotations

import struct

import pytest

from plc.image import ImageSize, ProcessImage, Write
from plc.modbus import AllowList, ModbusMap, PduHandler
from plc.modbus.pdu import DeviceIdentity, PduSizeError

SIZE = ImageSize(ix=64, qx=64, mx=64, iw=32, qw=32, mw=32)
MAP = ModbusMap(SIZE)
HANDLER = PduHandler(MAP, AllowList.parse("coil:0-31,hr:0-15").resolve(MAP))
IMAGE = ProcessImage(SIZE)
IMAGE.qw[0:4] = [10, 11, 12, 13]
SNAP = IMAGE.snapshot(0)


def fc23(r_addr, r_count, w_addr, w_count, byte_count, data: bytes) -> bytes:
    return struct.pack(">BHHHHB", 0x17, r_addr, r_count, w_addr, w_count, byte_count) + data


# -- FC23 read/write multiple registers: the byte count ----------------------------------

FC23_CASES = [
    # (name, pdu, expected response or "size" for a closed connection, expected batch)
    (
        "honest",
        fc23(0, 2, 4, 2, 4, b"\x00\x01\xff\xff"),
        b"\x17\x04\x00\x0a\x00\x0b",
        (Write("QW", 4, (1, -1)),),
    ),
    ("count-says-1-of-2", fc23(0, 2, 4, 2, 2, b"\x00\x01"), b"\x97\x03", None),
    ("count-says-3-of-1", fc23(0, 2, 4, 1, 6, bytes(6)), b"\x97\x03", None),
    ("odd-count", fc23(0, 1, 4, 1, 3, bytes(3)), b"\x97\x03", None),
    ("count-0", fc23(0, 1, 4, 1, 0, b""), b"\x97\x03", None),
    ("count-beyond-frame", fc23(0, 1, 4, 2, 4, b"\x00\x01"), "size", None),
    ("count-short-of-frame", fc23(0, 1, 4, 1, 2, b"\x00\x01\x00\x02"), "size", None),
    ("write-count-0", fc23(0, 1, 4, 0, 0, b""), b"\x97\x03", None),
    ("write-count-122", fc23(0, 1, 0, 122, 244, bytes(244)), b"\x97\x03", None),
    ("read-count-126", fc23(0, 126, 4, 1, 2, b"\x00\x01"), b"\x97\x03", None),
    ("read-unmapped", fc23(40, 1, 4, 1, 2, b"\x00\x01"), b"\x97\x02", None),
    ("write-not-allowed", fc23(0, 1, 16, 1, 2, b"\x00\x01"), b"\x97\x02", None),
]


@pytest.mark.parametrize(
    ("pdu", "expected", "batch"),
    [c[1:] for c in FC23_CASES],
    ids=[c[0] for c in FC23_CASES],
)
def test_fc23_byte_count(pdu, expected, batch):
    if expected == "size":
        with pytest.raises(PduSizeError, match="byte count"):
            HANDLER.handle(pdu, SNAP)
        return
    assert HANDLER.handle(pdu, SNAP) == (expected, batch)


# -- FC43 / MEI 14 read device identification ------------------------------------------

IDENTITY = DeviceIdentity(
    vendor_name="V",
    product_code="PC",
    revision="1.2",
    vendor_url="http://x",
    product_name="PN",
    model_name="MN",
    user_application_name="APP",
)
ID_HANDLER = PduHandler(MAP, AllowList.parse("").resolve(MAP), IDENTITY)
OBJECTS = IDENTITY.objects()


def id_answer(code: int, ids: list[int]) -> bytes:
    body = b"".join(bytes((i, len(OBJECTS[i]))) + OBJECTS[i] for i in ids)
    return bytes((0x2B, 0x0E, code, 0x82, 0x00, 0x00, len(ids))) + body


FC43_CASES = [
    # (read code, first object id, expected object ids or an exception code)
    (1, 0, [0, 1, 2]),
    (1, 2, [2]),  # basic stream from its last object
    (1, 1, [1, 2]),
    (1, 3, [0, 1, 2]),  # beyond the basic category: restart at 0
    (2, 6, [6]),  # regular stream from its last object
    (2, 5, [5, 6]),
    (2, 7, [0, 1, 2, 3, 4, 5, 6]),  # beyond: restart
    (3, 6, [6]),
    (3, 0xFF, [0, 1, 2, 3, 4, 5, 6]),
    (4, 6, [6]),  # one specific object: the last one
    (4, 0, [0]),
    (4, 7, 0x02),  # no such object
    (0, 0, 0x03),
    (5, 0, 0x03),
]


@pytest.mark.parametrize(("code", "first", "expected"), FC43_CASES)
def test_fc43_read_device_identification(code, first, expected):
    response, batch = ID_HANDLER.handle(bytes((0x2B, 0x0E, code, first)), SNAP)
    assert batch is None
    if isinstance(expected, int):
        assert response == bytes((0xAB, expected))
    else:
        assert response == id_answer(code, expected)


def test_fc43_other_mei_type_is_illegal_function():
    assert ID_HANDLER.handle(b"\x2b\x0d\x01\x00", SNAP) == (b"\xab\x01", None)


# -- the top of the address space ----------------------------------------------------------

# areas placed so that %MX ends at coil 65535 and %MW at register 65535
TOP = ModbusMap(SIZE, mx_coil_offset=65536 - 64, mw_register_offset=65536 - 32)
TOP_HANDLER = PduHandler(TOP, AllowList.parse("coil:65500-65535,hr:65530-65535").resolve(TOP))
TOP_IMAGE = ProcessImage(SIZE)
TOP_IMAGE.mx[62:64] = b"\x01\x01"
TOP_IMAGE.mw[30:32] = [7, -2]
TOP_SNAP = TOP_IMAGE.snapshot(0)

TOP_CASES = [
    ("fc01-ends-at-65535", struct.pack(">BHH", 1, 65534, 2), b"\x01\x01\x03", None),
    ("fc01-one-past", struct.pack(">BHH", 1, 65535, 2), b"\x81\x02", None),
    ("fc01-only-65535", struct.pack(">BHH", 1, 65535, 1), b"\x01\x01\x01", None),
    ("fc03-ends-at-65535", struct.pack(">BHH", 3, 65534, 2), b"\x03\x04\x00\x07\xff\xfe", None),
    ("fc03-one-past", struct.pack(">BHH", 3, 65535, 2), b"\x83\x02", None),
    ("fc03-max-count-past", struct.pack(">BHH", 3, 65535, 125), b"\x83\x02", None),
    (
        "fc06-at-65535",
        struct.pack(">BHH", 6, 65535, 5),
        struct.pack(">BHH", 6, 65535, 5),
        (Write("MW", 31, (5,)),),
    ),
    (
        "fc16-ends-at-65535",
        struct.pack(">BHHBhh", 16, 65534, 2, 4, 1, 2),
        struct.pack(">BHH", 16, 65534, 2),
        (Write("MW", 30, (1, 2)),),
    ),
    ("fc16-one-past", struct.pack(">BHHBhh", 16, 65535, 2, 4, 1, 2), b"\x90\x02", None),
    (
        "fc15-ends-at-65535",
        struct.pack(">BHHBB", 15, 65533, 3, 1, 0b101),
        struct.pack(">BHH", 15, 65533, 3),
        (Write("MX", 61, (1, 0, 1)),),
    ),
    ("fc15-one-past", struct.pack(">BHHBB", 15, 65534, 3, 1, 0b101), b"\x8f\x02", None),
    (
        "fc23-both-end-at-65535",
        fc23(65535, 1, 65535, 1, 2, b"\x00\x09"),
        b"\x17\x02\xff\xfe",
        (Write("MW", 31, (9,)),),
    ),
    ("fc23-read-one-past", fc23(65535, 2, 65535, 1, 2, b"\x00\x09"), b"\x97\x02", None),
    ("fc23-write-one-past", fc23(65535, 1, 65535, 2, 4, bytes(4)), b"\x97\x02", None),
]


@pytest.mark.parametrize(
    ("pdu", "expected", "batch"), [c[1:] for c in TOP_CASES], ids=[c[0] for c in TOP_CASES]
)
def test_requests_at_the_top_of_the_address_space(pdu, expected, batch):
    assert TOP_HANDLER.handle(pdu, TOP_SNAP) == (expected, batch)
