"""The register-read fast path of the face answers byte for byte what the general path does.

A connection is driven without sockets (a recording transport), and every answer is compared
with `encode(tid, unit, PduHandler.handle(pdu, snapshot))`, the general path's result, for
reads inside, across and outside the areas, odd counts, unit filters and values outside INT.
"""

from __future__ import annotations

import asyncio
import struct

import pytest

from plc.image import ImageSize, ProcessImage
from plc.modbus import ModbusFace
from plc.modbus.frame import encode
from plc.modbus.server import _Connection

SIZE = ImageSize(ix=64, qx=64, mx=64, iw=40, qw=40, mw=40)


class _Recorder:
    def __init__(self) -> None:
        self.sent: list[bytes] = []
        self.closed = False

    def write(self, data: bytes) -> None:
        self.sent.append(data)

    def get_extra_info(self, key: str):
        return ("127.0.0.1", 40000) if key == "peername" else None

    def close(self) -> None:
        self.closed = True

    def pause_reading(self) -> None:
        pass

    def resume_reading(self) -> None:
        pass


def _image() -> ProcessImage:
    image = ProcessImage(SIZE)
    for area in ("iw", "qw", "mw"):
        words = getattr(image, area)
        for i in range(len(words)):
            words[i] = (i * 977 - 15000) % 65536 - 32768  # negative and positive INTs
    return image


def _answers(face: ModbusFace, frames: list[bytes]) -> list[bytes]:
    async def run() -> list[bytes]:
        conn = _Connection(face)
        transport = _Recorder()
        conn.connection_made(transport)
        for frame in frames:
            conn.data_received(frame)
        assert not transport.closed
        return transport.sent

    return asyncio.run(run())


def _request(tid: int, unit: int, fc: int, address: int, count: int) -> bytes:
    return struct.pack(">HHHBBHH", tid, 0, 6, unit, fc, address, count)


CASES = [
    (fc, address, count)
    for fc in (0x03, 0x04)
    for address, count in [
        (0, 1),
        (0, 10),
        (3, 37),
        (39, 1),
        (30, 11),  # %QW38..39 then registers 40..1023 that are not mapped: exception 02
        (1024, 40),  # %MW0..39
        (1020, 10),  # crosses unmapped 1020..1023: exception 02
        (1063, 1),
        (1064, 1),
        (0, 0),
        (0, 125),
        (0, 126),
        (65535, 2),
    ]
]


@pytest.mark.parametrize("unit_id", [None, 7])
def test_fast_reads_answer_as_the_general_path(unit_id):
    snap = _image().snapshot(3)
    face = ModbusFace(lambda: snap, None, SIZE, port=0, unit_id=unit_id)  # type: ignore[arg-type]
    frames, expected = [], []
    tid = 0
    for unit in (1, 7, 0xFF):
        for fc, address, count in CASES:
            tid += 1
            frame = _request(tid, unit, fc, address, count)
            frames.append(frame)
            if unit_id is not None and unit not in (unit_id, 0xFF):
                pdu = bytes((fc | 0x80, 0x0B))
            else:
                pdu, _ = face.handler.handle(frame[7:], snap)
            expected.append(encode(tid, unit, pdu))
    assert _answers(face, frames) == expected
    assert face.stats.requests == len(frames)
    assert face.stats.exceptions == sum(e[7] & 0x80 != 0 for e in expected)


def test_unsigned_values_in_the_image_take_the_wrapping_path():
    image = _image()
    image.qw[5] = 65535  # not an INT: the general path sends it as 0xFFFF
    image.qw[6] = 40000
    snap = image.snapshot(1)
    face = ModbusFace(lambda: snap, None, SIZE, port=0)  # type: ignore[arg-type]
    (answer,) = _answers(face, [_request(9, 1, 0x03, 4, 3)])
    assert answer == encode(9, 1, b"\x03\x06" + struct.pack(">hHH", image.qw[4], 65535, 40000))


def test_a_failing_snapshot_costs_one_exception_04():
    calls = {"n": 0}
    snap = _image().snapshot(1)

    def flaky():
        calls["n"] += 1
        if calls["n"] == 2:  # the first call is the size check that start() makes
            raise RuntimeError("snapshot lost")
        return snap

    face = ModbusFace(flaky, None, SIZE, port=0)  # type: ignore[arg-type]
    face._check_snapshot_fits()
    answers = _answers(face, [_request(1, 1, 0x03, 0, 2), _request(2, 1, 0x03, 0, 2)])
    assert answers[0] == encode(1, 1, b"\x83\x04")
    assert answers[1] == encode(2, 1, b"\x03\x04" + struct.pack(">2h", *snap.qw[:2]))
    assert face.stats.internal_errors == 1
