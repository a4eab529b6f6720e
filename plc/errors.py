"""The PLC package's one error root: every error it raises is a PlcError, so a user of the
soft-PLC alone (ladder, runtime, Modbus face) catches one class. The subclasses keep the
builtin base they had (ValueError for bad input, RuntimeError for a state), so existing
handlers still see them."""

from __future__ import annotations


class PlcError(Exception):
    """Base of every error the PLC package raises (ladder language, runtime, Modbus face,
    remote panel, M-code table)."""
