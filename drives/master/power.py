"""Master-side CiA 402 logic, pure: statusword decoding, the next controlword toward a goal,
homing status, EMCY texts. No I/O; the axis group calls these once per IPO cycle per axis.
"""

from __future__ import annotations

# Statusword masks and values per power state (CiA 402; the same table as canopen's SW_MASK).
SW_STATES = (
    ("NOT READY TO SWITCH ON", 0x4F, 0x00),
    ("SWITCH ON DISABLED", 0x4F, 0x40),
    ("READY TO SWITCH ON", 0x6F, 0x21),
    ("SWITCHED ON", 0x6F, 0x23),
    ("OPERATION ENABLED", 0x6F, 0x27),
    ("QUICK STOP ACTIVE", 0x6F, 0x07),
    ("FAULT REACTION ACTIVE", 0x4F, 0x0F),
    ("FAULT", 0x4F, 0x08),
)

CW_DISABLE_VOLTAGE = 0x0000
CW_QUICK_STOP = 0x0002
CW_SHUTDOWN = 0x0006
CW_SWITCH_ON = 0x0007
CW_ENABLE_OPERATION = 0x000F
CW_FAULT_RESET = 0x0080
CW_HOMING_START = 0x0010  # operation-mode specific bit 4 in homing mode

SW_FAULT = 0x0008
SW_WARNING = 0x0080
SW_TARGET_REACHED = 0x0400
SW_INTERNAL_LIMIT = 0x0800
SW_OMS12 = 0x1000
SW_OMS13 = 0x2000
HOMING_MASK = SW_OMS13 | SW_OMS12 | SW_TARGET_REACHED


def state_name(statusword: int) -> str:
    """The CiA 402 power state a statusword reports ('UNKNOWN' if no mask matches)."""
    for name, mask, value in SW_STATES:
        if statusword & mask == value:
            return name
    return "UNKNOWN"


def enable_controlword(statusword: int) -> int | None:
    """The controlword that moves a drive one step toward OPERATION ENABLED.

    None when it is already there. FAULT and FAULT REACTION ACTIVE return None too: enabling
    does not reset faults implicitly (a master must decide to, with `fault_reset`).
    """
    state = state_name(statusword)
    if state == "OPERATION ENABLED":
        return None
    if state == "SWITCH ON DISABLED":
        return CW_SHUTDOWN  # transition 2 (0x000F here would be ignored: strict drives)
    if state in ("READY TO SWITCH ON", "SWITCHED ON"):
        return CW_ENABLE_OPERATION  # transitions 3+4, or 4
    if state == "QUICK STOP ACTIVE":
        return CW_DISABLE_VOLTAGE  # transition 12, then start over from SWITCH ON DISABLED
    if state in ("FAULT", "FAULT REACTION ACTIVE"):
        return None
    return CW_DISABLE_VOLTAGE  # NOT READY TO SWITCH ON / UNKNOWN: wait for the drive


def homing_status(statusword: int) -> str:
    """Homing mode status from statusword bits 13, 12, 10 (CiA 402 homing mode)."""
    bits = statusword & HOMING_MASK
    return {
        0x0000: "IN PROGRESS",
        0x0400: "INTERRUPTED",
        0x1000: "ATTAINED",
        0x1400: "TARGET REACHED",
        0x2000: "ERROR VELOCITY IS NOT ZERO",
        0x2400: "ERROR VELOCITY IS ZERO",
    }.get(bits, "UNKNOWN")


def interpolation_period(seconds: float) -> tuple[int, int]:
    """0x60C2 (value, index) with value * 10**index == seconds, value 1..255.

    Raises ValueError if the period cannot be written exactly (e.g. 0.3333 ms).
    """
    for index in (-3, -4, -5, -6, -2, -1, 0):
        value = seconds / 10.0**index
        rounded = round(value)
        if 1 <= rounded <= 255 and abs(value - rounded) < 1e-6:
            return rounded, index
    raise ValueError(f"IPO cycle {seconds} s cannot be written as 0x60C2 value x 10^index")


# EMCY error codes (CiA 301 / CiA 402 / IEC 61800-7) the master can name for the operator.
EMCY_TEXT = {
    0x0000: "error reset / no error",
    0x1000: "generic error",
    0x2310: "continuous overcurrent",
    0x2350: "I2t overload",
    0x3130: "mains phase failure (supply loss)",
    0x3210: "DC-link overvoltage",
    0x3220: "DC-link undervoltage",
    0x4210: "excess temperature device (heat sink)",
    0x4310: "excess temperature drive",
    0x7111: "brake chopper failure",
    0x7121: "motor blocked",
    0x7305: "encoder (incremental sensor 1) fault",
    0x8100: "SYNC timeout",
    0x8110: "CAN overrun (frames lost)",
    0x8120: "CAN in error passive mode",
    0x8130: "heartbeat or life guard error",
    0x8140: "recovered from bus-off",
    0x8210: "PDO not processed due to length error",
    0x8220: "PDO length exceeded",
    0x8240: "unexpected SYNC data length",
    0x8250: "RPDO timeout",
    0x8611: "following error",
    0x8612: "reference limit (limit switch)",
}


def emcy_text(code: int) -> str:
    """A short operator text for an EMCY code (family name when the code is not listed)."""
    if code in EMCY_TEXT:
        return EMCY_TEXT[code]
    family = {
        0x1: "generic",
        0x2: "current",
        0x3: "voltage",
        0x4: "temperature",
        0x5: "device hardware",
        0x6: "device software",
        0x7: "additional modules",
        0x8: "monitoring / communication",
        0x9: "external error",
        0xF: "additional functions / device specific",
    }.get(code >> 12, "unknown")
    return f"{family} error 0x{code:04X}"
