"""EMCY producer (CiA 301 7.2.7) with the error register 0x1001 and history 0x1003."""

from __future__ import annotations

import struct
from collections import deque

from drives.application import ABORT_VALUE_RANGE, ObjectAccessError
from drives.cia301.od import Entry, ObjectDictionary

REGISTER_GENERIC = 0x01
REGISTER_COMMUNICATION = 0x10
HISTORY_DEPTH = 8
_FRAME = struct.Struct("<HB5s")


class EmcyProducer:
    """Builds EMCY frames, keeps 0x1001/0x1003 and queues frames while EMCY is not allowed."""

    def __init__(self, od: ObjectDictionary) -> None:
        self.od = od
        self.application_register = 0
        self.communication_errors: set[int] = set()
        self.history: deque[int] = deque(maxlen=HISTORY_DEPTH)
        self.queue: deque[bytes] = deque(maxlen=64)
        self.since_sent_s = 1e9
        od.read_hooks[0x1001] = lambda entry: self.register
        if (0x1003, 0) in od:
            od.read_hooks[0x1003] = self._read_history
            od.write_hooks[0x1003] = self._write_history

    @property
    def register(self) -> int:
        """0x1001: the application's bits plus communication (bit 4) and generic (bit 0)."""
        value = self.application_register
        if self.communication_errors:
            value |= REGISTER_COMMUNICATION
        if value:
            value |= REGISTER_GENERIC
        return value & 0xFF

    @property
    def cob_id(self) -> int | None:
        raw = int(self.od.get(0x1014, 0)) if (0x1014, 0) in self.od else 0x80
        return None if raw & 0x80000000 else raw & 0x7FF

    @property
    def inhibit_s(self) -> float:
        """0x1015 in 100 us units: the least time between two EMCY frames."""
        return int(self.od.get(0x1015, 0)) * 1e-4 if (0x1015, 0) in self.od else 0.0

    def may_send(self) -> bool:
        return self.since_sent_s + 1e-12 >= self.inhibit_s

    def _read_history(self, entry: Entry) -> int:
        if entry.subindex == 0:
            return len(self.history)
        position = entry.subindex - 1
        return self.history[position] if position < len(self.history) else 0

    def _write_history(self, entry: Entry, value: int) -> None:
        if entry.subindex != 0 or value != 0:
            raise ObjectAccessError(ABORT_VALUE_RANGE, "only 0 may be written to 0x1003:00")
        self.history.clear()

    def frame(self, error_code: int, manufacturer: bytes = b"\x00" * 5) -> bytes:
        """Record an EMCY (history unless it is a reset) and return its 8 data bytes."""
        if error_code:
            self.history.appendleft(error_code & 0xFFFF)
        return _FRAME.pack(
            error_code & 0xFFFF, self.register, bytes(manufacturer[:5]).ljust(5, b"\x00")
        )

    def reset(self) -> None:
        self.application_register = 0
        self.communication_errors.clear()
        self.history.clear()
        self.queue.clear()
        self.since_sent_s = 1e9
