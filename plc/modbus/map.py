"""Where each process-image area sits in the four Modbus tables.

The layout follows OpenPLC v3's slave map so an HMI configured for OpenPLC reads the same
addresses here:

    coils             0 ..           %QX (bit index byte*8+bit)
                      8192 ..        %MX (offset `mx_coil_offset`, after OpenPLC's 8192 %QX coils)
    discrete inputs   0 ..           %IX
    input registers   0 ..           %IW
    holding registers 0 ..           %QW
                      1024 ..        %MW (offset `mw_register_offset`, as OpenPLC)

Addresses are 0-based on the wire. An address not covered by an area answers exception 02,
never a plausible zero.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from plc.image import Area, ImageSize

Table = Literal["coil", "di", "ir", "hr"]
TABLES: tuple[Table, ...] = ("coil", "di", "ir", "hr")
MODBUS_ADDRESSES = 65536

#: Piece of a request that falls into one image area: (area, first index in area, count).
Piece = tuple[Area, int, int]


@dataclass(frozen=True, slots=True)
class Segment:
    """`count` consecutive Modbus addresses from `start` map to `area` from index 0."""

    table: Table
    start: int
    count: int
    area: Area

    @property
    def end(self) -> int:
        return self.start + self.count


class ModbusMap:
    """The Modbus address map of one PLC image; resolves requests to image pieces."""

    def __init__(
        self,
        size: ImageSize | None = None,
        *,
        mx_coil_offset: int = 8192,
        mw_register_offset: int = 1024,
    ) -> None:
        self.size = size = size or ImageSize()
        self.mx_coil_offset = mx_coil_offset
        self.mw_register_offset = mw_register_offset
        segments = [
            Segment("coil", 0, size.qx, "QX"),
            Segment("coil", mx_coil_offset, size.mx, "MX"),
            Segment("di", 0, size.ix, "IX"),
            Segment("ir", 0, size.iw, "IW"),
            Segment("hr", 0, size.qw, "QW"),
            Segment("hr", mw_register_offset, size.mw, "MW"),
        ]
        self._by_table: dict[Table, tuple[Segment, ...]] = {}
        for table in TABLES:
            segs = sorted((s for s in segments if s.table == table and s.count), key=_start)
            for a, b in zip(segs, segs[1:], strict=False):
                if a.end > b.start:
                    raise ValueError(
                        f"Modbus map: {table} %{a.area} ({a.start}..{a.end - 1}) overlaps "
                        f"%{b.area} starting at {b.start}; raise the %{b.area} offset"
                    )
            if segs and segs[-1].end > MODBUS_ADDRESSES:
                s = segs[-1]
                raise ValueError(
                    f"Modbus map: {table} %{s.area} ends at {s.end - 1}, beyond address 65535"
                )
            self._by_table[table] = tuple(segs)

    def segments(self, table: Table) -> tuple[Segment, ...]:
        return self._by_table[table]

    def resolve(self, table: Table, address: int, count: int) -> list[Piece] | None:
        """Image pieces for `count` addresses from `address`, or None if any is unmapped.

        A request may run from one area into the next when they are contiguous on the wire
        (e.g. %QW1023 then %MW0 at 1023..1024 with the default sizes).
        """
        pieces: list[Piece] = []
        end = address + count
        for seg in self._by_table[table]:
            if address < seg.start:
                return None
            if address >= seg.end:
                continue
            take = min(end, seg.end) - address
            pieces.append((seg.area, address - seg.start, take))
            address += take
            if address == end:
                return pieces
        return None

    def address_of(self, area: Area, index: int) -> tuple[Table, int]:
        """Modbus (table, address) of image `area[index]`; ValueError outside the image."""
        for segs in self._by_table.values():
            for seg in segs:
                if seg.area == area:
                    if not 0 <= index < seg.count:
                        raise ValueError(
                            f"%{area}{_iec_index(area, index)} is outside the image "
                            f"(%{area} has {seg.count} {'bits' if area[1] == 'X' else 'words'})"
                        )
                    return seg.table, seg.start + index
        raise ValueError(f"%{area} is not in the Modbus map (image size 0)")


def _start(seg: Segment) -> int:
    return seg.start


def _iec_index(area: str, index: int) -> str:
    return f"{index // 8}.{index % 8}" if area.endswith("X") else str(index)
