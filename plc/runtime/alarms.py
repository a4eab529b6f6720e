"""PLC system alarms: numbered, with text, raised by the runtime and acknowledged by users."""

from __future__ import annotations

from dataclasses import dataclass

# Numbers of the runtime's own alarms (the machine program uses its own range below 9000).
ALARM_WATCHDOG = 9001
ALARM_PROGRAM_FAULT = 9002
ALARM_DIV_ZERO = 9003
ALARM_WRITE_REJECTED = 9004
ALARM_RETAIN_STORE = 9005
ALARM_PROGRAM_SWAP = 9006
ALARM_IO_FAULT = 9007

ALARM_TEXT = {
    ALARM_WATCHDOG: "scan watchdog: scan time exceeded the limit; outputs in safe state, PLC in FAULT",
    ALARM_PROGRAM_FAULT: "program fault: the ladder program raised an error; PLC in FAULT",
    ALARM_DIV_ZERO: "division by zero in DIV/MOD; destination left unchanged",
    ALARM_WRITE_REJECTED: "a queued write was outside the process image and was dropped",
    ALARM_RETAIN_STORE: "retentive memory could not be saved or loaded",
    ALARM_PROGRAM_SWAP: "online change refused: the new program does not fit the image",
    ALARM_IO_FAULT: "I/O provider failed; outputs in safe state, PLC in FAULT",
}


@dataclass(frozen=True, slots=True)
class Alarm:
    number: int
    text: str
    detail: str
    scan: int
    time_ms: int
    fatal: bool

    def __str__(self) -> str:
        tail = f" ({self.detail})" if self.detail else ""
        return f"PLC {self.number}: {self.text}{tail}"
