"""The write allow-list: which Modbus addresses a client may write.

Everything is read-only unless listed. Two spellings, mixable in one comma-separated string:

    coil:0-15,hr:1024-1100,hr:7        Modbus table and 0-based addresses (inclusive ranges)
    %QX0.0-%QX1.7,%MW0-%MW99,%QW5      IEC direct addresses (the second end may drop the
                                       prefix: %MW0-99, %QX0.0-1.7)

Tables: `coil` (alias `coils`, `co`) and `hr` (alias `holding`). Discrete inputs, input
registers, %IX and %IW cannot be listed: Modbus has no function that writes them.

A register range may carry the values it accepts, as IEC INT (signed 16-bit):

    %MW0-%MW2=0..200,hr:1030=-100..100

A write with any value outside is refused whole with exception 03 (illegal data value), as a
real control refuses an override of 65535 % instead of wrapping it to something else.
"""

from __future__ import annotations

import bisect
import re
from dataclasses import dataclass

from plc.errors import PlcError
from plc.image import Area
from plc.modbus.map import ModbusMap, Table

_TABLE_ALIASES: dict[str, Table] = {
    "coil": "coil",
    "coils": "coil",
    "co": "coil",
    "hr": "hr",
    "holding": "hr",
}
_READ_ONLY_TABLES = {"di", "ir", "discrete", "input"}
_WRITABLE_AREAS: tuple[Area, ...] = ("QX", "MX", "QW", "MW")
_IEC = re.compile(r"%([IQM])([XW])(\d+)(?:\.(\d+))?$", re.IGNORECASE)
_BARE = re.compile(r"(\d+)(?:\.(\d+))?$")


class AllowListError(PlcError, ValueError):
    """A malformed allow-list; the message names the item, its column and the reason."""


@dataclass(frozen=True, slots=True)
class AllowEntry:
    """One listed range, inclusive, either in a Modbus table or in an image area."""

    space: str  # a Table ("coil"/"hr") or an Area ("QX", "MW", ...)
    first: int
    last: int
    text: str
    values: tuple[int, int] | None = None  # accepted INT values, inclusive (registers only)


class AllowList:
    """Parsed allow-list, still independent of any map; `resolve` binds it to one."""

    def __init__(self, entries: tuple[AllowEntry, ...] | list[AllowEntry] = ()) -> None:
        self.entries = tuple(entries)

    @classmethod
    def read_only(cls) -> AllowList:
        return cls(())

    @classmethod
    def parse(cls, text: str | None) -> AllowList:
        """Parse `coil:0-15,hr:1024-1100,%QX0.0-%QX1.7,...`; raises AllowListError."""
        if text is None or not text.strip() or text.strip().lower() == "none":
            return cls(())
        entries = []
        col = 1
        for raw in text.split(","):
            item = raw.strip()
            item_col = col + (len(raw) - len(raw.lstrip()))
            col += len(raw) + 1
            if not item:
                raise AllowListError(f"writable: col {item_col}: empty item (stray comma?)")
            try:
                entries.append(_parse_item(item))
            except AllowListError as e:
                raise AllowListError(f"writable: col {item_col}: {item!r}: {e}") from None
        return cls(entries)

    def __str__(self) -> str:
        return ",".join(e.text for e in self.entries) or "none"

    def __repr__(self) -> str:
        return f"AllowList.parse({str(self)!r})"

    def resolve(self, mb_map: ModbusMap) -> WriteGuard:
        """Bind to `mb_map`; AllowListError if a listed range lies outside the map."""
        ranges: dict[Table, list[tuple[int, int]]] = {"coil": [], "hr": []}
        limits: list[tuple[int, int, int, int]] = []
        for e in self.entries:
            if e.space in ("coil", "hr"):
                table = e.space
                first, last = e.first, e.last
                if mb_map.resolve(table, first, last - first + 1) is None:
                    raise AllowListError(
                        f"writable: {e.text!r}: {table} {first}..{last} is not (entirely) "
                        f"in the Modbus map"
                    )
            else:
                try:
                    table, first = mb_map.address_of(e.space, e.first)
                    _, last = mb_map.address_of(e.space, e.last)
                except ValueError as err:
                    raise AllowListError(f"writable: {e.text!r}: {err}") from None
            ranges[table].append((first, last + 1))
            if e.values is not None:
                limits.append((first, last + 1, *e.values))
        return WriteGuard({t: _merge(r) for t, r in ranges.items()}, limits)


