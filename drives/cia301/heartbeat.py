"""Heartbeat producer 0x1017 and consumer 0x1016 (CiA 301 7.2.8.3.2), pure timers."""

from __future__ import annotations

from dataclasses import dataclass

from drives.application import ObjectAccessError
from drives.cia301.od import Entry, ObjectDictionary

ABORT_INCOMPATIBLE = 0x06040043

UNCONFIGURED, UNKNOWN, ACTIVE, TIMEOUT = "UNCONFIGURED", "UNKNOWN", "ACTIVE", "TIMEOUT"


@dataclass
class Monitored:
    """One 0x1016 entry. Monitoring starts with the first heartbeat, not the boot-up."""

    node_id: int
    time_ms: int
    state: str = UNKNOWN
    silent_s: float = 0.0


class HeartbeatProducer:
    def __init__(self, od: ObjectDictionary) -> None:
        self.od = od
        self._store = od._store  # the dictionary's value store, read every tick
        self.elapsed_s = 0.0
        od.write_hooks[0x1017] = self._write_period

    @property
    def period_s(self) -> float:
        return int(self._store.get((0x1017, 0), 0)) / 1000.0

    def _write_period(self, entry: Entry, value: int) -> None:
        self.od.set(0x1017, 0, value)
        self.elapsed_s = 0.0

    def due(self, dt_s: float) -> bool:
        """Advance by dt; True when a heartbeat is due now."""
        period_ms = int(self._store.get((0x1017, 0), 0))  # `period_s`, inlined: every tick
        if period_ms <= 0:
            return False
        period = period_ms / 1000.0
        self.elapsed_s += dt_s
        if self.elapsed_s + 1e-12 >= period:
            self.elapsed_s -= period
            if self.elapsed_s >= period:  # a long step: send one, do not burst
                self.elapsed_s = 0.0
            return True
        return False


class HeartbeatConsumer:
    def __init__(self, od: ObjectDictionary) -> None:
        self.od = od
        self.monitored: dict[int, Monitored] = {}
        if (0x1016, 0) in od:
            od.write_hooks[0x1016] = self._write_entry
        self.reload()

    def reload(self) -> None:
        self.monitored.clear()
        if (0x1016, 0) not in self.od:
            return
        for sub in range(1, int(self.od.get(0x1016, 0)) + 1):
            self._configure(int(self.od.get(0x1016, sub)))

    def _configure(self, raw: int) -> None:
        node_id, time_ms = (raw >> 16) & 0xFF, raw & 0xFFFF
        if node_id and time_ms:
            self.monitored[node_id] = Monitored(node_id, time_ms)

    def _write_entry(self, entry: Entry, value: int) -> None:
        if entry.subindex == 0:
            raise ObjectAccessError(0x06010002, "0x1016:00 is read-only")
        node_id, time_ms = (value >> 16) & 0xFF, value & 0xFFFF
        if node_id and time_ms:
            count = int(self.od.get(0x1016, 0))
            for sub in range(1, count + 1):
                other = int(self.od.get(0x1016, sub))
                if sub != entry.subindex and (other >> 16) & 0xFF == node_id and other & 0xFFFF:
                    raise ObjectAccessError(
                        ABORT_INCOMPATIBLE, f"node {node_id} already monitored in sub {sub}"
                    )
        self.od.set(0x1016, entry.subindex, value)
        self.reload()

    def on_heartbeat(self, node_id: int, state_byte: int) -> bool:
        """A heartbeat or boot-up from `node_id`; True if it recovered from a timeout."""
        monitored = self.monitored.get(node_id)
        if monitored is None:
            return False
        if state_byte & 0x7F == 0:  # boot-up: the remote node reset, wait for its heartbeat
            was_timeout = monitored.state == TIMEOUT
            monitored.state, monitored.silent_s = UNKNOWN, 0.0
            return was_timeout
        recovered = monitored.state == TIMEOUT
        monitored.state, monitored.silent_s = ACTIVE, 0.0
        return recovered

    def advance(self, dt_s: float) -> list[int]:
        """Node-IDs whose heartbeat was lost during this step."""
        lost = []
        for monitored in self.monitored.values():
            if monitored.state != ACTIVE:
                continue
            monitored.silent_s += dt_s
            if monitored.silent_s * 1000.0 > monitored.time_ms + 1e-9:
                monitored.state = TIMEOUT
                lost.append(monitored.node_id)
        return lost

    @property
    def any_timeout(self) -> bool:
        return any(m.state == TIMEOUT for m in self.monitored.values())
