"""The CiA 402 objects the drive application owns: type, access, default, value limits.

Position, velocity and acceleration objects are in *user units*: by default 1 unit = 1 µm
(0x6092 feed constant 10000 units per screw revolution of a 10 mm lead), velocity µm/s,
acceleration µm/s². 0x6080 is in motor rpm; torque/current objects in ‰ of rated.
"""

from __future__ import annotations

from dataclasses import dataclass

from drives.cia402.homing import SUPPORTED_METHODS

I8, U8, I16, U16, I32, U32 = "i8", "u8", "i16", "u16", "i32", "u32"
TYPE_RANGE = {
    I8: (-(1 << 7), (1 << 7) - 1),
    U8: (0, (1 << 8) - 1),
    I16: (-(1 << 15), (1 << 15) - 1),
    U16: (0, (1 << 16) - 1),
    I32: (-(1 << 31), (1 << 31) - 1),
    U32: (0, (1 << 32) - 1),
}
TYPE_SIZE = {I8: 1, U8: 1, I16: 2, U16: 2, I32: 4, U32: 4}

SUPPORTED_MODES = (0, 1, 3, 6, 8, 9)  # 0 = no mode: hold position
SUPPORTED_DRIVE_MODES = 0x001 | 0x004 | 0x020 | 0x080 | 0x100  # 0x6502: PP PV HM CSP CSV


@dataclass(frozen=True, slots=True)
class Entry:
    name: str
    dtype: str
    writable: bool
    default: int = 0
    low: int | None = None  # tighter than the type range
    high: int | None = None
    allowed: frozenset[int] | None = None  # a value set (abort 0x06090030 outside it)


def _e(name, dtype, writable=True, default=0, low=None, high=None, allowed=None) -> Entry:
    return Entry(name, dtype, writable, default, low, high, allowed)


# index -> {subindex: Entry}; records carry their sub 0 "number of entries" explicitly.
OBJECTS: dict[int, dict[int, Entry]] = {
    0x603F: {0: _e("error code", U16, False)},
    0x6007: {0: _e("abort connection option code", I16, default=1, low=0, high=3)},
    0x6040: {0: _e("controlword", U16)},
    0x6041: {0: _e("statusword", U16, False)},
    0x605A: {0: _e("quick stop option code", I16, default=2, low=0, high=8)},
    0x605B: {0: _e("shutdown option code", I16, default=0, low=0, high=1)},
    0x605C: {0: _e("disable operation option code", I16, default=1, low=0, high=1)},
    0x605D: {0: _e("halt option code", I16, default=1, low=1, high=4)},
    0x605E: {0: _e("fault reaction option code", I16, default=2, low=0, high=4)},
    0x6060: {0: _e("modes of operation", I8, allowed=frozenset(SUPPORTED_MODES))},
    0x6061: {0: _e("modes of operation display", I8, False)},
    0x6062: {0: _e("position demand value", I32, False)},
    0x6063: {0: _e("position actual internal value", I32, False)},
    0x6064: {0: _e("position actual value", I32, False)},
    0x6065: {0: _e("following error window", U32, default=60000)},
    0x6066: {0: _e("following error time out", U16, default=20)},
    0x6067: {0: _e("position window", U32, default=10)},
    0x6068: {0: _e("position window time", U16, default=10)},
    0x606B: {0: _e("velocity demand value", I32, False)},
    0x606C: {0: _e("velocity actual value", I32, False)},
    0x606D: {0: _e("velocity window", U16, default=1000)},
    0x606E: {0: _e("velocity window time", U16, default=10)},
    0x606F: {0: _e("velocity threshold", U16, default=1000)},
    0x6072: {0: _e("max torque", U16, default=3000, low=0, high=3000)},
    0x6075: {0: _e("motor rated current", U32, False)},
    0x6076: {0: _e("motor rated torque", U32, False)},
    0x6077: {0: _e("torque actual value", I16, False)},
    0x6078: {0: _e("current actual value", I16, False)},
    0x607A: {0: _e("target position", I32)},
    0x607C: {0: _e("home offset", I32)},
    0x607D: {
        0: _e("number of entries", U8, False, 2),
        1: _e("min position limit", I32, default=-(1 << 31)),
        2: _e("max position limit", I32, default=(1 << 31) - 1),
    },
    0x607F: {0: _e("max profile velocity", U32, default=833_000, low=1)},
    0x6080: {0: _e("max motor speed", U32, default=5000, low=1)},
    0x6081: {0: _e("profile velocity", U32, default=100_000)},
    0x6083: {0: _e("profile acceleration", U32, default=2_000_000, low=1)},
    0x6084: {0: _e("profile deceleration", U32, default=2_000_000, low=1)},
    0x6085: {0: _e("quick stop deceleration", U32, default=10_000_000, low=1)},
    0x608F: {
        0: _e("number of entries", U8, False, 2),
        1: _e("encoder increments", U32, False),
        2: _e("motor revolutions", U32, False, 1),
    },
    0x6091: {
        0: _e("number of entries", U8, False, 2),
        1: _e("motor revolutions", U32, False),
        2: _e("shaft revolutions", U32, False),
    },
    0x6092: {
        0: _e("number of entries", U8, False, 2),
        1: _e("feed", U32, default=10_000, low=1),
        2: _e("shaft revolutions", U32, default=1, low=1),
    },
    0x6098: {0: _e("homing method", I8, default=35, allowed=SUPPORTED_METHODS)},
    0x6099: {
        0: _e("number of entries", U8, False, 2),
        1: _e("speed during search for switch", U32, default=20_000, low=1),
        2: _e("speed during search for zero", U32, default=2_000, low=1),
    },
    0x609A: {0: _e("homing acceleration", U32, default=1_000_000, low=1)},
    0x60C2: {
        0: _e("number of entries", U8, False, 2),
        1: _e("interpolation time period value", U8, default=2),
        2: _e("interpolation time index", I8, default=-3, low=-6, high=0),
    },
    0x60F4: {0: _e("following error actual value", I32, False)},
    0x60FD: {0: _e("digital inputs", U32, False)},
    0x60FF: {0: _e("target velocity", I32)},
    0x6502: {0: _e("supported drive modes", U32, False, SUPPORTED_DRIVE_MODES)},
}

# Writable only while the power stage is off (abort 0x08000022 otherwise).
NEEDS_POWER_OFF = frozenset({0x6092})
