"""The drives package's one error root: every error it raises is a DrivesError, so a user
of the drives alone (a virtual CiA 402 drive, the CAN simulator) catches one class.
The subclasses keep the builtin base they had (ValueError for bad input, RuntimeError for a
state), so existing handlers still see them."""

from __future__ import annotations


class DrivesError(Exception):
    """Base of every error the drives package raises (bus, CANopen services, drives, the
    master's axis group, the configuration sections)."""