class WriteGuard:
    """Allow-list resolved to merged half-open Modbus address ranges per writable table."""

    def __init__(
        self,
        ranges: dict[Table, list[tuple[int, int]]],
        limits: list[tuple[int, int, int, int]] | None = None,
    ) -> None:
        self._ranges = ranges
        self._starts = {t: [a for a, _ in r] for t, r in ranges.items()}
        #: holding-register value limits: (first, end, lowest, highest)
        self._limits = tuple(limits or ())

    def values_allowed(self, address: int, values: tuple[int, ...]) -> bool:
        """True when every INT value written from holding register `address` on lies in
        the value range listed for its register (registers without one take any value)."""
        for first, end, low, high in self._limits:
            for i in range(max(first, address), min(end, address + len(values))):
                if not low <= values[i - address] <= high:
                    return False
        return True

    def allows(self, table: Table, address: int, count: int) -> bool:
        """True when every address in `address .. address+count-1` is listed."""
        ranges = self._ranges.get(table)
        if not ranges:
            return False
        i = bisect.bisect_right(self._starts[table], address) - 1
        return i >= 0 and address + count <= ranges[i][1]

    def ranges(self, table: Table) -> list[tuple[int, int]]:
        return list(self._ranges.get(table, ()))


def _merge(ranges: list[tuple[int, int]]) -> list[tuple[int, int]]:
    merged: list[tuple[int, int]] = []
    for a, b in sorted(ranges):
        if merged and a <= merged[-1][1]:
            merged[-1] = (merged[-1][0], max(merged[-1][1], b))
        else:
            merged.append((a, b))
    return merged


_VALUES = re.compile(r"\s*(-?\d+)\s*\.\.\s*(-?\d+)\s*$")


def _parse_item(item: str) -> AllowEntry:
    item, eq, values_txt = item.partition("=")
    entry = _parse_addresses(item.strip())
    if not eq:
        return entry
    if entry.space not in ("hr", "QW", "MW"):
        raise AllowListError("a value range (=LOW..HIGH) applies to registers only")
    m = _VALUES.match(values_txt)
    if not m:
        raise AllowListError(f"value range {values_txt!r} is not LOW..HIGH (e.g. =0..200)")
    low, high = int(m.group(1)), int(m.group(2))
    if not -32768 <= low <= high <= 32767:
        raise AllowListError(f"value range {low}..{high} is not an ordered INT range")
    return AllowEntry(
        entry.space, entry.first, entry.last, f"{entry.text}={low}..{high}", (low, high)
    )


def _parse_addresses(item: str) -> AllowEntry:
    if item.startswith("%"):
        return _parse_iec(item)
    table_txt, sep, rng = item.partition(":")
    if not sep:
        raise AllowListError("expected TABLE:FIRST[-LAST] (e.g. hr:0-9) or an IEC range (%MW0-9)")
    key = table_txt.strip().lower()
    if key in _READ_ONLY_TABLES:
        raise AllowListError(f"table {table_txt!r} is read-only in Modbus; only coil and hr")
    table = _TABLE_ALIASES.get(key)
    if table is None:
        raise AllowListError(f"unknown table {table_txt!r}; use coil or hr")
    first_txt, dash, last_txt = rng.strip().partition("-")
    first = _number(first_txt, "first address")
    last = _number(last_txt, "last address") if dash else first
    _check_order(first, last)
    if last > 65535:
        raise AllowListError(f"address {last} beyond 65535")
    text = f"{table}:{first}-{last}" if dash else f"{table}:{first}"
    return AllowEntry(table, first, last, text)


def _parse_iec(item: str) -> AllowEntry:
    first_txt, dash, last_txt = item.partition("-")
    area, first = _iec_address(first_txt.strip())
    if dash:
        last_txt = last_txt.strip()
        if last_txt.startswith("%"):
            area2, last = _iec_address(last_txt)
            if area2 != area:
                raise AllowListError(f"range runs from %{area} into %{area2}; split it")
        else:
            last = _bare_index(area, last_txt)
    else:
        last = first
    _check_order(first, last)
    return AllowEntry(area, first, last, item.replace(" ", ""))


def _iec_address(txt: str) -> tuple[Area, int]:
    m = _IEC.match(txt)
    if not m:
        raise AllowListError(f"{txt!r} is not an IEC address like %QX0.0 or %MW10")
    area: Area = (m.group(1) + m.group(2)).upper()  # type: ignore[assignment]
    if area not in _WRITABLE_AREAS:
        raise AllowListError(f"%{area} is an input area; Modbus cannot write it")
    return area, _index(area, m.group(3), m.group(4), txt)


def _bare_index(area: Area, txt: str) -> int:
    m = _BARE.match(txt)
    if not m:
        raise AllowListError(f"range end {txt!r} is not a %{area} address")
    return _index(area, m.group(1), m.group(2), txt)


def _index(area: Area, major: str, minor: str | None, txt: str) -> int:
    if area.endswith("X"):
        if minor is None:
            raise AllowListError(f"{txt!r}: bit address needs byte.bit (e.g. %{area}0.3)")
        bit = int(minor)
        if bit > 7:
            raise AllowListError(f"{txt!r}: bit number {bit} is not 0..7")
        return int(major) * 8 + bit
    if minor is not None:
        raise AllowListError(f"{txt!r}: word address takes no .bit")
    return int(major)


def _number(txt: str, what: str) -> int:
    txt = txt.strip()
    if not txt.isdigit():
        raise AllowListError(f"{what} {txt!r} is not a decimal number")
    return int(txt)


def _check_order(first: int, last: int) -> None:
    if last < first:
        raise AllowListError(f"range end {last} is before its start {first}")
