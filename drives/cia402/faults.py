"""The drive's fault catalogue: EMCY/0x603F code, 0x1001 bits, reaction, detection bound.

`FAULTS` is the single table the application, the tests and docs/cia402.md agree on.
"""

from __future__ import annotations

from dataclasses import dataclass

from drives.fault_registry import DRIVE_FAULTS

# 0x1001 error register bits (CiA 301).
ER_GENERIC = 0x01
ER_CURRENT = 0x02
ER_VOLTAGE = 0x04
ER_TEMPERATURE = 0x08
ER_COMMUNICATION = 0x10
ER_PROFILE = 0x20
ER_MANUFACTURER = 0x80


@dataclass(frozen=True, slots=True)
class FaultSpec:
    code: int
    name: str
    register: int  # 0x1001 value while this fault is active (generic bit included)
    forced_coast: bool  # True: the power stage is cut at once whatever 0x605E says
    bound: str  # detection bound, for the documentation


FAULTS: dict[int, FaultSpec] = {
    f.code: f
    for f in (
        FaultSpec(
            0x2310,
            "overcurrent",
            ER_GENERIC | ER_CURRENT,
            True,
            "1 sub-step after |I| > overcurrent_trip",
        ),
        FaultSpec(
            0x2350,
            "I²t overload",
            ER_GENERIC | ER_CURRENT,
            False,
            "1 sub-step after ∫(I²−I_rated²)dt > (I_peak²−I_rated²)·i2t_peak_time",
        ),
        FaultSpec(
            0x3130,
            "mains phase failure (supply loss)",
            ER_GENERIC | ER_VOLTAGE,
            False,
            "mains_loss_detect (20 ms) + 1 sub-step, power stage on",
        ),
        FaultSpec(
            0x3210,
            "DC-link overvoltage",
            ER_GENERIC | ER_VOLTAGE,
            True,
            "1 sub-step after V_dc > overvoltage_trip",
        ),
        FaultSpec(
            0x3220,
            "DC-link undervoltage",
            ER_GENERIC | ER_VOLTAGE,
            True,
            "1 sub-step after V_dc < undervoltage_trip, power stage on",
        ),
        FaultSpec(
            0x4210,
            "excess temperature device",
            ER_GENERIC | ER_TEMPERATURE,
            False,
            "1 cycle after the heat-sink sensor exceeds device_trip (85 degC)",
        ),
        FaultSpec(
            0x7111,
            "brake chopper failure",
            ER_GENERIC | ER_VOLTAGE,
            False,
            "the brake check: chopper_check (100 ms) after the chopper circuit opens",
        ),
        FaultSpec(
            0x4310,
            "excess temperature drive",
            ER_GENERIC | ER_TEMPERATURE,
            False,
            "1 sub-step after the winding model exceeds the trip temperature",
        ),
        FaultSpec(
            0x7121,
            "motor blocked",
            ER_GENERIC | ER_PROFILE,
            False,
            "blocked_time + 1 sub-step at the current limit below blocked_speed",
        ),
        FaultSpec(
            0x7305,
            "incremental encoder 1 fault",
            ER_GENERIC | ER_PROFILE,
            True,
            "1 sub-step (signal loss, or a count jump above 1.5× max speed)",
        ),
        FaultSpec(
            0x8110,
            "CAN overrun",
            ER_GENERIC | ER_COMMUNICATION,
            False,
            "on_communication_fault, when 0x6007 = 1",
        ),
        FaultSpec(
            0x8130,
            "heartbeat / life guard error",
            ER_GENERIC | ER_COMMUNICATION,
            False,
            "on_communication_fault, when 0x6007 = 1",
        ),
        FaultSpec(
            0x8140,
            "recovered from bus-off",
            ER_GENERIC | ER_COMMUNICATION,
            False,
            "on_communication_fault, when 0x6007 = 1",
        ),
        FaultSpec(
            0x8210,
            "PDO not processed due to length error",
            ER_GENERIC | ER_COMMUNICATION,
            False,
            "on_communication_fault, when 0x6007 = 1",
        ),
        FaultSpec(
            0x8611,
            "following error",
            ER_GENERIC | ER_PROFILE,
            False,
            "0x6066 + 1 sub-step after |0x60F4| first exceeds 0x6065",
        ),
        FaultSpec(
            0x8612,
            "reference limit (hardware limit switch)",
            ER_GENERIC | ER_PROFILE,
            False,
            "1 sub-step after the switch becomes active (table position)",
        ),
    )
}

COMMUNICATION_CODES = frozenset({0x8110, 0x8120, 0x8130, 0x8140, 0x8210, 0x8220, 0x8250, 0x8100})


def spec(code: int) -> FaultSpec:
    """The table entry, or a generic one for a code the table does not list."""
    found = FAULTS.get(code)
    if found is not None:
        return found
    reg = ER_GENERIC | (ER_COMMUNICATION if (code & 0xFF00) in (0x8100, 0x8200) else 0)
    return FaultSpec(code, f"error 0x{code:04X}", reg, False, "")


#: Kinds accepted by Drive402.inject(): the "drive" rows of drives.fault_registry.
INJECT_KINDS = tuple(DRIVE_FAULTS)
