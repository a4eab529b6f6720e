"""The seam between the CiA 301 communication layer and a device profile application.

`drives.cia301` (NMT, SDO, PDO, SYNC, EMCY, heartbeat) knows nothing of motion; a profile
application such as `drives.cia402` knows nothing of frames. The slave owns the object
dictionary storage for communication objects (0x1000-0x1FFF) and asks the application for
everything it owns (0x2000-0x9FFF). The application never sends frames: it queues EMCY
requests that the slave sends when the NMT state allows it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

from drives.errors import DrivesError

# SDO abort codes (CiA 301 7.2.4.3.17) that applications raise most often.
ABORT_NOT_EXIST = 0x06020000  # object does not exist in the object dictionary
ABORT_SUBINDEX = 0x06090011  # sub-index does not exist
ABORT_READ_ONLY = 0x06010002  # attempt to write a read-only object
ABORT_WRITE_ONLY = 0x06010001  # attempt to read a write-only object
ABORT_VALUE_RANGE = 0x06090030  # value range of parameter exceeded
ABORT_VALUE_HIGH = 0x06090031  # value of parameter written too high
ABORT_VALUE_LOW = 0x06090032  # value of parameter written too low
ABORT_DEVICE_STATE = 0x08000022  # data cannot be transferred because of the device state
ABORT_GENERAL = 0x08000000


class ObjectAccessError(DrivesError):
    """An object access refused with a CiA 301 SDO abort code (also used for RPDO writes)."""

    def __init__(self, abort_code: int, message: str = "") -> None:
        super().__init__(f"0x{abort_code:08X} {message}".strip())
        self.abort_code = abort_code


@dataclass(frozen=True, slots=True)
class EmcyRequest:
    """An emergency the application wants sent. `error_code` 0x0000 resets (error cleared)."""

    error_code: int
    error_register: int  # the value for 0x1001 after this event
    manufacturer: bytes = b"\x00" * 5


class DriveApplication(Protocol):
    """What the CiA 301 slave calls on the profile application."""

    def owns(self, index: int) -> bool:
        """True if the application holds this object (reads/writes go to it, not OD storage)."""

    def read_object(self, index: int, subindex: int) -> int | float | bytes:
        """Current value; raise ObjectAccessError for a refused read."""

    def write_object(self, index: int, subindex: int, value: int | float | bytes) -> None:
        """Apply a write from SDO or RPDO; raise ObjectAccessError to refuse it unchanged."""

    def on_sync(self) -> None:
        """SYNC received: synchronous RPDO data has been applied; TPDOs sample right after."""

    def advance(self, dt_s: float) -> None:
        """Integrate the plant over dt_s seconds of simulated time."""

    def on_nmt_state(self, state: str) -> None:
        """NMT state changed: 'INITIALISING', 'PRE-OPERATIONAL', 'OPERATIONAL', 'STOPPED'."""

    def on_communication_fault(self, error_code: int) -> None:
        """The 301 layer detected a fault: 0x8130 heartbeat or life guarding lost, 0x8110 CAN
        overrun, 0x8140 recovered from bus-off, 0x8100 SYNC time-out, 0x8210/0x8220 RPDO
        shorter/longer than mapped, 0x8240 SYNC length, 0x8250 RPDO deadline. React per the
        0x6007 abort connection option code (the slave has already sent the EMCY)."""

    # Optional: `on_nmt_reset(scope)` with scope "node" or "communication". The slave calls
    # it, when defined, to tell the two NMT resets apart (on_nmt_state sees INITIALISING for
    # both); a drive maps "node" to its power-on reset.

    def take_emcy(self) -> list[EmcyRequest]:
        """EMCYs raised since the last call, oldest first."""
