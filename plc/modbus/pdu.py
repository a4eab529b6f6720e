"""Modbus PDU handling, pure: (request PDU, one snapshot) in, (response PDU, write batch) out.

Checks run in the order of the Modbus Application Protocol spec (v1.1b3, §6 state diagrams):
function supported (else 01) -> quantity and byte count in range (else 03) -> every address
mapped (else 02) -> writable per the allow-list (else 02) -> execute (else 04).

A PDU whose size contradicts its own function code (a truncated FC03, an FC16 whose byte count
disagrees with the MBAP length) raises `PduSizeError`: the MBAP length or the PDU lies, the
byte stream is suspect, and the server closes the connection instead of guessing.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from plc.errors import PlcError
from plc.image import Area, Snapshot, Write
from plc.modbus.allowlist import WriteGuard
from plc.modbus.map import ModbusMap, Piece, Table

ILLEGAL_FUNCTION = 0x01
ILLEGAL_DATA_ADDRESS = 0x02
ILLEGAL_DATA_VALUE = 0x03
SERVER_DEVICE_FAILURE = 0x04
GATEWAY_TARGET_FAILED = 0x0B

MAX_READ_BITS = 2000
MAX_READ_REGISTERS = 125
MAX_WRITE_COILS = 1968
MAX_WRITE_REGISTERS = 123
MAX_RW_WRITE_REGISTERS = 121
MAX_RW_READ_REGISTERS = 125

_ADDR_QTY = struct.Struct(">HH")
_unpack_addr_qty = _ADDR_QTY.unpack_from
_FC23 = struct.Struct(">HHHHB")

#: 8 bytes of 0/1 (one per bit, LSB first) -> the packed byte, and back.
_PACK = {bytes((v >> j) & 1 for j in range(8)): v for v in range(256)}
_UNPACK = [bytes((v >> j) & 1 for j in range(8)) for v in range(256)]

Result = tuple[bytes, tuple[Write, ...] | None]


class PduSizeError(PlcError):
    """The PDU's size contradicts its function code's own fields; close the connection."""


class _Refused(Exception):
    def __init__(self, code: int) -> None:
        self.code = code


@dataclass(frozen=True, slots=True)
class DeviceIdentity:
    """Objects served by FC43/14 Read Device Identification (conformity level 0x82)."""

    vendor_name: str = "fmscell"
    product_code: str = "FMSCELL-SOFTPLC"
    revision: str = "0.1"
    vendor_url: str = ""
    product_name: str = "fmscell soft-PLC"
    model_name: str = "soft-PLC"
    user_application_name: str = ""

    def objects(self) -> dict[int, bytes]:
        values = (
            self.vendor_name,
            self.product_code,
            self.revision,
            self.vendor_url,
            self.product_name,
            self.model_name,
            self.user_application_name,
        )
        return {i: v.encode("ascii", "replace")[:64] for i, v in enumerate(values)}


class PduHandler:
    """Answers request PDUs against one map and one write allow-list."""

    def __init__(
        self, mb_map: ModbusMap, guard: WriteGuard, identity: DeviceIdentity | None = None
    ) -> None:
        self.map = mb_map
        self.guard = guard
        self._objects = (identity or DeviceIdentity()).objects()
        self._dispatch = {
            0x01: self._read_coils,
            0x02: self._read_discrete_inputs,
            0x03: self._read_holding_registers,
            0x04: self._read_input_registers,
            0x05: self._write_single_coil,
            0x06: self._write_single_register,
            0x0F: self._write_multiple_coils,
            0x10: self._write_multiple_registers,
            0x17: self._read_write_registers,
            0x2B: self._encapsulated_interface,
        }
        # Hot path: FC03 on a request inside one area skips the generic resolver.
        self._hr_fast = tuple((s.start, s.end, _LOWER[s.area]) for s in mb_map.segments("hr"))

    def handle(self, pdu: bytes, snap: Snapshot) -> Result:
        """Response PDU and the write batch to queue (None for reads and exceptions)."""
        fc = pdu[0]
        fn = self._dispatch.get(fc)
        if fn is None:
            return bytes((fc | 0x80, ILLEGAL_FUNCTION)), None
        try:
            return fn(pdu, snap)
        except _Refused as e:
            return bytes((fc | 0x80, e.code)), None

    # -- reads -------------------------------------------------------------------------

    def _read_bits(self, table: Table, pdu: bytes, snap: Snapshot) -> Result:
        _expect_size(pdu, 5)
        address, count = _unpack_addr_qty(pdu, 1)
        if not 1 <= count <= MAX_READ_BITS:
            raise _Refused(ILLEGAL_DATA_VALUE)
        bits = _gather_bits(snap, self._resolve(table, address, count))
        data = pack_bits(bits)
        return bytes((pdu[0], len(data))) + data, None

    def _read_coils(self, pdu: bytes, snap: Snapshot) -> Result:
        return self._read_bits("coil", pdu, snap)

    def _read_discrete_inputs(self, pdu: bytes, snap: Snapshot) -> Result:
        return self._read_bits("di", pdu, snap)

    def _read_holding_registers(self, pdu: bytes, snap: Snapshot) -> Result:
        if len(pdu) == 5:
            address, count = _unpack_addr_qty(pdu, 1)
            if 1 <= count <= MAX_READ_REGISTERS:
                for start, end, attr in self._hr_fast:
                    if start <= address and address + count <= end:
                        i = address - start
                        words = getattr(snap, attr)[i : i + count]
                        if len(words) == count:
                            return b"\x03" + bytes((2 * count,)) + _pack_words(words), None
        return self._read_registers("hr", pdu, snap)

    def _read_input_registers(self, pdu: bytes, snap: Snapshot) -> Result:
        return self._read_registers("ir", pdu, snap)

    def _read_registers(self, table: Table, pdu: bytes, snap: Snapshot) -> Result:
        _expect_size(pdu, 5)
        address, count = _unpack_addr_qty(pdu, 1)
        if not 1 <= count <= MAX_READ_REGISTERS:
            raise _Refused(ILLEGAL_DATA_VALUE)
        words = _gather_words(snap, self._resolve(table, address, count))
        return bytes((pdu[0], 2 * count)) + _pack_words(words), None

    # -- writes ------------------------------------------------------------------------

    def _write_single_coil(self, pdu: bytes, snap: Snapshot) -> Result:
        _expect_size(pdu, 5)
        address, value = _unpack_addr_qty(pdu, 1)
        if value not in (0x0000, 0xFF00):
            raise _Refused(ILLEGAL_DATA_VALUE)
        pieces = self._resolve_writable("coil", address, 1)
        return pdu, _bit_batch(pieces, b"\x01" if value else b"\x00")

    def _write_single_register(self, pdu: bytes, snap: Snapshot) -> Result:
        _expect_size(pdu, 5)
        (address,) = struct.unpack_from(">H", pdu, 1)
        pieces = self._resolve_writable("hr", address, 1)
        values = struct.unpack_from(">h", pdu, 3)
        self._check_values(address, values)
        return pdu, _word_batch(pieces, values)

    def _write_multiple_coils(self, pdu: bytes, snap: Snapshot) -> Result:
        byte_count = _expect_counted_size(pdu, 6)
        address, count = _unpack_addr_qty(pdu, 1)
        if not 1 <= count <= MAX_WRITE_COILS or byte_count != (count + 7) // 8:
            raise _Refused(ILLEGAL_DATA_VALUE)
        pieces = self._resolve_writable("coil", address, count)
        bits = unpack_bits(pdu[6:], count)
        return pdu[:5], _bit_batch(pieces, bits)

    def _write_multiple_registers(self, pdu: bytes, snap: Snapshot) -> Result:
        byte_count = _expect_counted_size(pdu, 6)
        address, count = _unpack_addr_qty(pdu, 1)
        if not 1 <= count <= MAX_WRITE_REGISTERS or byte_count != 2 * count:
            raise _Refused(ILLEGAL_DATA_VALUE)
        pieces = self._resolve_writable("hr", address, count)
        values = struct.unpack_from(f">{count}h", pdu, 6)
        self._check_values(address, values)
        return pdu[:5], _word_batch(pieces, values)

    def _read_write_registers(self, pdu: bytes, snap: Snapshot) -> Result:
        """FC23. The write is queued for the next scan, so the read part shows this scan's
        image, i.e. the values before the write (unless the face answers after the scan)."""
        byte_count = _expect_counted_size(pdu, 10)
        r_addr, r_count, w_addr, w_count, _ = _FC23.unpack_from(pdu, 1)
        if (
            not 1 <= r_count <= MAX_RW_READ_REGISTERS
            or not 1 <= w_count <= MAX_RW_WRITE_REGISTERS
            or byte_count != 2 * w_count
        ):
            raise _Refused(ILLEGAL_DATA_VALUE)
        read_pieces = self._resolve("hr", r_addr, r_count)
        write_pieces = self._resolve_writable("hr", w_addr, w_count)
        values = struct.unpack_from(f">{w_count}h", pdu, 10)
        self._check_values(w_addr, values)
        words = _gather_words(snap, read_pieces)
        response = bytes((0x17, 2 * r_count)) + _pack_words(words)
        return response, _word_batch(write_pieces, values)

    # -- FC43 / MEI 14 -----------------------------------------------------------------

    def _encapsulated_interface(self, pdu: bytes, snap: Snapshot) -> Result:
        if len(pdu) < 2 or pdu[1] != 0x0E:
            raise _Refused(ILLEGAL_FUNCTION)
        _expect_size(pdu, 4)
        code, object_id = pdu[2], pdu[3]
        if not 1 <= code <= 4:
            raise _Refused(ILLEGAL_DATA_VALUE)
        objects = self._objects
        if code == 4:
            if object_id not in objects:
                raise _Refused(ILLEGAL_DATA_ADDRESS)
            ids = [object_id]
        else:
            # Basic = 0..2; regular (and extended: we have no private objects) = 0..6. An id
            # outside the category restarts the stream at object 0 (spec §6.21).
            last = 2 if code == 1 else 6
            first = object_id if object_id <= last else 0
            ids = list(range(first, last + 1))
        body = b"".join(bytes((i, len(objects[i]))) + objects[i] for i in ids)
        return bytes((0x2B, 0x0E, code, 0x82, 0x00, 0x00, len(ids))) + body, None

    # -- helpers -----------------------------------------------------------------------

    def _resolve(self, table: Table, address: int, count: int) -> list[Piece]:
        if address + count > 0x10000:
            raise _Refused(ILLEGAL_DATA_ADDRESS)
        pieces = self.map.resolve(table, address, count)
        if pieces is None:
            raise _Refused(ILLEGAL_DATA_ADDRESS)
        return pieces

    def _check_values(self, address: int, values: tuple[int, ...]) -> None:
        """Refuse the whole write (03) if a value lies outside its register's listed range:
        the last check, after the address ones, like a device validating the data it took."""
        if not self.guard.values_allowed(address, values):
            raise _Refused(ILLEGAL_DATA_VALUE)

    def _resolve_writable(self, table: Table, address: int, count: int) -> list[Piece]:
        pieces = self._resolve(table, address, count)
        if not self.guard.allows(table, address, count):
            raise _Refused(ILLEGAL_DATA_ADDRESS)
        return pieces


_LOWER: dict[Area, str] = {a: a.lower() for a in ("IX", "QX", "MX", "IW", "QW", "MW")}


def _expect_size(pdu: bytes, size: int) -> None:
    if len(pdu) != size:
        raise PduSizeError(f"function {pdu[0]:#04x}: PDU of {len(pdu)} bytes, expected {size}")


def _expect_counted_size(pdu: bytes, header: int) -> int:
    """Byte count of a PDU with a `header`-byte fixed part ending in the byte count."""
    if len(pdu) < header:
        raise PduSizeError(f"function {pdu[0]:#04x}: PDU of {len(pdu)} bytes is truncated")
    byte_count = pdu[header - 1]
    if len(pdu) != header + byte_count:
        raise PduSizeError(
            f"function {pdu[0]:#04x}: byte count {byte_count} but {len(pdu) - header} "
            f"data bytes in the frame"
        )
    return byte_count


def _gather_bits(snap: Snapshot, pieces: list[Piece]) -> bytes:
    bits = b"".join(getattr(snap, _LOWER[a])[i : i + n] for a, i, n in pieces)
    if len(bits) != sum(n for _, _, n in pieces):  # snapshot smaller than the map
        raise _Refused(SERVER_DEVICE_FAILURE)
    return bits


def _gather_words(snap: Snapshot, pieces: list[Piece]) -> tuple[int, ...]:
    if len(pieces) == 1:
        area, i, n = pieces[0]
        words = getattr(snap, _LOWER[area])[i : i + n]
    else:
        words = sum((getattr(snap, _LOWER[a])[i : i + n] for a, i, n in pieces), ())
    if len(words) != sum(n for _, _, n in pieces):  # snapshot smaller than the map
        raise _Refused(SERVER_DEVICE_FAILURE)
    return words


def _pack_words(words: tuple[int, ...]) -> bytes:
    """IEC INT as unsigned 16-bit two's complement; tolerate 0..65535 too."""
    try:
        return struct.pack(f">{len(words)}h", *words)
    except struct.error:
        try:
            return struct.pack(f">{len(words)}H", *(int(w) & 0xFFFF for w in words))
        except (TypeError, ValueError):
            raise _Refused(SERVER_DEVICE_FAILURE) from None


def pack_bits(bits: bytes) -> bytes:
    """Bytes of 0/1 (one per bit) -> Modbus bit field, LSB of the first byte first."""
    pad = -len(bits) % 8
    if pad:
        bits = bits + bytes(pad)
    try:
        return bytes([_PACK[bits[i : i + 8]] for i in range(0, len(bits), 8)])
    except KeyError:
        return pack_bits(bytes(1 if b else 0 for b in bits))


def unpack_bits(data: bytes, count: int) -> bytes:
    """Modbus bit field -> `count` bytes of 0/1."""
    return b"".join([_UNPACK[b] for b in data])[:count]


def _bit_batch(pieces: list[Piece], bits: bytes) -> tuple[Write, ...]:
    batch = []
    off = 0
    for area, i, n in pieces:
        batch.append(Write(area, i, tuple(bits[off : off + n])))
        off += n
    return tuple(batch)


def _word_batch(pieces: list[Piece], values: tuple[int, ...]) -> tuple[Write, ...]:
    batch = []
    off = 0
    for area, i, n in pieces:
        batch.append(Write(area, i, values[off : off + n]))
        off += n
    return tuple(batch)
