"""The slave's object dictionary: definitions from the EDS, values in storage or the application.

`canopen.import_od` supplies the definitions (data type, access, limits, defaults, PDO
mapping); this module adds what a device needs on top: value storage for the communication
objects, strict sub-index and size checks, limit checks with the right SDO abort codes, and
delegation to the `DriveApplication` for every object it owns.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import canopen
from canopen import objectdictionary as odt

from drives.application import (
    ABORT_GENERAL,
    ABORT_NOT_EXIST,
    ABORT_READ_ONLY,
    ABORT_SUBINDEX,
    ABORT_VALUE_HIGH,
    ABORT_VALUE_LOW,
    ABORT_WRITE_ONLY,
    DriveApplication,
    ObjectAccessError,
)

ABORT_LENGTH_MISMATCH = 0x06070010
ABORT_LENGTH_HIGH = 0x06070012
ABORT_LENGTH_LOW = 0x06070013

Value = int | float | str | bytes


@lru_cache(maxsize=16)
def load_od(eds_path: str) -> canopen.ObjectDictionary:
    """The EDS parsed once per file with node-ID 0; definitions are shared, never mutated.

    `$NODEID` defaults are marked `relative` by canopen; `ObjectDictionary.reset` adds the
    node-ID, so one parse (~0.1 s) serves every node on the bus.
    """
    return canopen.import_od(eds_path, 0)


@dataclass(slots=True)
class Entry:
    """One addressable sub-object with everything the hot paths need precomputed."""

    index: int
    subindex: int
    var: odt.ODVariable
    codec: struct.Struct | None  # None for strings and domains
    bits: int
    readable: bool
    writable: bool
    mappable: bool
    minimum: int | float | None
    maximum: int | float | None
    owned: bool  # held by the application, not by storage

    def decode(self, data: bytes) -> Value:
        if self.codec is not None:
            return self.codec.unpack(data)[0]
        return self.var.decode_raw(data)

    def encode(self, value: Value) -> bytes:
        if self.codec is not None:
            try:
                return self.codec.pack(value)
            except struct.error:
                # An application answering 12.0 for an integer is tolerated; a value that
                # does not fit the type is the application's fault: general error abort.
                try:
                    return self.codec.pack(int(round(value)))
                except (struct.error, TypeError, ValueError):
                    raise ObjectAccessError(
                        ABORT_GENERAL, f"0x{self.index:04X}:{self.subindex} value {value!r}"
                    ) from None
        if isinstance(value, bytes | bytearray):
            return bytes(value)
        return self.var.encode_raw(value)


WriteHook = Callable[[Entry, Any], None]
ReadHook = Callable[[Entry], Any]


class ObjectDictionary:
    """Storage + access rules. Hooks let the services validate writes and compute reads."""

    def __init__(self, eds_path: str, node_id: int, application: DriveApplication) -> None:
        self.node_id = node_id
        self.definitions = load_od(eds_path)
        self.application = application
        self._entries: dict[tuple[int, int], Entry] = {}
        self.entries = self._entries  # read-only view for the services
        self._objects: dict[int, Any] = {}
        for index in self.definitions:
            obj = self.definitions[index]
            self._objects[index] = obj
            owned = index >= 0x2000 and application.owns(index)
            variables = [obj] if isinstance(obj, odt.ODVariable) else list(obj.values())
            for var in variables:
                codec = var.STRUCT_TYPES.get(var.data_type)
                self._entries[(index, var.subindex)] = Entry(
                    index=index,
                    subindex=var.subindex,
                    var=var,
                    codec=codec,
                    bits=codec.size * 8 if codec else 0,
                    readable=var.readable,
                    writable=var.writable,
                    mappable=var.pdo_mappable,
                    minimum=var.min,
                    maximum=var.max,
                    owned=owned,
                )
        self._store: dict[tuple[int, int], Value] = {}
        self.write_hooks: dict[int, WriteHook] = {}
        self.read_hooks: dict[int, ReadHook] = {}
        self.reset(0x0000, 0xFFFF)

    # ------------------------------------------------------------------ lookup
    def entry(self, index: int, subindex: int) -> Entry:
        """The entry or ObjectAccessError 0x06020000 / 0x06090011."""
        entry = self._entries.get((index, subindex))
        if entry is None:
            if index not in self._objects:
                raise ObjectAccessError(ABORT_NOT_EXIST, f"object 0x{index:04X} does not exist")
            raise ObjectAccessError(
                ABORT_SUBINDEX, f"object 0x{index:04X} has no sub-index {subindex}"
            )
        return entry

    def __contains__(self, key: tuple[int, int]) -> bool:
        return key in self._entries

    def reset(self, first: int, last: int) -> None:
        """Reload the EDS default values of objects first..last (NMT reset services)."""
        for (index, subindex), entry in self._entries.items():
            if first <= index <= last and not entry.owned:
                default = entry.var.default
                if default is None:
                    default = b"" if entry.codec is None else 0
                elif entry.var.relative:
                    default += self.node_id
                self._store[(index, subindex)] = default

    # ------------------------------------------------------------------ values
    def get(self, index: int, subindex: int) -> Value:
        """Current value without access checks (internal use and TPDO sampling)."""
        entry = self._entries[(index, subindex)]
        hook = self.read_hooks.get(index)
        if hook is not None:
            return hook(entry)
        if entry.owned:
            return self.application.read_object(index, subindex)
        return self._store[(index, subindex)]

    def set(self, index: int, subindex: int, value: Value) -> None:
        """Store a value without checks (the services' own bookkeeping)."""
        self._store[(index, subindex)] = value

    def read(self, index: int, subindex: int) -> bytes:
        """SDO upload: encoded bytes, or ObjectAccessError with the abort code."""
        entry = self.entry(index, subindex)
        if not entry.readable:
            raise ObjectAccessError(ABORT_WRITE_ONLY, f"0x{index:04X}:{subindex} is write-only")
        return entry.encode(self.get(index, subindex))

    def write(self, index: int, subindex: int, data: bytes, *, size_known: bool = True) -> None:
        """SDO download: checks access, length and limits, then applies the value."""
        entry = self.entry(index, subindex)
        if not entry.writable:
            raise ObjectAccessError(ABORT_READ_ONLY, f"0x{index:04X}:{subindex} is read-only")
        if entry.codec is not None:
            size = entry.codec.size
            if not size_known and len(data) >= size:
                data = data[:size]  # expedited without size indication: the type decides
            if len(data) > size:
                raise ObjectAccessError(
                    ABORT_LENGTH_HIGH, f"{len(data)} bytes for {size}-byte type"
                )
            if len(data) < size:
                raise ObjectAccessError(ABORT_LENGTH_LOW, f"{len(data)} bytes for {size}-byte type")
        value = entry.decode(bytes(data))
        self.write_value(entry, value)

    def write_value(self, entry: Entry, value: Value) -> None:
        """Apply a decoded value: limits, service hook, then application or storage."""
        if entry.minimum is not None and value < entry.minimum:
            raise ObjectAccessError(ABORT_VALUE_LOW, f"{value} below {entry.minimum}")
        if entry.maximum is not None and value > entry.maximum:
            raise ObjectAccessError(ABORT_VALUE_HIGH, f"{value} above {entry.maximum}")
        hook = self.write_hooks.get(entry.index)
        if hook is not None:
            hook(entry, value)
            return
        if entry.owned:
            if isinstance(value, str):
                value = value.encode("ascii")
            self.application.write_object(entry.index, entry.subindex, value)
        else:
            self._store[(entry.index, entry.subindex)] = value
