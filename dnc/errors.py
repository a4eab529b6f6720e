"""The DNC host's refusals. Each carries a stable `kind` the REST layer maps to a problem type."""

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
