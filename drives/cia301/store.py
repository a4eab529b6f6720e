"""Store and restore parameters, 0x1010 / 0x1011 (CiA 301 7.5.2.13-14), in memory.

Writing the signature "save" (0x65766173) to 0x1010:sub keeps the current values of that
parameter group; they replace the EDS defaults at the next reset. Writing "load"
(0x64616F6C) to 0x1011:sub drops the kept values of the group, so the next reset restores
the defaults. Any other value aborts with 0x08000020 (CTT "Other 01-04"). "Non-volatile"
here means: survives NMT resets of this slave object.
"""

from __future__ import annotations

from drives.application import ObjectAccessError
from drives.cia301.od import Entry, ObjectDictionary

SAVE = 0x65766173
LOAD = 0x64616F6C
ABORT_CANNOT_STORE = 0x08000020

# sub-index -> index range of the parameter group
GROUPS = {1: (0x1000, 0x9FFF), 2: (0x1000, 0x1FFF), 3: (0x6000, 0x9FFF)}
# Objects that are state or commands, never parameters.
VOLATILE = {0x1001, 0x1003, 0x1010, 0x1011, 0x6040, 0x6041, 0x607A, 0x60FF, 0x6071}


class ParameterStore:
    def __init__(self, od: ObjectDictionary) -> None:
        self.od = od
        self.saved: dict[tuple[int, int], object] = {}
        if (0x1010, 1) in od:
            od.write_hooks[0x1010] = self._write_store
            od.write_hooks[0x1011] = self._write_restore
            od.read_hooks[0x1010] = lambda entry: 1 if entry.subindex else 3
            od.read_hooks[0x1011] = lambda entry: 1 if entry.subindex else 3

    def _group(self, entry: Entry) -> tuple[int, int]:
        group = GROUPS.get(entry.subindex)
        if group is None:
            raise ObjectAccessError(0x06090011, f"no parameter group {entry.subindex}")
        return group

    def _parameters(self, first: int, last: int):
        for (index, subindex), entry in self.od.entries.items():
            parameter = entry.writable and entry.readable and index not in VOLATILE
            if parameter and first <= index <= last:
                yield (index, subindex), entry

    def _write_store(self, entry: Entry, value: int) -> None:
        first, last = self._group(entry)
        if value != SAVE:
            raise ObjectAccessError(ABORT_CANNOT_STORE, f"signature 0x{value:08X} is not 'save'")
        for key, _ in self._parameters(first, last):
            try:
                self.saved[key] = self.od.get(*key)
            except ObjectAccessError:
                continue  # the application refuses to read it: nothing to keep

    def _write_restore(self, entry: Entry, value: int) -> None:
        first, last = self._group(entry)
        if value != LOAD:
            raise ObjectAccessError(ABORT_CANNOT_STORE, f"signature 0x{value:08X} is not 'load'")
        for key in [k for k in self.saved if first <= k[0] <= last]:
            del self.saved[key]

    def apply(self, first: int, last: int) -> None:
        """After the defaults were reloaded: put the kept values of first..last back."""
        for (index, subindex), value in self.saved.items():
            if first <= index <= last:
                entry = self.od.entry(index, subindex)
                if entry.owned:
                    try:
                        self.od.application.write_object(index, subindex, value)
                    except ObjectAccessError:
                        continue
                else:
                    self.od.set(index, subindex, value)
