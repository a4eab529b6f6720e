"""`Sample`: one IPO-cycle setpoint of the interpolator.

A plain Python dataclass (not compiled with the planner): the machine, the controller and
the tests read, compare and copy it like any other value.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class Sample:
    """One IPO-cycle setpoint."""

    t: float  # seconds since the Motion was created (cycle count x IPO cycle)
    pose: tuple[float, ...]  # commanded machine position, mm
    velocity: float  # path velocity, mm/s
    line: int  # source line of the block being executed (0 before the first)
    sync: object | None = None  # a sync-point command reached in this cycle
