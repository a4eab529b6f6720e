"""The NC's alarm list: numbered alarms with a source, an axis, a time and a reset rule.

Reset rules (what the operator's RESET does to an alarm):

    RESET       cleared by reset (the cause was an event: a following error, a program error)
    CAUSE_GONE  cleared by reset only once its cause is gone (E-stop released, drive fault
                no longer reported); otherwise it stays
    SELF        mirrors a condition (a PLC alarm): it goes away with the condition, not by reset

Alarms that lose the axes' reference (E-stop, encoder faults) additionally need a homing run
before AUTO/MDI cycle start: that is the controller's reference state, not the alarm list.
"""

from __future__ import annotations

from dataclasses import dataclass

from cnc.status import Alarm

RESET, CAUSE_GONE, SELF = "reset", "cause_gone", "self"

# NC alarm numbers (3000 series; 1000s are the PLC program's, 2000s the DNC port's).
ESTOP = 3001
AXES_DISABLED = 3002
PLC_STOPPED = 3003  # the PLC left RUN (STOP, or FAULT: its watchdog, a program fault)
FOLLOWING_ERROR = 3010
PROGRAM_ERROR = 3020
HOMING_FAILED = 3030
NOT_REFERENCED = 3031  # a warning per axis that lost its reference: home the machine
DRIVE_FAULT = 3040
BUS_FAULT = 3041
DRIP_ABORTED = 3050

# The machine-tool PLC program's alarm texts (docs/machine_plc.md), for the PLC alarm the NC
# sees as PlcAlarmNumber.
PLC_ALARM_TEXTS = {
    1001: "emergency stop: E-stop button pressed or safety chain open",
    1002: "spindle drive not ready within 1 s of enable",
    1003: "spindle not at speed within 10 s (M3/M4)",
    1004: "spindle orientation (M19) not done within 5 s",
    1005: "spindle not stopped within 10 s (M5)",
    1006: "coolant pump on but no coolant pressure for 3 s (pump failure)",
    1007: "spindle fell below the commanded speed for 2 s while turning (stall)",
    1010: "tool change: spindle not oriented within 5 s",
    1011: "tool change: carousel not at the tool's pocket within 5 s",
    1012: "tool change: arm not at grip within 2 s",
    1013: "tool change: arm not extracted within 2 s",
    1014: "tool change: arm not swapped within 2 s",
    1015: "tool change: arm not inserted within 2 s",
    1016: "tool change: arm not home within 2 s",
    1017: "T function: carousel not at the tool's pocket within 5 s",
    1018: "tool number out of range 1..20",
    1020: "M function not finished within 30 s",
    1021: "M code not handled by the PLC",
    1022: "S function: spindle not at the new speed within 10 s",
    1030: "guard door opened during automatic operation: feed hold, spindle stop",
    1031: "door lock not engaged within 1 s",
    1040: "air pressure low: feed hold",
    1041: "lubricant level low: refill (cycle start refused)",
    1042: "lubrication pressure not reached during the pulse",
    1050: "program select: no answer from the NC within 1 s",
    1051: "zero return: no answer from the NC within 1 s",
}


@dataclass(slots=True)
class _Entry:
    alarm: Alarm
    rule: str
    cause: str | None  # the key of the condition that must be gone (CAUSE_GONE / SELF)


class AlarmList:
    """Active alarms in the order raised; one entry per (number, axis)."""

    def __init__(self) -> None:
        self._entries: list[_Entry] = []
        self.raised = 0  # count of alarms ever raised (for tests and the event log)

    def raise_(
        self,
        number: int,
        text: str,
        t: float,
        *,
        source: str = "NC",
        axis: str | None = None,
        rule: str = RESET,
        cause: str | None = None,
        severity: str = "FAULT",
    ) -> bool:
        """Add an alarm; False if the same number/axis is already active (not re-raised)."""
        for e in self._entries:
            if e.alarm.number == number and e.alarm.axis == axis:
                return False
        alarm = Alarm(number, text, source, severity, axis, t)
        self._entries.append(_Entry(alarm, rule, cause))
        self.raised += 1
        return True

    def clear_self(self, cause: str, keep: int | None = None) -> None:
        """Drop SELF alarms of `cause` (all, or all but number `keep`)."""
        self._entries = [
            e
            for e in self._entries
            if not (e.rule == SELF and e.cause == cause and e.alarm.number != keep)
        ]

    def reset(self, active_causes: set[str]) -> list[Alarm]:
        """Apply RESET: drop RESET alarms and CAUSE_GONE alarms whose cause is not active.
        Returns the alarms that stay."""
        keep = []
        for e in self._entries:
            if e.rule == RESET:
                continue
            if e.rule == CAUSE_GONE and e.cause not in active_causes:
                continue
            keep.append(e)
        self._entries = keep
        return [e.alarm for e in keep]

    def clear(self, number: int, axis: str | None = None) -> None:
        """Drop the alarm `number` of `axis` (a SELF alarm whose condition ended)."""
        self._entries = [
            e for e in self._entries if not (e.alarm.number == number and e.alarm.axis == axis)
        ]

    def nc_count(self) -> int:
        """Active alarms raised by the NC side (not mirrors of the PLC's)."""
        return sum(1 for e in self._entries if e.alarm.source != "PLC")

    def has(self, number: int) -> bool:
        return any(e.alarm.number == number for e in self._entries)

    @property
    def active(self) -> tuple[Alarm, ...]:
        return tuple(e.alarm for e in self._entries)

    @property
    def blocking(self) -> tuple[Alarm, ...]:
        """Alarms that refuse cycle start (every FAULT; warnings do not)."""
        return tuple(e.alarm for e in self._entries if e.alarm.severity == "FAULT")

    def __len__(self) -> int:
        return len(self._entries)
