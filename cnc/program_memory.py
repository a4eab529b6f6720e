"""The controller's part program memory: programs by O number within a capacity in bytes.

O numbers run 1..99999999: a Fanuc with the 8-digit program number option stores
O00000001..O99999999 (Haas NGC takes 5 digits and more too); 4-digit controls stop at O9999.
The whole chain (check, memory, select, DNC port, PLC, DNC host, REST) takes 8 digits.
"""

from __future__ import annotations

import hashlib
import threading
from dataclasses import dataclass

from cnc.errors import CncError

MAX_PROGRAM_NUMBER = 99_999_999


def program_number_error(number: int) -> str | None:
    """Why `number` is not a storable O number, or None."""
    if not 1 <= number <= MAX_PROGRAM_NUMBER:
        return f"program number O{number} outside O1..O{MAX_PROGRAM_NUMBER}"
    return None


@dataclass(frozen=True, slots=True)
class ProgramEntry:
    number: int
    size: int  # bytes
    sha256: str


class MemoryFull(CncError):
    def __init__(self, number: int, size: int, free: int, capacity: int) -> None:
        super().__init__(
            f"program O{number:04d} needs {size} bytes but only {free} of {capacity} bytes are "
            "free; delete programs or drip-feed it (BTR)"
        )
        self.number, self.size, self.free, self.capacity = number, size, free, capacity


class ProgramMemory:
    """Thread-safe: the DNC port stores while the NC reads."""

    def __init__(self, capacity_bytes: int) -> None:
        if capacity_bytes <= 0:
            raise ValueError("program memory capacity must be > 0 bytes")
        self.capacity = capacity_bytes
        self._programs: dict[int, str] = {}
        self._lock = threading.Lock()

    @property
    def used(self) -> int:
        with self._lock:
            return sum(_size(t) for t in self._programs.values())

    @property
    def free(self) -> int:
        return self.capacity - self.used

    def fits(self, number: int, size: int) -> bool:
        """Would a program of `size` bytes stored as `number` fit (replacing any old copy)?"""
        with self._lock:
            others = sum(_size(t) for n, t in self._programs.items() if n != number)
        return others + size <= self.capacity

    def store(self, number: int, text: str) -> ProgramEntry:
        why = program_number_error(number)
        if why is not None:
            raise ValueError(why)
        size = _size(text)
        with self._lock:
            others = sum(_size(t) for n, t in self._programs.items() if n != number)
            if others + size > self.capacity:
                raise MemoryFull(number, size, self.capacity - others, self.capacity)
            self._programs[number] = text
        return ProgramEntry(number, size, _sha(text))

    def get(self, number: int) -> str:
        with self._lock:
            return self._programs[number]

    def __contains__(self, number: int) -> bool:
        with self._lock:
            return number in self._programs

    def delete(self, number: int) -> None:
        with self._lock:
            del self._programs[number]

    def directory(self) -> list[ProgramEntry]:
        with self._lock:
            items = sorted(self._programs.items())
        return [ProgramEntry(n, _size(t), _sha(t)) for n, t in items]


def _size(text: str) -> int:
    return len(text.encode("utf-8"))


def _sha(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()
