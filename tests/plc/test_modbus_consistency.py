"""Every request reads one scan's snapshot: a 32-bit value over two registers is never torn.

A fake scan thread runs scans back to back (driven explicitly, no timing), each writing a
32-bit counter high word first, then doing other work, then the low word, into the live image;
a client reads both registers in a loop. Reading the live image would tear; snapshots cannot.
"""

from __future__ import annotations

import struct
import threading

from pymodbus.client import ModbusTcpClient

from tests.plc.conftest import RawClient


def _run_scans(plc, logic, stop: threading.Event) -> threading.Thread:
    def loop() -> None:
        while not stop.is_set():
            plc.scan(logic)

    t = threading.Thread(target=loop, daemon=True)
    t.start()
    return t


def test_32bit_counter_over_two_registers_never_torn(start_face):
    face, plc = start_face()
    state = {"k": 0}

    def logic(img) -> None:
        k = state["k"] = (state["k"] + 1) & 0xFFFF
        value = k * 0x00010001  # both halves equal k: any tear shows hi != lo
        img.qw[0] = struct.unpack(">h", struct.pack(">H", value >> 16))[0]
        img.mw[0:50] = [k] * 50  # work between the two halves widens the window
        img.qw[1] = struct.unpack(">h", struct.pack(">H", value & 0xFFFF))[0]

    stop = threading.Event()
    thread = _run_scans(plc, logic, stop)
    client = RawClient(face.bound_port)
    seen, torn = set(), 0
    try:
        for _ in range(3000):
            body = client.request(b"\x03\x00\x00\x00\x02")
            hi, lo = struct.unpack(">HH", body[2:])
            torn += hi != lo
            seen.add(hi)
    finally:
        stop.set()
        thread.join()
        client.close()
    assert torn == 0
    assert len(seen) > 10  # the scan really ran while we read


def test_coil_group_never_mixed_across_scans(start_face):
    face, plc = start_face()

    def logic(img) -> None:
        new = not img.qx[0]
        for i in range(16):  # one bit at a time, as rungs would
            img.qx[i] = new

    stop = threading.Event()
    thread = _run_scans(plc, logic, stop)
    mixed, seen = 0, set()
    try:
        with ModbusTcpClient("127.0.0.1", port=face.bound_port, retries=0) as c:
            for _ in range(1000):
                bits = c.read_coils(0, count=16).bits[:16]
                mixed += len(set(bits)) != 1
                seen.add(bits[0])
    finally:
        stop.set()
        thread.join()
    assert mixed == 0
    assert seen == {True, False}


def test_each_write_request_is_one_batch(start_face):
    face, plc = start_face(writable="hr:0-200")
    with ModbusTcpClient("127.0.0.1", port=face.bound_port, retries=0) as c:
        for k in range(10):
            assert not c.write_registers(0, [k] * 100).isError()
    batches = plc.queue.drain()
    assert len(batches) == 10
    assert all(len(b) == 1 and len(b[0].values) == 100 for b in batches)
    assert [b[0].values[0] for b in batches] == list(range(10))
