"""Process data objects (CiA 301 7.2.2): configuration rules and compiled packing.

Each PDO channel mirrors its communication record (0x1400/0x1800 + k) and mapping record
(0x1600/0x1A00 + k). Writes follow the CiA 301 procedure (invalidate via COB-ID bit 31, set
the count to 0, write entries, set the count, validate) and are refused with the abort codes
CTT "PDO 22-33" expects. A valid mapping is compiled into one `struct.Struct` so a PDO costs
one pack or unpack plus one application call per mapped object.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from functools import partial

from drives.application import ABORT_DEVICE_STATE, ABORT_VALUE_RANGE, ObjectAccessError
from drives.cia301.od import Entry, ObjectDictionary

ABORT_NOT_MAPPABLE = 0x06040041
ABORT_PDO_LENGTH = 0x06040042
ABORT_INCOMPATIBLE = 0x06040043

COB_INVALID = 0x80000000
COB_NO_RTR = 0x40000000
COB_EXTENDED = 0x20000000

MAX_PDO_BITS = 64
# Dummy entries map a data-type index to skip bytes (CTT "PDO 33").
DUMMY_FORMATS = {0x0002: "b", 0x0003: "h", 0x0004: "i", 0x0005: "B", 0x0006: "H", 0x0007: "I"}
# CAN-IDs reserved for other services (CiA 301 7.3.5; CTT "Other 10").
RESTRICTED_IDS = (
    (0x000, 0x07F),
    (0x101, 0x180),
    (0x581, 0x5FF),
    (0x601, 0x67F),
    (0x6E0, 0x6FF),
    (0x701, 0x7FF),
)


def restricted(can_id: int) -> bool:
    return any(low <= can_id <= high for low, high in RESTRICTED_IDS)


@dataclass
class PdoChannel:
    """One RPDO or TPDO: configuration plus runtime state."""

    number: int
    transmit: bool
    comm_index: int
    map_index: int
    cob_id: int = 0
    valid: bool = False
    rtr_allowed: bool = True
    trans_type: int = 255
    inhibit_100us: int = 0
    event_timer_ms: int = 0
    sync_start: int = 0
    codec: struct.Struct | None = None
    targets: list[Entry | None] = field(default_factory=list)
    length: int = 0
    #: TPDO: one zero-argument reader per mapped object, resolved when the mapping is
    #: compiled (sampling then costs one call per object, no per-frame dispatch)
    readers: list = field(default_factory=list)
    #: RPDO: one one-argument writer per mapped object (None for a dummy entry)
    writers: list = field(default_factory=list)
    # runtime
    sync_count: int = 0
    pending: bytes | None = None  # synchronous RPDO waiting for the next SYNC
    last_sent: bytes | None = None
    since_sent: float = 1e9  # seconds since the last transmission (inhibit, event timer)
    length_error: bool = False
    started: bool = False  # synchronous TPDO: SYNC start value (0x18xx:06) reached
    since_rx: float = 0.0  # RPDO deadline monitoring (0x14xx:05)
    rx_seen: bool = False
    timed_out: bool = False

    @property
    def synchronous(self) -> bool:
        return self.trans_type <= 240

    @property
    def event_driven(self) -> bool:
        return self.trans_type >= 254


class PdoService:
    """Owns the PDO channels of one node and validates every write to their records."""

    def __init__(self, od: ObjectDictionary, on_change) -> None:
        self.od = od
        self.on_change = on_change  # called after a configuration change (rebuild dispatch)
        self.rpdos: list[PdoChannel] = []
        self.tpdos: list[PdoChannel] = []
        self.refused_writes = 0
        for k in range(512):
            if (0x1400 + k, 1) in od and (0x1600 + k, 0) in od:
                self.rpdos.append(PdoChannel(k + 1, False, 0x1400 + k, 0x1600 + k))
            if (0x1800 + k, 1) in od and (0x1A00 + k, 0) in od:
                self.tpdos.append(PdoChannel(k + 1, True, 0x1800 + k, 0x1A00 + k))
        self._by_comm = {c.comm_index: c for c in self.rpdos + self.tpdos}
        self._by_map = {c.map_index: c for c in self.rpdos + self.tpdos}
        for channel in self.rpdos + self.tpdos:
            od.write_hooks[channel.comm_index] = self._write_comm
            od.write_hooks[channel.map_index] = self._write_map
        self.reload()

    # ------------------------------------------------------------------ configuration
    def reload(self) -> None:
        """Read every channel from the object dictionary (after a reset)."""
        for channel in self.rpdos + self.tpdos:
            self._load(channel)
        self.on_change()

    def _value(self, index: int, subindex: int, default: int = 0) -> int:
        return int(self.od.get(index, subindex)) if (index, subindex) in self.od else default

    def _load(self, channel: PdoChannel) -> None:
        raw = self._value(channel.comm_index, 1)
        channel.cob_id = raw & 0x1FFFFFFF
        channel.valid = not raw & COB_INVALID
        channel.rtr_allowed = not raw & COB_NO_RTR
        channel.trans_type = self._value(channel.comm_index, 2, 255)
        channel.inhibit_100us = self._value(channel.comm_index, 3)
        channel.event_timer_ms = self._value(channel.comm_index, 5)
        channel.sync_start = self._value(channel.comm_index, 6)
        channel.sync_count = 0
        channel.pending = None
        channel.last_sent = None
        channel.since_sent = 1e9
        channel.started = False
        channel.since_rx, channel.rx_seen, channel.timed_out = 0.0, False, False
        count = self._value(channel.map_index, 0)
        entries = [self._value(channel.map_index, s) for s in range(1, count + 1)]
        try:
            self._compile(channel, entries)
        except ObjectAccessError:
            channel.codec, channel.targets, channel.length = None, [], 0
            channel.valid = False  # an EDS with a broken default mapping stays off

    def _resolve(self, channel: PdoChannel, raw: int) -> tuple[str, Entry | None, int]:
        index, subindex, bits = raw >> 16, (raw >> 8) & 0xFF, raw & 0xFF
        if index in DUMMY_FORMATS and subindex == 0:
            fmt = DUMMY_FORMATS[index]
            if struct.calcsize(fmt) * 8 != bits:
                raise ObjectAccessError(ABORT_INCOMPATIBLE, f"dummy 0x{raw:08X} length")
            return fmt, None, bits
        try:
            entry = self.od.entry(index, subindex)
        except ObjectAccessError as exc:
            raise ObjectAccessError(ABORT_NOT_MAPPABLE, f"0x{raw:08X}: {exc}") from None
        direction_ok = entry.readable if channel.transmit else entry.writable
        if not entry.mappable or entry.codec is None or not direction_ok:
            raise ObjectAccessError(ABORT_NOT_MAPPABLE, f"0x{index:04X}:{subindex} not mappable")
        if entry.bits != bits:
            raise ObjectAccessError(
                ABORT_INCOMPATIBLE, f"0x{raw:08X}: object has {entry.bits} bits"
            )
        return entry.codec.format.lstrip("<"), entry, bits

    def _compile(self, channel: PdoChannel, entries: list[int]) -> None:
        formats, targets, total = [], [], 0
        for raw in entries:
            fmt, entry, bits = self._resolve(channel, raw)
            formats.append(fmt)
            targets.append(entry)
            total += bits
        if total > MAX_PDO_BITS:
            raise ObjectAccessError(ABORT_PDO_LENGTH, f"{total} bits mapped, at most 64")
        channel.codec = struct.Struct("<" + "".join(formats))
        channel.targets = targets
        channel.length = channel.codec.size
        channel.readers = [self._reader(e) for e in targets] if channel.transmit else []
        channel.writers = [] if channel.transmit else [self._writer(e) for e in targets]

    def _writer(self, entry: Entry | None):
        """A one-argument callable storing a received value in a mapped object (None: dummy)."""
        if entry is None:
            return None
        if entry.owned:
            return partial(self.od.application.write_object, entry.index, entry.subindex)
        return partial(self.od.set, entry.index, entry.subindex)

    def _reader(self, entry: Entry | None):
        """A zero-argument callable returning the current value of a mapped object."""
        if entry is None:
            return _zero  # dummy entry: transmitted as 0
        index, subindex = entry.index, entry.subindex
        if entry.owned and index not in self.od.read_hooks:
            # An application may hand out a direct reader for the objects TPDOs sample
            # every cycle (optional, beyond the DriveApplication protocol).
            application = self.od.application
            factory = getattr(application, "object_reader", None)
            reader = factory(index, subindex) if factory is not None else None
            return reader or partial(application.read_object, index, subindex)
        return partial(self.od.get, index, subindex)

    def _write_comm(self, entry: Entry, value: int) -> None:
        channel = self._by_comm[entry.index]
        sub = entry.subindex
        if sub == 1:
            can_id = value & 0x1FFFFFFF
            becomes_valid = not value & COB_INVALID
            if value & COB_EXTENDED or can_id > 0x7FF:
                raise ObjectAccessError(ABORT_VALUE_RANGE, "29-bit PDO identifiers not supported")
            if becomes_valid and channel.valid and can_id != channel.cob_id:
                raise ObjectAccessError(ABORT_VALUE_RANGE, "COB-ID changed while PDO valid")
            if becomes_valid and restricted(can_id):
                raise ObjectAccessError(ABORT_VALUE_RANGE, f"CAN-ID 0x{can_id:03X} is restricted")
        elif sub == 2:
            allowed = value <= 240 or value >= (252 if channel.transmit else 254)
            if not allowed:
                raise ObjectAccessError(ABORT_VALUE_RANGE, f"transmission type {value}")
        elif sub in (3, 6) and channel.valid:
            raise ObjectAccessError(ABORT_VALUE_RANGE, "only while the PDO is invalid")
        elif sub == 6 and value > 240:
            raise ObjectAccessError(ABORT_VALUE_RANGE, f"SYNC start value {value}")
        self.od.set(entry.index, sub, value)
        self._load(channel)
        self.on_change()

    def _write_map(self, entry: Entry, value: int) -> None:
        channel = self._by_map[entry.index]
        if channel.valid:
            raise ObjectAccessError(ABORT_DEVICE_STATE, "mapping changed while PDO valid")
        count = int(self.od.get(entry.index, 0))
        if entry.subindex == 0:
            if value:
                entries = [int(self.od.get(entry.index, s)) for s in range(1, value + 1)]
                channel_copy = PdoChannel(channel.number, channel.transmit, 0, 0)
                self._compile(channel_copy, entries)
        else:
            if count != 0:
                raise ObjectAccessError(ABORT_DEVICE_STATE, "set sub-index 0 to 0 first")
            if value:
                self._resolve(channel, value)
        self.od.set(entry.index, entry.subindex, value)
        self._load(channel)
        self.on_change()

    # ------------------------------------------------------------------ data
    def unpack(self, channel: PdoChannel, data: bytes | bytearray) -> None:
        """Write received RPDO data to its mapped objects."""
        values = _codec_of(channel).unpack_from(data)
        writers = channel.writers
        if len(values) != len(writers):
            raise ValueError(f"PDO {channel.number}: {len(values)} values, {len(writers)} writers")
        # indexed, not zip(strict=True): compiled, the keyword argument costs a string per call
        for i in range(len(writers)):
            write, value = writers[i], values[i]
            if write is None:
                continue
            try:
                write(value)
            except ObjectAccessError:
                self.refused_writes += 1  # an RPDO has no answer channel

    def pack(self, channel: PdoChannel) -> bytes:
        """Sample the mapped objects of a TPDO."""
        codec = _codec_of(channel)
        values = [read() for read in channel.readers]
        try:
            return codec.pack(*values)
        except struct.error:
            return codec.pack(*(int(round(v)) for v in values))


def _codec_of(channel: PdoChannel) -> struct.Struct:
    codec = channel.codec
    if codec is None:  # only a channel whose mapping was never compiled
        raise ValueError(f"PDO {channel.number}: no mapping compiled")
    return codec


def _zero() -> int:
    return 0
