"""Tag table and memory layout: where every tag, address and timer member lives.

Located tags and IEC addresses live in the process image (`ix`, `qx`, `mx`, `iw`, `qw`,
`mw`). Everything else (internal BOOL/INT tags, timer and counter members, system flags)
lives in one flat list `v` of slots, so the generated scan function reaches every datum with
a single list index.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from plc.image import ImageSize
from plc.ladder.ast import TagDecl, TagType
from plc.ladder.instructions import COUNTER_SLOTS, TIMER_SLOTS

_ADDR = re.compile(r"^%([IQM])([XW]?)(\d+)(?:\.(\d+))?$")

# System tags, predeclared in every program, in slots 0..3 of `v`.
SYSTEM_TAGS: tuple[tuple[str, TagType, str], ...] = (
    ("S_FIRST_SCAN", "BOOL", "1 during the first scan after entering RUN"),
    ("S_OVERFLOW", "BOOL", "set by ADD/SUB/MUL/DIV/MOV when a result wrapped; cleared each scan"),
    ("S_DIV_ZERO", "BOOL", "set by DIV/MOD on division by zero; cleared each scan"),
    ("S_FAULT_RUNG", "INT", "rung number of the last division by zero"),
)
SLOT_FIRST_SCAN, SLOT_OVERFLOW, SLOT_DIV_ZERO, SLOT_FAULT_RUNG = range(4)


@dataclass(frozen=True, slots=True)
class Location:
    """Where a scalar lives: an image area + index, or a slot of `v` (area 'V')."""

    area: str  # IX QX MX IW QW MW or V
    index: int

    @property
    def expr(self) -> str:
        return f"{self.area.lower()}[{self.index}]"


def parse_address(text: str) -> tuple[str, int] | str:
    """`%IX1.2` -> ("IX", 10). Returns an error message string when malformed."""
    m = _ADDR.match(text.upper())
    if not m:
        return f"malformed address {text!r} (expected e.g. %IX0.0, %QW3, %MW10)"
    kind, size, num, bit = m.group(1), m.group(2) or "X", int(m.group(3)), m.group(4)
    area = kind + size
    if size == "X":
        if bit is None:
            return f"bit address {text!r} needs byte.bit (e.g. %{kind}X{num}.0)"
        b = int(bit)
        if b > 7:
            return f"bit number {b} in {text!r} is out of range 0..7"
        return area, num * 8 + b
    if bit is not None:
        return f"word address {text!r} takes no .bit"
    return area, num


def format_address(area: str, index: int) -> str:
    if area.endswith("X"):
        return f"%{area}{index // 8}.{index % 8}"
    return f"%{area}{index}"


@dataclass(slots=True)
class Symbol:
    name: str
    type: TagType
    decl: TagDecl | None
    location: Location | None = None  # BOOL / INT
    members: dict[str, int] = field(default_factory=dict)  # TIMER / COUNTER: member -> slot

    @property
    def slots(self) -> list[int]:
        if self.members:
            return list(self.members.values())
        if self.location is not None and self.location.area == "V":
            return [self.location.index]
        return []


@dataclass(slots=True)
class SymbolTable:
    size: ImageSize
    symbols: dict[str, Symbol] = field(default_factory=dict)  # key: upper-case name
    v_init: list[int | bool] = field(default_factory=list)

    def lookup(self, name: str) -> Symbol | None:
        return self.symbols.get(name.upper())

    def alloc(self, init: int | bool) -> int:
        self.v_init.append(init)
        return len(self.v_init) - 1

    def add(
        self,
        decl: TagDecl | None,
        name: str,
        type_: TagType,
        location: Location | None,
        init: int | None,
    ) -> Symbol:
        sym = Symbol(name, type_, decl)
        if type_ == "TIMER":
            sym.members = {
                m: self.alloc(False if m in ("EN", "TT", "DN") else 0) for m in TIMER_SLOTS
            }
        elif type_ == "COUNTER":
            sym.members = {
                m: self.alloc(0 if m in ("ACC", "PRE") else False) for m in COUNTER_SLOTS
            }
        elif location is None:
            value: int | bool = bool(init) if type_ == "BOOL" else int(init or 0)
            sym.location = Location("V", self.alloc(value))
        else:
            sym.location = location
        self.symbols[name.upper()] = sym
        return sym


def new_table(size: ImageSize) -> SymbolTable:
    table = SymbolTable(size)
    for name, type_, _doc in SYSTEM_TAGS:
        table.add(None, name, type_, None, None)
    return table
