"""Map, allow-list and face configuration: table-driven, with the errors users will read."""

from __future__ import annotations

import socket

import pytest

from plc.image import ImageSize, WriteQueue
from plc.modbus import AllowList, AllowListError, ModbusFace, ModbusMap
from plc.modbus.frame import FrameViolation, MbapDecoder
from tests.plc.conftest import FakeScan

MAP = ModbusMap(ImageSize())


@pytest.mark.parametrize(
    ("text", "coil", "hr"),
    [
        ("", [], []),
        ("none", [], []),
        ("coil:0-15", [(0, 16)], []),
        ("coil:3", [(3, 4)], []),
        ("hr:1024-1100", [], [(1024, 1101)]),
        ("coil:0-15,hr:1024-1100", [(0, 16)], [(1024, 1101)]),
        ("coils:0-3, co:4-7 ,holding:5", [(0, 8)], [(5, 6)]),
        ("%QX0.0-%QX1.7", [(0, 16)], []),
        ("%QX0.0-1.7", [(0, 16)], []),
        ("%QX2.3", [(19, 20)], []),
        ("%MX0.0-%MX0.7", [(8192, 8200)], []),
        ("%MW0-%MW99", [], [(1024, 1124)]),
        ("%MW0-99,%QW5", [], [(5, 6), (1024, 1124)]),
        ("%qw10-%qw12", [], [(10, 13)]),
        ("hr:0-9,hr:5-20,hr:21", [], [(0, 22)]),
        ("hr:1020-1023,%MW0-3", [], [(1020, 1028)]),
    ],
)
def test_allow_list_parses(text, coil, hr):
    guard = AllowList.parse(text).resolve(MAP)
    assert guard.ranges("coil") == coil
    assert guard.ranges("hr") == hr


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("coil", "expected TABLE:FIRST[-LAST]"),
        ("coil:0-15,,hr:1", "col 11: empty item"),
        ("coil:a-3", "first address 'a' is not a decimal number"),
        ("coil:9-3", "range end 3 is before its start 9"),
        ("di:0-3", "read-only in Modbus"),
        ("ir:0", "read-only in Modbus"),
        ("xx:0", "unknown table 'xx'"),
        ("hr:0-70000", "beyond 65535"),
        ("%IX0.0", "%IX is an input area"),
        ("%IW3", "%IW is an input area"),
        ("%QX0", "bit address needs byte.bit"),
        ("%QX0.8", "bit number 8"),
        ("%MW1.2", "word address takes no .bit"),
        ("%QW0-%MW3", "range runs from %QW into %MW"),
        ("%QZ1", "not an IEC address"),
        ("hr:0-9, %MW0-x", "col 9"),
        ("coil:0-3=0..1", "applies to registers only"),
        ("%MX0.0=0..1", "applies to registers only"),
        ("%MW0=0-200", "is not LOW..HIGH"),
        ("%MW0=", "is not LOW..HIGH"),
        ("hr:3=200..0", "not an ordered INT range"),
        ("hr:3=0..40000", "not an ordered INT range"),
    ],
)
def test_allow_list_errors(text, message):
    with pytest.raises(AllowListError) as info:
        AllowList.parse(text)
    assert message in str(info.value)
    assert str(info.value).startswith("writable:")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("hr:2048", "not (entirely) in the Modbus map"),
        ("hr:1000-1100", None),  # %QW then %MW, contiguous: fine
        ("coil:1000-1030", "not (entirely) in the Modbus map"),
        ("%MW1024", "outside the image"),
        ("%QX128.0", "outside the image"),
    ],
)
def test_allow_list_against_map(text, message):
    allow = AllowList.parse(text)
    if message is None:
        allow.resolve(MAP)
        return
    with pytest.raises(AllowListError, match=message.replace("(", r"\(").replace(")", r"\)")):
        allow.resolve(MAP)


@pytest.mark.parametrize(
    ("address", "values", "ok"),
    [
        (1024, (0,), True),
        (1024, (200,), True),
        (1024, (201,), False),
        (1024, (-1,), False),  # 65535 on the wire
        (1022, (-5, 7, 100), True),  # %QW1022..1023 take any value, %MW0 is in range
        (1022, (-5, 7, 300), False),
        (1026, (200, -9), True),  # %MW2 limited, %MW3 not
        (1030, (-100,), True),
        (1030, (-101,), False),
    ],
)
def test_allow_list_value_ranges(address, values, ok):
    guard = AllowList.parse("hr:1000-1023,%MW0-%MW2=0..200,%MW3,hr:1030=-100..100").resolve(MAP)
    assert guard.values_allowed(address, values) is ok


