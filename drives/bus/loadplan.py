"""Worst-case bus-load planning for cyclic CANopen traffic, checked before a bus starts.

`load = (bits(SYNC) + sum(bits(PDO)) + sum(heartbeats and other periodic frames)) /
(SYNC period * bitrate)`, every frame counted with worst-case stuffing. Above 100 % the
configuration cannot run and is refused; above 70 % it runs with little room for SDO and EMCY.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

from drives.bus.frame import nominal_bits, worst_case_bits
from drives.errors import DrivesError

WARN_LOAD = 0.70
MAX_LOAD = 1.00


@dataclass(frozen=True)
class CyclicFrame:
    """A frame sent periodically: `per_sync` times per SYNC period, or every `period_s`."""

    name: str
    data_len: int
    per_sync: float = 1.0
    period_s: float | None = None
    extended: bool = False

    def rate_per_window(self, sync_period_s: float) -> float:
        if self.period_s is not None:
            return sync_period_s / self.period_s
        return self.per_sync


@dataclass(frozen=True)
class LoadPlan:
    """Computed figures; loads are fractions of the bitrate (1.0 = 100 %)."""

    bitrate: int
    sync_period_s: float
    worst_case_bits: float
    nominal_bits: float
    worst_case_load: float
    nominal_load: float
    frames: tuple[CyclicFrame, ...] = field(default_factory=tuple)

    def describe(self) -> str:
        return (
            f"worst-case bus load {self.worst_case_load:.1%} "
            f"({self.worst_case_bits:.0f} bits per {self.sync_period_s * 1e3:g} ms SYNC period "
            f"at {self.bitrate / 1e3:g} kbit/s; {self.nominal_load:.1%} without stuffing, "
            f"{len(self.frames)} cyclic frame kinds)"
        )


class BusOverloadError(DrivesError, ValueError):
    """The configured cyclic traffic needs more than the bitrate; `.plan` has the figures."""

    def __init__(self, plan: LoadPlan) -> None:
        super().__init__(f"bus configuration refused: {plan.describe()} exceeds 100 %")
        self.plan = plan


class BusLoadWarning(UserWarning):
    """The configured cyclic traffic exceeds 70 % of the bitrate."""


def plan_load(
    frames: list[CyclicFrame], *, sync_period_s: float, bitrate: int = 1_000_000, check: bool = True
) -> LoadPlan:
    """Worst-case load of `frames` per SYNC period; refuse > 100 %, warn > 70 % if `check`."""
    if sync_period_s <= 0:
        raise ValueError(f"sync_period_s must be > 0, got {sync_period_s}")
    if bitrate <= 0:
        raise ValueError(f"bitrate must be > 0, got {bitrate}")
    worst = sum(
        f.rate_per_window(sync_period_s) * worst_case_bits(f.data_len, extended=f.extended)
        for f in frames
    )
    nominal = sum(
        f.rate_per_window(sync_period_s) * nominal_bits(f.data_len, extended=f.extended)
        for f in frames
    )
    capacity = sync_period_s * bitrate
    plan = LoadPlan(
        bitrate=bitrate,
        sync_period_s=sync_period_s,
        worst_case_bits=worst,
        nominal_bits=nominal,
        worst_case_load=worst / capacity,
        nominal_load=nominal / capacity,
        frames=tuple(frames),
    )
    if check:
        if plan.worst_case_load > MAX_LOAD:
            raise BusOverloadError(plan)
        if plan.worst_case_load > WARN_LOAD:
            warnings.warn(
                f"bus load high: {plan.describe()} is above 70 %", BusLoadWarning, stacklevel=2
            )
    return plan


def axis_traffic(
    n_axes: int,
    *,
    rpdos_per_axis: int = 1,
    tpdos_per_axis: int = 1,
    rpdo_bytes: int = 8,
    tpdo_bytes: int = 8,
    heartbeat_s: float | None = None,
    master_heartbeat: bool = False,
) -> list[CyclicFrame]:
    """The cyclic frames of `n_axes` synchronous drives plus the SYNC itself."""
    frames = [CyclicFrame("SYNC", 0)]
    for axis in range(1, n_axes + 1):
        frames += [CyclicFrame(f"axis{axis}.RPDO", rpdo_bytes) for _ in range(rpdos_per_axis)]
        frames += [CyclicFrame(f"axis{axis}.TPDO", tpdo_bytes) for _ in range(tpdos_per_axis)]
        if heartbeat_s:
            frames.append(CyclicFrame(f"axis{axis}.heartbeat", 1, period_s=heartbeat_s))
    if heartbeat_s and master_heartbeat:
        frames.append(CyclicFrame("master.heartbeat", 1, period_s=heartbeat_s))
    return frames
