"""The DNC host's refusals, every one a DncError.

DncError is the package's one root. Each class carries a stable `kind`; web_api/problems.py
maps each kind to its problem+json type and HTTP status, in one table. Refusals raised
elsewhere in the package derive from these (dependencies.MissingDependency,
posting.PostRefused), and so does a transfer that fails on the line, dnc.transfer.
TransferError (its `kind` names the line trouble, retried or not; answered as a 502
`transfer-failed` problem). The machine's side of the DNC line answers with its own alarms
(cnc.faces.dnc_port.DncAlarm, a CncError). The running cell's errors are dnc.cell.CellError.
"""

from __future__ import annotations


class DncError(Exception):
    """A request the host refuses. `kind` is stable (used as the problem+json type suffix)."""

    kind = "dnc-error"

    def __init__(self, message: str, **detail: object) -> None:
        super().__init__(message)
        self.message = message
        self.detail = detail


class InvalidUpload(DncError):
    kind = "invalid-upload"


class UploadTooLarge(InvalidUpload):
    """Larger than the upload limit (`size`, `limit` in the detail)."""

    kind = "upload-too-large"


class InvalidCursor(DncError):
    """A page cursor that is not one the list gave out (dnc.cursor)."""

    kind = "invalid-cursor"


class NotFound(DncError):
    kind = "not-found"


class Conflict(DncError):
    kind = "conflict"


class WorkflowError(DncError):
    """A release-workflow step the revision's status or check results forbid."""

    kind = "workflow"


class DatabaseUnavailable(DncError):
    kind = "database-unavailable"


class IdempotencyMismatch(DncError):
    """The same Idempotency-Key was used before with a different request body."""

    kind = "idempotency-key-reuse"


class NotForMachine(DncError):
    """A released program the machine it is dispatched to cannot run (an axis it lacks):
    the program's line, column and why."""

    kind = "not-for-machine"


class NoMachineCanRun(DncError):
    """A job whose program no machine of the cell can run (its kind, an axis it needs):
    each machine's reason in `machines`, what the program needs in `needs`."""

    kind = "no-machine-can-run"
