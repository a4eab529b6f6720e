"""The server package's one error root: every exception class `server` defines is a
ServerError. The running cell's refusals that travel through the REST contract are
dnc.cell's CellError family (MachineUnavailable, CommandRefused...), which `server`
raises; a class of its own that is one of those derives from both, so the API still
answers it as the cell's problem and a user of `server` still catches ServerError."""

from __future__ import annotations


class ServerError(Exception):
    """Base of every exception class the server package (cell composition, host loops,
    supervisor) defines."""
