"""PDU edge cases a mutation run found untested: an FC23 byte count that lies, FC43 read
device identification starting from the last object, requests ending at address 65535."""

from __future__ import annotations

import struct

import pytest

from plc.image import ImageSize, ProcessImage, Write
from plc.modbus import AllowList, ModbusMap, PduHandler
from plc.modbus.pdu import DeviceIdentity, PduSizeError, pack_bits

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


# -- every function against a small map, hand-computed ---------------------------------------
# Handlers are built inside the tests (not at import): a mutation run switches mutants after
# collection, and a handler built at import would keep the unmutated constructor's work.

# coils: %QX 0..15, %MX 16..31; holding registers: %QW 0..7, %MW 8..39 (the areas touch, so a
# request can run from one into the next); discrete inputs %IX 0..15; input registers %IW 0..7
SMALL = ImageSize(ix=16, qx=16, mx=16, iw=8, qw=8, mw=32)
WRITES = "coil:0-31,hr:0-13,hr:14=-5..5"  # hr 15.. read-only; hr 14 takes -5..5 only


def small_handler() -> PduHandler:
    small_map = ModbusMap(SMALL, mx_coil_offset=16, mw_register_offset=8)
    return PduHandler(small_map, AllowList.parse(WRITES).resolve(small_map))


def small_snapshot():
    img = ProcessImage(SMALL)
    img.ix[:] = [i % 3 == 0 for i in range(16)]  # bits 0,3,6 | 9,12,15 -> 0x49 0x92
    img.qx[:] = [i % 2 == 1 for i in range(16)]  # 0xAA 0xAA
    img.mx[:] = [i < 4 for i in range(16)]  # 0x0F 0x00
    img.iw[:] = [-1, 2, 300, -32768, 32767, 0, 7, 8]
    img.qw[:] = [10 * i for i in range(8)]
    img.mw[:] = [100 + i for i in range(32)]
    return img.snapshot(0)


def req(fc: int, a: int, b: int) -> bytes:
    return struct.pack(">BHH", fc, a, b)


def regs(fc: int, *words: int) -> bytes:
    return bytes((fc, 2 * len(words))) + struct.pack(f">{len(words)}h", *words)


