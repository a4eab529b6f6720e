"""Axis configuration and the records the axis group hands upward (feedback, faults)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from drives.errors import DrivesError


@dataclass(frozen=True)
class AxisConfig:
    """One axis of the group: its drive on the bus and the limits written to it by SDO.

    Positions are in mm at the API, `units_per_mm` user units on the bus (1000: 1 um, the
    virtual drive's default). `line` selects the CAN line (index into the group's buses).
    """

    name: str
    node_id: int
    line: int = 0
    units_per_mm: float = 1000.0
    min_mm: float | None = None  # 0x607D:1 software limit (None: leave the drive's)
    max_mm: float | None = None  # 0x607D:2
    max_velocity_mm_s: float | None = None  # 0x607F max profile velocity
    max_accel_mm_s2: float | None = None  # 0x6083 / 0x6084 profile acceleration / deceleration
    quick_stop_decel_mm_s2: float | None = None  # 0x6085
    following_error_window_mm: float | None = None  # 0x6065 (None: the drive's default)
    following_error_timeout_ms: int | None = None  # 0x6066
    homing_method: int = 35  # 0x6098 (CiA 402-2 numbering; 35/37 = current position)
    home_offset_mm: float = 0.0  # 0x607C
    homing_search_mm_s: float = 20.0  # 0x6099:1 switch search (fast)
    homing_creep_mm_s: float = 2.0  # 0x6099:2 zero search (creep)
    homing_accel_mm_s2: float = 1000.0  # 0x609A
    homing_timeout_s: float = 120.0

    def __post_init__(self) -> None:
        if not self.name:
            raise ValueError("axis: name must not be empty")
        if not 1 <= self.node_id <= 127:
            raise ValueError(f"axis {self.name}: node_id must be 1..127, got {self.node_id}")
        if self.line < 0:
            raise ValueError(f"axis {self.name}: line must be >= 0, got {self.line}")
        if not (self.units_per_mm > 0 and math.isfinite(self.units_per_mm)):
            raise ValueError(f"axis {self.name}: units_per_mm must be > 0")
        if self.min_mm is not None and self.max_mm is not None and self.min_mm >= self.max_mm:
            raise ValueError(f"axis {self.name}: min_mm {self.min_mm} >= max_mm {self.max_mm}")
        for key in (
            "max_velocity_mm_s",
            "max_accel_mm_s2",
            "quick_stop_decel_mm_s2",
            "following_error_window_mm",
            "homing_search_mm_s",
            "homing_creep_mm_s",
            "homing_accel_mm_s2",
            "homing_timeout_s",
        ):
            value = getattr(self, key)
            if value is not None and not (value > 0 and math.isfinite(value)):
                raise ValueError(f"axis {self.name}: {key} must be > 0, got {value!r}")

    def to_units(self, mm: float) -> int:
        return round(mm * self.units_per_mm)

    def to_mm(self, units: int) -> float:
        return units / self.units_per_mm


@dataclass(frozen=True)
class AxisFault:
    """A fault reported upward: from an EMCY, a lost heartbeat, a boot-up, or the statusword."""

    axis: str
    node_id: int
    emcy_code: int
    error_register: int
    text: str
    time: float  # group time (s): virtual in lockstep, since start in realtime
    source: str = "emcy"  # "emcy" | "heartbeat" | "bootup" | "statusword" | "tpdo"

    def __str__(self) -> str:
        return (
            f"axis {self.axis} (node {self.node_id}): {self.text} "
            f"[EMCY 0x{self.emcy_code:04X}, 0x1001=0x{self.error_register:02X}, {self.source}]"
        )


@dataclass
class AxisFeedback:
    """What one IPO cycle brings back, per axis name.

    Positions are the drives' 0x6064 sampled at this cycle's SYNC (before the targets of
    this cycle were integrated: one IPO cycle of transport delay, as on a real bus).
    """

    time: float
    cycle: int
    position_mm: dict[str, float]
    statusword: dict[str, int]
    following_error_mm: dict[str, float | None]
    state: dict[str, str]
    fresh: dict[str, bool]  # a TPDO arrived for this SYNC (False: values are a cycle old)
    faults: list[AxisFault] = field(default_factory=list)  # new since the previous cycle

    @property
    def all_fresh(self) -> bool:
        return all(self.fresh.values())


class AxisError(DrivesError, RuntimeError):
    """An axis did not do what the group asked (state, homing, boot): names axis and state."""

    def __init__(self, message: str, axes: tuple[str, ...] = ()) -> None:
        super().__init__(message)
        self.axes = axes
