"""SDO server (CiA 301 7.2.4): expedited, segmented and block transfers, pure frame logic.

`on_request(data)` takes the 8 data bytes of a client frame and returns the server frames to
send; `advance(dt)` runs the transfer timeout. The object dictionary raises ObjectAccessError
with the abort code for anything it refuses; malformed protocol gets the protocol aborts.
"""

from __future__ import annotations

import binascii
import logging
import struct
from dataclasses import dataclass, field

from drives.application import ObjectAccessError
from drives.cia301.od import ObjectDictionary

ABORT_TOGGLE = 0x05030000
ABORT_TIMEOUT = 0x05040000
logger = logging.getLogger(__name__)

ABORT_COMMAND = 0x05040001
ABORT_BLOCK_SIZE = 0x05040002
ABORT_SEQUENCE = 0x05040003
ABORT_CRC = 0x05040004
ABORT_MEMORY = 0x05040005
ABORT_LENGTH_MISMATCH = 0x06070010
ABORT_LENGTH_HIGH = 0x06070012
ABORT_LENGTH_LOW = 0x06070013
ABORT_GENERAL = 0x08000000

MAX_TRANSFER = 65536  # bytes a single download may carry (bounded memory)
BLOCK_SIZE = 127  # segments per block the server asks for

_HEAD = struct.Struct("<BHB")
_ABORT = struct.Struct("<BHBL")
_SIZE = struct.Struct("<BHBL")


def abort_frame(index: int, subindex: int, code: int) -> bytes:
    return _ABORT.pack(0x80, index, subindex, code)


@dataclass
class _Transfer:
    kind: str  # "down" | "up" | "block-down" | "block-up"
    index: int
    subindex: int
    size: int | None = None
    toggle: int = 0
    buffer: bytearray = field(default_factory=bytearray)
    data: bytes = b""
    pos: int = 0
    crc: bool = False
    seqno: int = 0
    blksize: int = BLOCK_SIZE
    block_start: int = 0
    last_bytes: int = 0
    done: bool = False
    phase: str = ""  # block transfers: "segments" | "end" | "ack" | "start"