# fmt: off
SMALL_CASES = [
    # FC01 read coils
    ("fc01-one", req(1, 0, 1), b"\x01\x01\x00", None),
    ("fc01-qx-into-mx", req(1, 14, 4), b"\x01\x01\x0e", None),  # qx14=0 qx15=1 mx0=1 mx1=1
    ("fc01-all-32", req(1, 0, 32), b"\x01\x04\xaa\xaa\x0f\x00", None),
    ("fc01-count-2000-checked-then-unmapped", req(1, 0, 2000), b"\x81\x02", None),
    ("fc01-count-2001", req(1, 0, 2001), b"\x81\x03", None),
    ("fc01-count-0", req(1, 0, 0), b"\x81\x03", None),
    # FC02 read discrete inputs
    ("fc02-all", req(2, 0, 16), b"\x02\x02\x49\x92", None),
    ("fc02-one-past", req(2, 15, 2), b"\x82\x02", None),
    # FC03 read holding registers: inside one area (fast path) and across two (general)
    ("fc03-one", req(3, 0, 1), regs(3, 0), None),
    ("fc03-inside-qw", req(3, 1, 2), regs(3, 10, 20), None),
    ("fc03-qw-into-mw", req(3, 6, 4), regs(3, 60, 70, 100, 101), None),
    ("fc03-inside-mw", req(3, 9, 2), regs(3, 101, 102), None),  # %MW1, not %MW17
    ("fc03-mw-to-its-end", req(3, 38, 2), regs(3, 130, 131), None),
    ("fc03-count-125-checked-then-unmapped", req(3, 0, 125), b"\x83\x02", None),
    ("fc03-count-126", req(3, 0, 126), b"\x83\x03", None),
    ("fc03-count-0", req(3, 0, 0), b"\x83\x03", None),
    # FC04 read input registers
    ("fc04-one", req(4, 0, 1), regs(4, -1), None),
    ("fc04-all", req(4, 0, 8), regs(4, -1, 2, 300, -32768, 32767, 0, 7, 8), None),
    ("fc04-one-past", req(4, 7, 2), b"\x84\x02", None),
    ("fc04-count-0", req(4, 0, 0), b"\x84\x03", None),
    # FC05 write single coil: only 0x0000 and 0xFF00
    ("fc05-on", req(5, 3, 0xFF00), req(5, 3, 0xFF00), (Write("QX", 3, (1,)),)),
    ("fc05-off", req(5, 17, 0x0000), req(5, 17, 0x0000), (Write("MX", 1, (0,)),)),
    ("fc05-0001", req(5, 3, 0x0001), b"\x85\x03", None),
    ("fc05-ff01", req(5, 3, 0xFF01), b"\x85\x03", None),
    ("fc05-unmapped", req(5, 32, 0xFF00), b"\x85\x02", None),
    ("fc05-last-coil", req(5, 31, 0xFF00), req(5, 31, 0xFF00), (Write("MX", 15, (1,)),)),
    # FC06 write single register: IEC INT, the listed value range
    ("fc06-minus-one", req(6, 2, 0xFFFF), req(6, 2, 0xFFFF), (Write("QW", 2, (-1,)),)),
    ("fc06-mw", req(6, 9, 7), req(6, 9, 7), (Write("MW", 1, (7,)),)),
    ("fc06-in-range", req(6, 14, 5), req(6, 14, 5), (Write("MW", 6, (5,)),)),
    ("fc06-out-of-range", req(6, 14, 6), b"\x86\x03", None),
    ("fc06-below-range", req(6, 14, 0xFFFA), b"\x86\x03", None),  # -6
    ("fc06-read-only", req(6, 15, 1), b"\x86\x02", None),
    # FC15 write multiple coils: byte count = ceil(count / 8)
    ("fc15-one", struct.pack(">BHHBB", 15, 0, 1, 1, 1), req(15, 0, 1), (Write("QX", 0, (1,)),)),
    ("fc15-qx-into-mx", struct.pack(">BHHBB", 15, 14, 4, 1, 0b1001), req(15, 14, 4),
     (Write("QX", 14, (1, 0)), Write("MX", 0, (0, 1)))),
    ("fc15-8-in-one-byte", struct.pack(">BHHBB", 15, 0, 8, 1, 0x81), req(15, 0, 8),
     (Write("QX", 0, (1, 0, 0, 0, 0, 0, 0, 1)),)),
    ("fc15-9-in-two-bytes", struct.pack(">BHHBBB", 15, 0, 9, 2, 0, 1), req(15, 0, 9),
     (Write("QX", 0, (0,) * 8 + (1,)),)),
    ("fc15-9-in-one-byte", struct.pack(">BHHBB", 15, 0, 9, 1, 0), b"\x8f\x03", None),
    ("fc15-count-0", struct.pack(">BHHB", 15, 0, 0, 0), b"\x8f\x03", None),
    ("fc15-count-1969", struct.pack(">BHHB", 15, 0, 1969, 247) + bytes(247), b"\x8f\x03", None),
    ("fc15-count-1968-checked-then-unmapped", struct.pack(">BHHB", 15, 0, 1968, 246) + bytes(246),
     b"\x8f\x02", None),
    # FC16 write multiple registers
    ("fc16-one", struct.pack(">BHHBh", 16, 0, 1, 2, -7), req(16, 0, 1), (Write("QW", 0, (-7,)),)),
    ("fc16-qw-into-mw", struct.pack(">BHHBhhh", 16, 7, 3, 6, 1, 2, 3), req(16, 7, 3),
     (Write("QW", 7, (1,)), Write("MW", 0, (2, 3)))),
    ("fc16-range-refused", struct.pack(">BHHBhh", 16, 13, 2, 4, 0, 9), b"\x90\x03", None),
    ("fc16-range-kept", struct.pack(">BHHBhh", 16, 13, 2, 4, 9, -5), req(16, 13, 2),
     (Write("MW", 5, (9, -5)),)),
    ("fc16-count-0", struct.pack(">BHHB", 16, 0, 0, 0), b"\x90\x03", None),
    ("fc16-count-124", struct.pack(">BHHB", 16, 0, 124, 248) + bytes(248), b"\x90\x03", None),
    ("fc16-count-123-checked-then-unmapped", struct.pack(">BHHB", 16, 0, 123, 246) + bytes(246),
     b"\x90\x02", None),
    # FC23 read/write: the read shows this scan's image, the write its value range
    ("fc23-across", fc23(6, 3, 12, 2, 4, b"\x00\x01\xff\xfb"), regs(0x17, 60, 70, 100),
     (Write("MW", 4, (1, -5)),)),
    ("fc23-range-refused", fc23(0, 1, 14, 1, 2, b"\x00\x06"), b"\x97\x03", None),
    ("fc23-read-125-checked-then-unmapped", fc23(0, 125, 0, 1, 2, b"\x00\x01"), b"\x97\x02", None),
    ("fc23-write-121-checked-then-unmapped", fc23(0, 1, 0, 121, 242, bytes(242)), b"\x97\x02", None),
    # FC43 without its MEI type; an unsupported function
    ("fc43-alone", b"\x2b", b"\xab\x01", None),
    ("fc08-unsupported", b"\x08\x00\x00\x00\x00", b"\x88\x01", None),
]
# fmt: on


