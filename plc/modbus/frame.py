"""Strict MBAP framing (Modbus/TCP application header), pure: bytes in, frames out.

    transaction id (2) | protocol id (2) = 0 | length (2) = 1 + len(PDU) | unit id (1) | PDU

The length field is the only thing that delimits frames on a TCP stream, so a header that
breaks a rule is a `FrameViolation` and the connection is closed: once a header lies, the
following bytes cannot be trusted to start a frame (the pymodbus 3.16 server instead keeps the
bad bytes at the head of its buffer and wedges the connection).

Rules: protocol id must be 0; length must be 2..254 (unit id + a 1..253-byte PDU, an ADU of at
most 260 bytes). Both are checked as soon as their bytes arrive, so garbage is refused at once
instead of waiting for a frame that will never complete.
"""

from __future__ import annotations

import struct

from plc.errors import PlcError

MBAP_SIZE = 7
MAX_PDU = 253
MAX_ADU = MBAP_SIZE - 1 + 1 + MAX_PDU  # 260
_HEADER = struct.Struct(">HHHB")
_pack_header = _HEADER.pack
_unpack_header = _HEADER.unpack_from

#: A decoded request: (transaction id, unit id, PDU).
Frame = tuple[int, int, bytes]


class FrameViolation(PlcError):
    """The byte stream broke an MBAP rule; the connection must be closed.

    `frames` holds the well-formed frames that preceded the bad header in the same data:
    they are answered before the close.
    """

    def __init__(self, reason: str, frames: list[Frame] | None = None) -> None:
        super().__init__(reason)
        self.frames = frames or []


class MbapDecoder:
    """Incremental decoder for one connection's byte stream."""

    __slots__ = ("_buf",)

    def __init__(self) -> None:
        self._buf = b""

    @property
    def pending(self) -> int:
        """Bytes of an incomplete frame held back (0 when the stream is at a frame boundary)."""
        return len(self._buf)

    def feed(self, data: bytes) -> list[Frame]:
        """Frames completed by `data`; raises FrameViolation on a header that breaks a rule."""
        buf = self._buf + data if self._buf else data
        frames: list[Frame] = []
        off = 0
        size = len(buf)
        while size - off >= MBAP_SIZE:
            tid, pid, length, unit = _unpack_header(buf, off)
            if pid != 0:
                raise FrameViolation(f"MBAP protocol id {pid} (must be 0 for Modbus)", frames)
            if not 2 <= length <= MAX_PDU + 1:
                raise FrameViolation(f"MBAP length {length} outside 2..254", frames)
            end = off + 6 + length
            if end > size:
                break
            frames.append((tid, unit, buf[off + MBAP_SIZE : end]))
            off = end
        rest = buf[off:] if off else buf
        if rest:
            try:
                _check_partial_header(rest)
            except FrameViolation as e:
                e.frames = frames
                raise
        self._buf = bytes(rest)
        return frames


def _check_partial_header(rest: bytes) -> None:
    if len(rest) >= 4 and (rest[2] or rest[3]):
        raise FrameViolation(f"MBAP protocol id {rest[2] << 8 | rest[3]} (must be 0 for Modbus)")
    if len(rest) >= 6:
        length = rest[4] << 8 | rest[5]
        if not 2 <= length <= MAX_PDU + 1:
            raise FrameViolation(f"MBAP length {length} outside 2..254")


def encode(tid: int, unit: int, pdu: bytes) -> bytes:
    """One response ADU."""
    return _pack_header(tid, 0, len(pdu) + 1, unit) + pdu
