"""SYNC consumer (CiA 301 7.2.5): COB-ID 0x1005, cycle period 0x1006 and its watchdog."""

from __future__ import annotations

from typing import Final

from drives.application import ABORT_DEVICE_STATE, ABORT_VALUE_RANGE, ObjectAccessError
from drives.cia301.od import Entry, ObjectDictionary

SYNC_TIMEOUT_FACTOR: Final = 1.5  # CANopenNode: SYNC lost after 1.5 x 0x1006


class SyncConsumer:
    def __init__(self, od: ObjectDictionary, on_change) -> None:
        self.od = od
        # the dictionary's value store (one dict for its lifetime): read every SYNC
        self._store = od._store
        self.on_change = on_change
        self.since_sync_s = 0.0
        self.seen = False
        self.timed_out = False
        self.count = 0
        if (0x1005, 0) in od:
            od.write_hooks[0x1005] = self._write_cob_id
        if (0x1019, 0) in od:
            od.write_hooks[0x1019] = self._write_overflow

    @property
    def overflow(self) -> int:
        """0x1019: 0 = SYNC without counter byte, else the counter runs 1..overflow."""
        return int(self._store.get((0x1019, 0), 0))

    def _write_overflow(self, entry: Entry, value: int) -> None:
        if value == 1 or value > 240:
            raise ObjectAccessError(ABORT_VALUE_RANGE, f"counter overflow {value}: 0 or 2..240")
        if self.period_s > 0:
            raise ObjectAccessError(ABORT_DEVICE_STATE, "0x1019 only while 0x1006 is 0")
        self.od.set(0x1019, 0, value)

    @property
    def cob_id(self) -> int:
        raw = int(self.od.get(0x1005, 0)) if (0x1005, 0) in self.od else 0x80
        return raw & 0x7FF

    @property
    def period_s(self) -> float:
        return int(self._store.get((0x1006, 0), 0)) * 1e-6

    def _write_cob_id(self, entry: Entry, value: int) -> None:
        if value & 0x40000000:
            raise ObjectAccessError(ABORT_VALUE_RANGE, "this node cannot produce SYNC (bit 30)")
        if value & 0x20000000 or value & 0x1FFFF800:
            raise ObjectAccessError(ABORT_VALUE_RANGE, "29-bit SYNC identifiers not supported")
        self.od.set(0x1005, 0, value)
        self.on_change()

    def on_sync(self) -> bool:
        """A SYNC arrived; True if it ends a SYNC timeout."""
        self.count += 1
        self.since_sync_s = 0.0
        self.seen = True
        recovered, self.timed_out = self.timed_out, False
        return recovered

    def advance(self, dt_s: float) -> bool:
        """True when the SYNC watchdog expires during this step."""
        if not self.seen or self.timed_out:
            return False
        period = int(self._store.get((0x1006, 0), 0)) * 1e-6  # `period_s`: every tick
        if period <= 0:
            return False
        self.since_sync_s += dt_s
        if self.since_sync_s > SYNC_TIMEOUT_FACTOR * period + 1e-12:
            self.timed_out = True
            return True
        return False

    def reset(self) -> None:
        self.since_sync_s, self.seen, self.timed_out, self.count = 0.0, False, False, 0
