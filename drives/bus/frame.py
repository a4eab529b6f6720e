"""Bit-exact classic CAN frame lengths (ISO 11898-1), bit stuffing included.

The stuffed length depends on the identifier and the payload, so it is computed on the real
bit stream SOF..CRC with the real CRC-15 rather than from the worst-case formula; the formula
is kept for load planning, where the payload is not known yet.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Final

CRC15_POLY: Final = 0x4599
# CRC delimiter 1 + ACK slot 1 + ACK delimiter 1 + EOF 7 + intermission 3: never stuffed.
TRAILER_BITS: Final = 13


def crc15(bits: list[int]) -> int:
    """CAN CRC-15 (polynomial 0x4599, initial 0) over a list of 0/1 bits."""
    crc = 0
    for bit in bits:
        crc_next = bit ^ ((crc >> 14) & 1)
        crc = (crc << 1) & 0x7FFF
        if crc_next:
            crc ^= CRC15_POLY
    return crc


def _bits(value: int, width: int) -> list[int]:
    return [(value >> (width - 1 - i)) & 1 for i in range(width)]


def unstuffed_bits(
    can_id: int,
    data: bytes,
    *,
    extended: bool = False,
    remote: bool = False,
    dlc: int | None = None,
) -> list[int]:
    """The bit stream SOF..CRC (the stuffed part of the frame) before stuffing."""
    if dlc is None:
        dlc = len(data)
    if not 0 <= dlc <= 15:
        raise ValueError(f"DLC {dlc} outside 0..15")
    if remote:
        data = b""
    elif len(data) > 8:
        raise ValueError(f"classic CAN data field of {len(data)} bytes (max 8)")
    bits = [0]  # SOF is dominant
    if extended:
        if not 0 <= can_id < 1 << 29:
            raise ValueError(f"29-bit identifier 0x{can_id:X} out of range")
        bits += _bits(can_id >> 18, 11)  # base identifier
        bits += [1, 1]  # SRR, IDE (both recessive)
        bits += _bits(can_id & 0x3FFFF, 18)  # identifier extension
        bits += [1 if remote else 0, 0, 0]  # RTR, r1, r0
    else:
        if not 0 <= can_id < 1 << 11:
            raise ValueError(f"11-bit identifier 0x{can_id:X} out of range")
        bits += _bits(can_id, 11)
        bits += [1 if remote else 0, 0, 0]  # RTR, IDE, r0
    bits += _bits(dlc, 4)
    for byte in data:
        bits += _bits(byte, 8)
    bits += _bits(crc15(bits), 15)
    return bits


def stuff_bit_count(bits: list[int]) -> int:
    """Stuff bits the transmitter inserts: one after every 5 equal bits, counting stuff bits."""
    count = 0
    run_bit = -1
    run = 0
    for bit in bits:
        if bit == run_bit:
            run += 1
        else:
            run_bit, run = bit, 1
        if run == 5:
            count += 1
            # The stuff bit is the complement and starts a new run of length 1.
            run_bit, run = 1 - bit, 1
    return count


def stuffed_bitstream(bits: list[int]) -> list[int]:
    """The bits as they appear on the wire (for hand-checking test vectors)."""
    out: list[int] = []
    run_bit = -1
    run = 0
    for bit in bits:
        out.append(bit)
        if bit == run_bit:
            run += 1
        else:
            run_bit, run = bit, 1
        if run == 5:
            out.append(1 - bit)
            run_bit, run = 1 - bit, 1
    return out


def _crc15_table() -> list[int]:
    table = []
    for byte in range(256):
        crc = byte << 7
        for _ in range(8):
            crc = ((crc << 1) ^ CRC15_POLY) if crc & 0x4000 else (crc << 1)
            crc &= 0x7FFF
        table.append(crc)
    return table


_CRC_TABLE: Final = _crc15_table()


def _stuff_table(width: int) -> list[int]:
    """Stuffing as a state machine over `width`-bit chunks.

    A state is the current run: (bit << 2) | (length - 1), length 1..4 (a run of 5 is stuffed
    at once and the stuff bit starts a run of 1 of the other value). Entry
    `table[state << width | chunk]` is `stuff_bits << 3 | next_state`.
    """
    table = []
    for state in range(8):
        for chunk in range(1 << width):
            run_bit, run = state >> 2, (state & 3) + 1
            stuff = 0
            for i in range(width - 1, -1, -1):
                bit = (chunk >> i) & 1
                if bit == run_bit:
                    run += 1
                else:
                    run_bit, run = bit, 1
                if run == 5:
                    stuff += 1
                    run_bit, run = 1 - bit, 1
            table.append(stuff << 3 | run_bit << 2 | (run - 1))
    return table


_STUFF8: Final = _stuff_table(8)
_STUFF7: Final = _stuff_table(7)
_STUFF1: Final = _stuff_table(1)


def _header_state(can_id: int, extended: bool, remote: bool, dlc: int) -> tuple[int, int, int, int]:
    """(CRC, stuff state, stuff bits, header bits) after the header SOF..DLC.

    The header is 19 bits (11-bit ID) or 39 bits (29-bit ID); left-padded with zeros to whole
    bytes (no effect on a CRC with initial value 0) the data bytes that follow stay byte
    aligned, so a frame only runs its data bytes and the CRC through the tables.
    """
    rtr = 1 if remote else 0
    if extended:
        if not 0 <= can_id < 1 << 29:
            raise ValueError(f"29-bit identifier 0x{can_id:X} out of range")
        # SOF, base ID 11, SRR 1, IDE 1, ext ID 18, RTR, r1, r0, DLC 4
        header = ((can_id >> 18) << 27) | (0b11 << 25) | ((can_id & 0x3FFFF) << 7)
        header |= (rtr << 6) | dlc
        header_bits = 39
    else:
        if not 0 <= can_id < 1 << 11:
            raise ValueError(f"11-bit identifier 0x{can_id:X} out of range")
        header = (can_id << 7) | (rtr << 6) | dlc  # SOF, ID 11, RTR, IDE, r0, DLC 4
        header_bits = 19
    crc = 0
    for byte in header.to_bytes((header_bits + 7) // 8, "big"):
        crc = ((crc << 8) & 0x7FFF) ^ _CRC_TABLE[((crc >> 7) ^ byte) & 0xFF]
    state = stuff = 0  # the SOF (0) starts the first run
    for i in range(header_bits - 2, -1, -1):
        entry = _STUFF1[state << 1 | (header >> i) & 1]
        stuff += entry >> 3
        state = entry & 7
    return crc, state, stuff, header_bits


_HEADERS: Final[dict[tuple[int, bool, bool, int], tuple[int, int, int, int]]] = {}


@lru_cache(maxsize=8192)
def frame_bits(
    can_id: int, data: bytes, extended: bool = False, remote: bool = False, dlc: int | None = None
) -> int:
    """Total bits on the wire of a data or remote frame, stuff bits and intermission included.

    Same result as `unstuffed_bits` + `stuff_bit_count` (the readable reference, kept for
    tests) but table-driven: the CRC and the stuffing state after the header are cached per
    header, then each data byte costs one CRC-table and one stuff-table lookup (stuffing is a
    run-length state machine fed a byte at a time), and the 15 CRC bits two more.
    """
    if dlc is None:
        dlc = len(data)
    if remote:
        data = b""
    elif len(data) > 8 or not 0 <= dlc <= 15:
        raise ValueError(f"classic CAN frame with {len(data)} data bytes / DLC {dlc}")
    return _bits_after_header(_header(can_id, extended, remote, dlc), data)


def data_frame_bits(can_id: int, data: bytes | bytearray, extended: bool = False) -> int:
    """`frame_bits` of a data frame (DLC = len(data) <= 8, checked by the caller), uncached.

    The bus computes this for every frame; PDO payloads (positions) rarely repeat, so a cache
    would miss and only add its own bookkeeping.
    """
    head = _HEADERS.get((can_id, extended, False, len(data)))
    if head is None:
        head = _header(can_id, extended, False, len(data))
    return _bits_after_header(head, data)


def _header(can_id: int, extended: bool, remote: bool, dlc: int) -> tuple[int, int, int, int]:
    key = (can_id, extended, remote, dlc)
    head = _HEADERS.get(key)
    if head is None:
        if len(_HEADERS) >= 4096:
            _HEADERS.clear()  # bounded: only a babbling fuzzer sees this many headers
        head = _HEADERS[key] = _header_state(can_id, extended, remote, dlc)
    return head


def _bits_after_header(head: tuple[int, int, int, int], data: bytes | bytearray) -> int:
    crc, state, stuff, header_bits = head
    crc_table, stuff8 = _CRC_TABLE, _STUFF8
    for byte in data:
        # crc is 15 bits: crc >> 7 is already one byte
        crc = ((crc << 8) & 0x7FFF) ^ crc_table[(crc >> 7) ^ byte]
        entry = stuff8[state << 8 | byte]
        stuff += entry >> 3
        state = entry & 7
    entry = _STUFF7[state << 7 | crc >> 8]
    stuff += entry >> 3
    entry = stuff8[(entry & 7) << 8 | (crc & 0xFF)]
    stuff += entry >> 3
    return header_bits + 8 * len(data) + 15 + stuff + TRAILER_BITS


def nominal_bits(data_len: int, *, extended: bool = False) -> int:
    """Frame length without any stuff bit: 47 + 8s (11-bit) or 67 + 8s (29-bit)."""
    return (67 if extended else 47) + 8 * data_len


def worst_case_bits(data_len: int, *, extended: bool = False) -> int:
    """Upper bound with maximal stuffing (Davis et al. 2007): nominal + floor((g + 8s - 1) / 4).

    g is the stuffable overhead: 34 bits for 11-bit identifiers, 54 for 29-bit identifiers.
    """
    g = 54 if extended else 34
    return nominal_bits(data_len, extended=extended) + (g + 8 * data_len - 1) // 4


ERROR_FRAME_BITS: Final = (
    6 + 8 + 3
)  # error flag, error delimiter, intermission (superposition ignored)