@pytest.mark.parametrize(
    ("pdu", "expected", "batch"), [c[1:] for c in SMALL_CASES], ids=[c[0] for c in SMALL_CASES]
)
def test_every_function_against_a_small_map(pdu, expected, batch):
    assert small_handler().handle(pdu, small_snapshot()) == (expected, batch)


def test_fc03_inside_one_area_is_answered_by_the_fast_path():
    """The hot path answers a register read inside one area without the general resolver
    (the same bytes: the table above); a read across areas takes the general path."""
    handler = small_handler()

    def general(*args):
        raise AssertionError("general path taken")

    handler._read_registers = general
    snap = small_snapshot()
    assert handler.handle(req(3, 0, 1), snap)[0] == regs(3, 0)
    assert handler.handle(req(3, 8, 32), snap)[0] == regs(3, *range(100, 132))
    assert handler.handle(req(3, 9, 1), snap)[0] == regs(3, 101)
    with pytest.raises(AssertionError, match="general path"):
        handler.handle(req(3, 6, 4), snap)


def test_fc03_count_over_255_is_refused_not_read_from_a_shifted_address():
    handler = PduHandler(ModbusMap(ImageSize()), AllowList.parse("").resolve(ModbusMap()))
    snap = ProcessImage(ImageSize()).snapshot(0)
    assert handler.handle(req(3, 0, 256), snap) == (b"\x83\x03", None)
    assert handler.handle(req(3, 0, 0x0101), snap) == (b"\x83\x03", None)


@pytest.mark.parametrize(
    ("pdu", "message"),
    [
        (b"\x03\x00\x00\x00", "function 0x03: PDU of 4 bytes, expected 5"),
        (b"\x05\x00\x00\xff\x00\x00", "function 0x05: PDU of 6 bytes, expected 5"),
        (b"\x01\x00\x00\x00\x01\x00", "function 0x01: PDU of 6 bytes, expected 5"),
        (b"\x2b\x0e", "function 0x2b: PDU of 2 bytes, expected 4"),
        (b"\x10\x00\x00\x00", "function 0x10: PDU of 4 bytes is truncated"),
        (b"\x10\x00\x00\x00\x01\x02\x00", "function 0x10: byte count 2 but 1 data bytes in"),
        (b"\x0f\x00\x00\x00\x09\x02\x00\x00\x00", "function 0x0f: byte count 2 but 3 data bytes"),
    ],
)
def test_a_pdu_whose_size_lies_names_function_and_sizes(pdu, message):
    with pytest.raises(PduSizeError) as lied:
        small_handler().handle(pdu, small_snapshot())
    assert str(lied.value).startswith(message)


def test_a_snapshot_smaller_than_the_map_is_a_device_failure():
    short = ProcessImage(ImageSize(ix=8, qx=8, mx=8, iw=4, qw=4, mw=4)).snapshot(0)
    handler = small_handler()
    assert handler.handle(req(1, 0, 16), short) == (b"\x81\x04", None)
    assert handler.handle(req(3, 0, 8), short) == (b"\x83\x04", None)
    assert handler.handle(req(3, 6, 4), short) == (b"\x83\x04", None)


def test_register_values_outside_int_are_sent_as_their_16_bits():
    snap = small_snapshot()
    odd = type(snap)(snap.scan, snap.ix, snap.qx, snap.mx, (40000, 65535, -1, 0) + snap.iw[4:],
                     snap.qw, snap.mw)  # fmt: skip
    assert (
        small_handler().handle(req(4, 0, 4), odd)[0] == b"\x04\x08\x9c\x40\xff\xff\xff\xff\x00\x00"
    )
    broken = type(snap)(snap.scan, snap.ix, snap.qx, snap.mx, (None,) * 8, snap.qw, snap.mw)
    assert small_handler().handle(req(4, 0, 1), broken) == (b"\x84\x04", None)


def test_pack_bits_takes_any_nonzero_byte_as_on():
    assert pack_bits(b"\x00\x05\x00\x01") == b"\x0a"
    assert pack_bits(b"\x02" * 9) == b"\xff\x01"
    assert pack_bits(b"\x00\x00\x00\x00\x00\x00\x00\x00\x00\x07") == b"\x00\x02"


def test_identity_objects_are_ascii_and_at_most_64_bytes():
    objects = DeviceIdentity(vendor_name="Müller" + "x" * 70, model_name="é").objects()
    assert objects[0] == b"M?ller" + b"x" * 58 and len(objects[0]) == 64
    assert objects[5] == b"?"
    assert objects[1] == b"FMSCELL-SOFTPLC"


def test_fc43_of_a_handler_without_an_identity_names_fmscell():
    response, _ = small_handler().handle(b"\x2b\x0e\x04\x00", small_snapshot())
    assert response == b"\x2b\x0e\x04\x82\x00\x00\x01\x00\x07fmscell"
