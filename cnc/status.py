"""The machine's status snapshot: what a controller shows on its screen, once per cycle.

A machine builds one `MachineStatus` per IPO/PLC cycle and hands it to its status face
(`cnc.faces.shdr.ShdrAdapter.publish`). It is plain data: no behaviour, no clock, no I/O, so
the SHDR formatter can diff two snapshots and a test can write one by hand.

Vocabulary follows MTConnect where MTConnect has a word for it (execution, controller mode,
emergency stop, availability), so the status face needs no translation tables. Units are the
controller's: mm, mm/min, rpm, percent, ms.
"""

from __future__ import annotations

from dataclasses import dataclass, field

# --- controlled vocabularies (MTConnect names) -------------------------------------------

AVAILABLE = "AVAILABLE"
UNAVAILABLE = "UNAVAILABLE"
AVAILABILITY = (AVAILABLE, UNAVAILABLE)

EXECUTION = (
    "READY",
    "ACTIVE",
    "INTERRUPTED",
    "FEED_HOLD",
    "STOPPED",
    "OPTIONAL_STOP",
    "PROGRAM_STOPPED",
    "PROGRAM_COMPLETED",
)
CONTROLLER_MODE = ("AUTOMATIC", "MANUAL_DATA_INPUT", "MANUAL", "EDIT")
# The operator's mode switch has more positions than MTConnect has modes: JOG and REF are
# both MANUAL, told apart by the sub-mode.
MODE_DETAIL = ("AUTO", "MDI", "JOG", "REF", "EDIT")
EMERGENCY_STOP = ("ARMED", "TRIGGERED")
ALARM_SOURCES = ("NC", "PLC", "DRIVE", "BUS", "DNC")
ALARM_SEVERITIES = ("WARNING", "FAULT")
ADAPTIVE_CONTROL = ("OFF", "STANDBY", "ACTIVE", "LIMITING")


@dataclass(frozen=True, slots=True)
class Alarm:
    """One entry of the controller's alarm list.

    `number` is the native alarm code (shown as the MTConnect nativeCode); `axis` names the
    axis for drive and following-error alarms; `time` is when it was raised, seconds on the
    machine's clock (informative only: the status stream stamps its own times).
    """

    number: int
    text: str
    source: str = "NC"
    severity: str = "FAULT"
    axis: str | None = None
    time: float = 0.0


@dataclass(frozen=True, slots=True)
class AxisStatus:
    """One axis: machine coordinates, mm (degrees for a rotary axis)."""

    actual: float = 0.0
    commanded: float = 0.0


@dataclass(frozen=True, slots=True)
class CanBusLoad:
    """CAN bus load over the last SYNC windows, percent of the bit rate."""

    mean: float = 0.0
    peak: float = 0.0


@dataclass(frozen=True, slots=True)
class ToolTipStatus:
    """mill5: the tool tip by forward kinematics of the interpolated joints (workpiece
    frame, mm) and its deviation from the programmed straight line (cnc.controller.tooltip):
    now, the running program's peak, and the peak of the drives' actual joints."""

    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    deviation: float = 0.0
    peak: float = 0.0
    actual_peak: float = 0.0


@dataclass(frozen=True, slots=True)
class MachineStatus:
    """A snapshot of the controller's state. Fields left at their defaults mean "idle"."""

    availability: str = AVAILABLE
    execution: str = "READY"
    controller_mode: str = "AUTOMATIC"
    mode_detail: str = "AUTO"
    program: str = ""
    line: int = 0
    block: str = ""
    path_feed_rate: float = 0.0  # mm/min, actual along the path
    axes: dict[str, AxisStatus] = field(default_factory=dict)
    spindle_speed: float = 0.0  # rpm, actual
    spindle_load: float = 0.0  # percent of rated
    spindle_override: float = 100.0  # percent
    feed_override: float = 100.0  # percent
    rapid_override: float = 100.0  # percent
    alarms: tuple[Alarm, ...] = ()
    part_count: int = 0
    emergency_stop: str = "ARMED"
    can_bus_load: CanBusLoad = field(default_factory=CanBusLoad)
    plc_scan_time_ms: float = 0.0
    adaptive_control: str = "OFF"
    unreferenced: tuple[str, ...] = ()  # axes not homed since power-on / losing the reference
    cycle_start_refused: str = ""  # the NC's reason for the last refused cycle start
    tool_tip: ToolTipStatus | None = None  # mill5 only

    def __post_init__(self) -> None:
        # Cheap guards against typos in the trade words; the machine builds one of these
        # every cycle, so only the enumerations are checked, not the numbers.
        _one_of("availability", self.availability, AVAILABILITY)
        _one_of("execution", self.execution, EXECUTION)
        _one_of("controller_mode", self.controller_mode, CONTROLLER_MODE)
        _one_of("mode_detail", self.mode_detail, MODE_DETAIL)
        _one_of("emergency_stop", self.emergency_stop, EMERGENCY_STOP)
        _one_of("adaptive_control", self.adaptive_control, ADAPTIVE_CONTROL)
        for alarm in self.alarms:
            _one_of("alarm source", alarm.source, ALARM_SOURCES)
            _one_of("alarm severity", alarm.severity, ALARM_SEVERITIES)


def _one_of(what: str, value: str, allowed: tuple[str, ...]) -> None:
    if value not in allowed:
        raise ValueError(f"MachineStatus: {what} {value!r} is not one of {', '.join(allowed)}")
