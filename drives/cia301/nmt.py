"""NMT slave state machine (CiA 301 7.3.2): pure, the slave performs the side effects."""

from __future__ import annotations

from enum import Enum


class NmtState(Enum):
    """NMT states with the value a heartbeat carries."""

    INITIALISING = 0x00
    STOPPED = 0x04
    OPERATIONAL = 0x05
    PRE_OPERATIONAL = 0x7F

    @property
    def label(self) -> str:
        """The name `canopen` and the application use ('PRE-OPERATIONAL', ...)."""
        return self.name.replace("_", "-")


# NMT command specifiers (first byte of a frame on COB-ID 0x000).
CS_START = 0x01
CS_STOP = 0x02
CS_ENTER_PRE_OPERATIONAL = 0x80
CS_RESET_NODE = 0x81
CS_RESET_COMMUNICATION = 0x82

RESET_NODE = "reset node"
RESET_COMMUNICATION = "reset communication"


def nmt_transition(state: NmtState, command: int) -> NmtState | str | None:
    """Next state for an NMT command, a reset action, or None (unknown command: ignore)."""
    if command == CS_START:
        return NmtState.OPERATIONAL
    if command == CS_STOP:
        return NmtState.STOPPED
    if command == CS_ENTER_PRE_OPERATIONAL:
        return NmtState.PRE_OPERATIONAL
    if command == CS_RESET_NODE:
        return RESET_NODE
    if command == CS_RESET_COMMUNICATION:
        return RESET_COMMUNICATION
    return None


def sdo_allowed(state: NmtState) -> bool:
    return state in (NmtState.PRE_OPERATIONAL, NmtState.OPERATIONAL)


def pdo_allowed(state: NmtState) -> bool:
    return state is NmtState.OPERATIONAL


def emcy_allowed(state: NmtState) -> bool:
    return state in (NmtState.PRE_OPERATIONAL, NmtState.OPERATIONAL)


def sync_allowed(state: NmtState) -> bool:
    return state in (NmtState.PRE_OPERATIONAL, NmtState.OPERATIONAL)
