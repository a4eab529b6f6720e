"""The data that crosses the controller's boundary once per IPO cycle.

The machine shell (drives, PLC runtime, faces) builds a `CycleInputs` from the axis layer's
feedback and the PLC's last scan, calls `Controller.cycle(inputs)` exactly once per IPO cycle
and applies the `CycleOutputs`: targets and the axis command to the axis layer, the NC->PLC
signals to the PLC before its next scan, the status to the status face.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from cnc.errors import CncError
from cnc.status import MachineStatus

AXIS_COMMANDS = ("none", "enable", "disable", "quick_stop", "home", "fault_reset")


class CommandRefused(CncError):
    """A command the current mode or state forbids; `reason` says why, in the operator's
    words ("cycle start refused: machine not homed (X, Z)")."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


@dataclass(frozen=True)
class AxisFeedback:
    """What the axis layer reports once per IPO cycle."""

    actual: Mapping[str, float]  # mm, machine coordinates, per axis name
    following_error: Mapping[str, float]  # mm
    enabled: bool  # all drives in OPERATION ENABLED
    homed: Mapping[str, bool]
    homing: bool  # a homing run is in progress
    faults: tuple[tuple[str, int, str], ...] = ()  # (axis, EMCY/603F code, text) since last


@dataclass(frozen=True)
class CycleInputs:
    t: float  # virtual time, s
    plc: Mapping[str, int | bool]  # PLC->NC signals by plc.signals name, latest scan
    axes: AxisFeedback


@dataclass(frozen=True)
class CycleOutputs:
    targets: Mapping[str, float]  # commanded position per axis, mm
    axis_command: str  # one of AXIS_COMMANDS; a one-shot request (see docs/controller.md)
    home_axes: tuple[str, ...]  # with axis_command == "home": which axes, in order
    plc: Mapping[str, int | bool]  # NC->PLC signal values to write before the next scan
    status: MachineStatus = field(default_factory=MachineStatus)