class SdoServer:
    """One SDO server channel; holds at most one transfer at a time."""

    def __init__(self, od: ObjectDictionary, *, timeout_s: float = 1.0) -> None:
        self.od = od
        self.timeout_s = timeout_s
        self.transfer: _Transfer | None = None
        self._idle = 0.0
        self.aborts_sent = 0

    # ------------------------------------------------------------------ entry points
    def advance(self, dt_s: float) -> list[bytes]:
        """Transfer timeout: abort 0x05040000 when the client stays silent too long."""
        if self.transfer is None:
            return []
        self._idle += dt_s
        if self._idle < self.timeout_s:
            return []
        return [self._abort(ABORT_TIMEOUT)]

    def reset(self) -> None:
        self.transfer = None
        self._idle = 0.0

    def on_request(self, data: bytes) -> list[bytes]:
        """Frames to answer one client request with."""
        self._idle = 0.0
        transfer = self.transfer
        if transfer is not None and transfer.kind == "block-down" and transfer.phase == "segments":
            if len(data) == 8 and data[0] == 0x80 and transfer.seqno == 0:
                self.transfer = None  # client abort during the segment phase
                return []
            return self._block_down_segment(transfer, data)
        if len(data) != 8:
            index, subindex = self._current_address(data)
            return [self._abort(ABORT_COMMAND, index, subindex)]
        command = data[0]
        ccs = command >> 5
        try:
            if ccs == 1:
                return self._init_download(data)
            if ccs == 0:
                return self._download_segment(data)
            if ccs == 2:
                return self._init_upload(data)
            if ccs == 3:
                return self._upload_segment(data)
            if ccs == 4:
                self.transfer = None
                return []
            if ccs == 6:
                return self._block_download(data)
            if ccs == 5:
                return self._block_upload(data)
        except ObjectAccessError as exc:
            index, subindex = self._current_address(data)
            return [self._abort(exc.abort_code, index, subindex)]
        except Exception:  # an application bug must not take the node off the bus
            logger.exception("SDO request %s failed", bytes(data).hex())
            index, subindex = self._current_address(data)
            return [self._abort(ABORT_GENERAL, index, subindex)]
        index, subindex = self._current_address(data)
        return [self._abort(ABORT_COMMAND, index, subindex)]

    # ------------------------------------------------------------------ helpers
    def _current_address(self, data: bytes) -> tuple[int, int]:
        if self.transfer is not None:
            return self.transfer.index, self.transfer.subindex
        if len(data) >= 3:  # echo the multiplexer of the refused frame, as far as it goes
            return data[1] | data[2] << 8, data[3] if len(data) >= 4 else 0
        return 0, 0

    def _abort(self, code: int, index: int | None = None, subindex: int | None = None) -> bytes:
        if index is None:
            index, subindex = (
                (self.transfer.index, self.transfer.subindex) if self.transfer else (0, 0)
            )
        self.transfer = None
        self.aborts_sent += 1
        return abort_frame(index, subindex or 0, code)

    # ------------------------------------------------------------------ download
    def _init_download(self, data: bytes) -> list[bytes]:
        command, index, subindex = _HEAD.unpack_from(data)
        self.transfer = None
        entry = self.od.entry(index, subindex)
        expedited = command & 0x02
        size_indicated = command & 0x01
        if expedited:
            size = 4 - ((command >> 2) & 0x03) if size_indicated else 4
            self.od.write(
                index, subindex, bytes(data[4 : 4 + size]), size_known=bool(size_indicated)
            )
            return [_HEAD.pack(0x60, index, subindex) + b"\x00" * 4]
        if not entry.writable:
            self.od.write(index, subindex, b"")  # raises read-only with the right code
        size = struct.unpack_from("<L", data, 4)[0] if size_indicated else None
        if size is not None:
            self._check_size(entry.codec.size if entry.codec else None, size)
        self.transfer = _Transfer("down", index, subindex, size=size)
        return [_HEAD.pack(0x60, index, subindex) + b"\x00" * 4]

    @staticmethod
    def _check_size(fixed: int | None, size: int) -> None:
        if fixed is not None and size != fixed:
            raise ObjectAccessError(ABORT_LENGTH_HIGH if size > fixed else ABORT_LENGTH_LOW)
        if size > MAX_TRANSFER:
            raise ObjectAccessError(ABORT_MEMORY, f"{size} bytes exceed {MAX_TRANSFER}")

    def _download_segment(self, data: bytes) -> list[bytes]:
        transfer = self.transfer
        if transfer is None or transfer.kind != "down":
            return [self._abort(ABORT_COMMAND, 0, 0)]
        command = data[0]
        toggle = (command >> 4) & 1
        if toggle != transfer.toggle:
            return [self._abort(ABORT_TOGGLE)]
        unused = (command >> 1) & 0x07
        transfer.buffer += data[1 : 8 - unused]
        if len(transfer.buffer) > MAX_TRANSFER or (
            transfer.size is not None and len(transfer.buffer) > transfer.size
        ):
            return [self._abort(ABORT_LENGTH_HIGH)]
        response = bytes([0x20 | (toggle << 4)]) + b"\x00" * 7
        transfer.toggle ^= 1
        if command & 0x01:  # last segment
            if transfer.size is not None and len(transfer.buffer) != transfer.size:
                return [self._abort(ABORT_LENGTH_MISMATCH)]
            self.transfer = None
            try:
                self.od.write(transfer.index, transfer.subindex, bytes(transfer.buffer))
            except ObjectAccessError as exc:
                return [abort_frame(transfer.index, transfer.subindex, exc.abort_code)]
        return [response]

    # ------------------------------------------------------------------ upload
    def _init_upload(self, data: bytes) -> list[bytes]:
        _, index, subindex = _HEAD.unpack_from(data)
        self.transfer = None
        value = self.od.read(index, subindex)
        size = len(value)
        if 0 < size <= 4:
            command = 0x43 | ((4 - size) << 2)
            return [_HEAD.pack(command, index, subindex) + value + b"\x00" * (4 - size)]
        self.transfer = _Transfer("up", index, subindex, size=size, data=value)
        return [_SIZE.pack(0x41, index, subindex, size)]

    def _upload_segment(self, data: bytes) -> list[bytes]:
        transfer = self.transfer
        if transfer is None or transfer.kind != "up":
            return [self._abort(ABORT_COMMAND, 0, 0)]
        toggle = (data[0] >> 4) & 1
        if toggle != transfer.toggle:
            return [self._abort(ABORT_TOGGLE)]
        chunk = transfer.data[transfer.pos : transfer.pos + 7]
        transfer.pos += len(chunk)
        last = transfer.pos >= len(transfer.data)
        command = (toggle << 4) | ((7 - len(chunk)) << 1) | (1 if last else 0)
        transfer.toggle ^= 1
        if last:
            self.transfer = None
        return [bytes([command]) + chunk + b"\x00" * (7 - len(chunk))]

    # ------------------------------------------------------------------ block download
    def _block_download(self, data: bytes) -> list[bytes]:
        command = data[0]
        transfer = self.transfer
        if command & 0x01 == 0:  # initiate
            _, index, subindex = _HEAD.unpack_from(data)
            self.transfer = None
            entry = self.od.entry(index, subindex)
            if not entry.writable:
                self.od.write(index, subindex, b"")
            size = struct.unpack_from("<L", data, 4)[0] if command & 0x02 else None
            if size is not None:
                self._check_size(entry.codec.size if entry.codec else None, size)
            self.transfer = _Transfer(
                "block-down", index, subindex, size=size, crc=bool(command & 0x04)
            )
            self.transfer.phase = "segments"
            return [bytes([0xA0 | (command & 0x04)]) + data[1:4] + bytes([BLOCK_SIZE, 0, 0, 0])]
        if transfer is None or transfer.kind != "block-down" or transfer.phase != "end":
            return [self._abort(ABORT_COMMAND, 0, 0)]
        unused = (command >> 2) & 0x07
        if transfer.last_bytes and unused:
            del transfer.buffer[len(transfer.buffer) - unused :]
        payload = bytes(transfer.buffer)
        self.transfer = None
        if transfer.size is not None and len(payload) != transfer.size:
            return [abort_frame(transfer.index, transfer.subindex, ABORT_LENGTH_MISMATCH)]
        if transfer.crc:
            crc = struct.unpack_from("<H", data, 1)[0]
            if binascii.crc_hqx(payload, 0) != crc:
                return [abort_frame(transfer.index, transfer.subindex, ABORT_CRC)]
        try:
            self.od.write(transfer.index, transfer.subindex, payload)
        except ObjectAccessError as exc:
            return [abort_frame(transfer.index, transfer.subindex, exc.abort_code)]
        return [bytes([0xA1]) + b"\x00" * 7]

    def _block_down_segment(self, transfer: _Transfer, data: bytes) -> list[bytes]:
        if len(data) != 8:
            return [self._abort(ABORT_COMMAND)]
        seqno = data[0] & 0x7F
        last = bool(data[0] & 0x80)
        if seqno == 0 or seqno > BLOCK_SIZE:
            return [self._abort(ABORT_SEQUENCE)]
        in_sequence = seqno == transfer.seqno + 1
        if in_sequence:
            transfer.seqno = seqno
            transfer.buffer += data[1:8]
            transfer.last_bytes = 7
            if len(transfer.buffer) > MAX_TRANSFER + 7:
                return [self._abort(ABORT_MEMORY)]
        # Out-of-sequence segments are ignored; the ack makes the client resend from there.
        if last or seqno >= transfer.blksize:
            ack = bytes([0xA2, transfer.seqno, BLOCK_SIZE]) + b"\x00" * 5
            if last and in_sequence:
                transfer.phase = "end"
            transfer.seqno = 0
            return [ack]
        return []

    # ------------------------------------------------------------------ block upload
    def _block_upload(self, data: bytes) -> list[bytes]:
        command = data[0]
        sub_command = command & 0x03
        transfer = self.transfer
        if sub_command == 0:  # initiate
            _, index, subindex = _HEAD.unpack_from(data)
            self.transfer = None
            blksize = data[4]
            if not 1 <= blksize <= 127:
                return [abort_frame(index, subindex, ABORT_BLOCK_SIZE)]
            value = self.od.read(index, subindex)
            self.transfer = _Transfer(
                "block-up",
                index,
                subindex,
                size=len(value),
                data=value,
                crc=bool(command & 0x04),
                blksize=blksize,
            )
            self.transfer.phase = "start"
            return [_SIZE.pack(0xC2 | (command & 0x04), index, subindex, len(value))]
        if transfer is None or transfer.kind != "block-up":
            return [self._abort(ABORT_COMMAND, 0, 0)]
        if sub_command == 3 and transfer.phase == "start":
            return self._send_block(transfer)
        if sub_command == 2 and transfer.phase == "ack":
            ackseq, blksize = data[1], data[2]
            if not 1 <= blksize <= 127:
                return [self._abort(ABORT_BLOCK_SIZE)]
            # Resume after the last segment the client confirmed.
            transfer.pos = min(transfer.block_start + 7 * ackseq, len(transfer.data))
            transfer.blksize = blksize
            if transfer.pos >= len(transfer.data) and transfer.done:
                transfer.phase = "end"
                unused = (7 - len(transfer.data) % 7) % 7 if transfer.data else 7
                crc = binascii.crc_hqx(transfer.data, 0) if transfer.crc else 0
                return [struct.pack("<BH", 0xC1 | (unused << 2), crc) + b"\x00" * 5]
            return self._send_block(transfer)
        if sub_command == 1 and transfer.phase == "end":
            self.transfer = None
            return []
        return [self._abort(ABORT_COMMAND)]

    def _send_block(self, transfer: _Transfer) -> list[bytes]:
        frames = []
        transfer.block_start = transfer.pos
        transfer.done = False
        for seqno in range(1, transfer.blksize + 1):
            chunk = transfer.data[transfer.pos : transfer.pos + 7]
            transfer.pos += len(chunk)
            last = transfer.pos >= len(transfer.data)
            frames.append(
                bytes([seqno | (0x80 if last else 0)]) + chunk + b"\x00" * (7 - len(chunk))
            )
            if last:
                transfer.done = True
                break
        transfer.phase = "ack"
        return frames
