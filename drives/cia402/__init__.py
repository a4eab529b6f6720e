"""CiA 402 device profile: power state machine, modes of operation, faults, Drive402."""

from drives.cia402.application import Drive402
from drives.cia402.faults import FAULTS, INJECT_KINDS, FaultSpec
from drives.cia402.statemachine import Command, Conditions, Options, PowerState, State, Stop

__all__ = [
    "FAULTS",
    "INJECT_KINDS",
    "Command",
    "Conditions",
    "Drive402",
    "FaultSpec",
    "Options",
    "PowerState",
    "State",
    "Stop",
]