def test_allow_list_round_trips_as_text():
    allow = AllowList.parse("coil:0-3, %MW0-99")
    assert str(allow) == "coil:0-3,%MW0-99"
    assert AllowList.parse(str(allow)).resolve(MAP).ranges("hr") == [(1024, 1124)]
    limited = AllowList.parse("%MW0 - %MW2 = 0 .. 200")
    assert str(limited) == "%MW0-%MW2=0..200"
    assert str(AllowList.parse(str(limited))) == str(limited)


@pytest.mark.parametrize(
    ("table", "address", "count", "pieces"),
    [
        ("coil", 0, 8, [("QX", 0, 8)]),
        ("coil", 8192, 2, [("MX", 0, 2)]),
        ("coil", 1020, 10, None),
        ("hr", 1020, 8, [("QW", 1020, 4), ("MW", 0, 4)]),
        ("hr", 2047, 1, [("MW", 1023, 1)]),
        ("hr", 2047, 2, None),
        ("di", 1023, 1, [("IX", 1023, 1)]),
        ("ir", 1024, 1, None),
    ],
)
def test_map_resolves(table, address, count, pieces):
    assert MAP.resolve(table, address, count) == pieces


def test_map_refuses_overlapping_areas():
    with pytest.raises(ValueError, match="overlaps"):
        ModbusMap(ImageSize(qw=2000))
    with pytest.raises(ValueError, match="beyond address 65535"):
        ModbusMap(ImageSize(mx=60000))
    ModbusMap(ImageSize(qw=2000), mw_register_offset=4096)


def test_face_rejects_bad_configuration():
    plc = FakeScan()
    with pytest.raises(AllowListError):
        ModbusFace(plc.get_snapshot, plc.queue, writable="hr:99999")
    with pytest.raises(ValueError, match="unit_id"):
        ModbusFace(plc.get_snapshot, plc.queue, unit_id=300)
    with pytest.raises(ValueError, match="disagree"):
        ModbusFace(plc.get_snapshot, WriteQueue(), ImageSize(qw=8), mb_map=ModbusMap())


def test_port_in_use_is_reported_to_the_caller():
    plc = FakeScan()
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        face = ModbusFace(plc.get_snapshot, plc.queue, port=port)
        with pytest.raises(OSError):
            face.start_in_thread()


def test_context_manager_and_restart():
    plc = FakeScan()
    with ModbusFace(plc.get_snapshot, plc.queue, port=0) as face:
        port = face.bound_port
        assert port > 0
    with pytest.raises(RuntimeError):
        _ = face.bound_port


@pytest.mark.parametrize(
    "stream",
    [
        bytes.fromhex("0001000000060103000000010001"),  # frame + 2 bytes of the next
        bytes.fromhex("00"),
    ],
)
def test_decoder_keeps_partial_frames(stream):
    d = MbapDecoder()
    frames = d.feed(stream)
    assert d.pending == len(stream) - sum(7 + len(f[2]) for f in frames)


def test_decoder_rejects_bad_header_early():
    with pytest.raises(FrameViolation, match="protocol id 256"):
        MbapDecoder().feed(b"\x00\x01\x01\x00")
    with pytest.raises(FrameViolation, match="length 600"):
        MbapDecoder().feed(b"\x00\x01\x00\x00\x02\x58")


def test_face_refuses_a_map_larger_than_the_image():
    plc = FakeScan(ImageSize(qw=8))
    face = ModbusFace(plc.get_snapshot, plc.queue, ImageSize(), port=0)  # size forgotten
    with pytest.raises(ValueError, match="snapshot %QW has 8 entries but the map serves 1024"):
        face.start_in_thread()


def test_short_snapshot_answers_04_not_short_data():
    from plc.modbus import PduHandler

    small = FakeScan(ImageSize(qw=8, qx=8))
    handler = PduHandler(MAP, AllowList.read_only().resolve(MAP))
    assert handler.handle(b"\x03\x00\x00\x00\x0a", small.snap) == (b"\x83\x04", None)
    assert handler.handle(b"\x01\x00\x00\x00\x0a", small.snap) == (b"\x81\x04", None)
    assert handler.handle(b"\x03\x00\x00\x00\x08", small.snap)[0][:2] == b"\x03\x10"
