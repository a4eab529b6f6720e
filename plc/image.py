"""The PLC's process image: the memory ladder logic solves over and Modbus serves.

Areas follow IEC 61131-3 direct addressing:

    %IX byte.bit  input bits      %IW n  input words
    %QX byte.bit  output bits     %QW n  output words
    %MX byte.bit  marker bits     %MW n  marker (memory) words

Bit areas are lists indexed by `byte * 8 + bit`; word areas are lists of Python ints holding
IEC INT values (-32768..32767). Modbus converts to unsigned 16-bit registers at its face.

Concurrency contract (why snapshots and a write queue): the scan owns the live lists. At the
end of each scan the runtime publishes an immutable `Snapshot`; every reader outside the scan
(Modbus, status) reads only the newest snapshot, so a request never mixes two scans and a
32-bit value over two registers is never torn. Writers outside the scan put a whole batch on
the `WriteQueue`; the runtime applies every queued batch at the start of the next scan, each
batch at once.
"""

from __future__ import annotations

import threading
from collections import deque
from dataclasses import dataclass
from typing import Literal

Area = Literal["IX", "QX", "MX", "IW", "QW", "MW"]
BIT_AREAS: tuple[Area, ...] = ("IX", "QX", "MX")
WORD_AREAS: tuple[Area, ...] = ("IW", "QW", "MW")
INT_MIN, INT_MAX = -32768, 32767


@dataclass(frozen=True, slots=True)
class ImageSize:
    """Sizes in bits (bit areas) and words (word areas)."""

    ix: int = 1024
    qx: int = 1024
    mx: int = 1024
    iw: int = 1024
    qw: int = 1024
    mw: int = 1024

    def of(self, area: Area) -> int:
        return getattr(self, area.lower())


@dataclass(frozen=True, slots=True)
class Snapshot:
    """One scan's image, immutable. Bits are bytes of 0/1, one byte per bit."""

    scan: int
    ix: bytes
    qx: bytes
    mx: bytes
    iw: tuple[int, ...]
    qw: tuple[int, ...]
    mw: tuple[int, ...]

    def area(self, area: Area) -> bytes | tuple[int, ...]:
        return getattr(self, area.lower())


@dataclass(frozen=True, slots=True)
class Write:
    """Set `values` starting at `index` of `area` (bit index = byte*8+bit, or word number)."""

    area: Area
    index: int
    values: tuple[int, ...]


class ProcessImage:
    def __init__(self, size: ImageSize | None = None) -> None:
        self.size = size or ImageSize()
        s = self.size
        self.ix = [False] * s.ix
        self.qx = [False] * s.qx
        self.mx = [False] * s.mx
        self.iw = [0] * s.iw
        self.qw = [0] * s.qw
        self.mw = [0] * s.mw

    def area(self, area: Area) -> list:
        return getattr(self, area.lower())

    def snapshot(self, scan: int) -> Snapshot:
        return Snapshot(
            scan,
            bytes(self.ix),
            bytes(self.qx),
            bytes(self.mx),
            tuple(self.iw),
            tuple(self.qw),
            tuple(self.mw),
        )

    def apply(self, write: Write) -> None:
        target = self.area(write.area)
        end = write.index + len(write.values)
        if write.index < 0 or end > len(target):
            raise IndexError(f"%{write.area}{write.index}..{end - 1} outside the image")
        if write.area in BIT_AREAS:
            target[write.index : end] = [bool(v) for v in write.values]
        else:
            target[write.index : end] = [_to_int(v) for v in write.values]


def _to_int(v: int) -> int:
    """Wrap to IEC INT so a register written as 0xFFFF reads back as -1 in ladder logic."""
    v &= 0xFFFF
    return v - 0x10000 if v > INT_MAX else v


class WriteQueue:
    """Batches of writes from outside the scan; each batch is applied whole, in order."""

    def __init__(self) -> None:
        self._batches: deque[tuple[Write, ...]] = deque()
        self._lock = threading.Lock()

    def put(self, batch: tuple[Write, ...] | list[Write]) -> None:
        with self._lock:
            self._batches.append(tuple(batch))

    def drain(self) -> list[tuple[Write, ...]]:
        with self._lock:
            batches = list(self._batches)
            self._batches.clear()
        return batches
