"""The running cell as the REST face sees it: a typed contract between `web_api` and `server`.

The routers that act on machines (commands, machine data, fault injection) need a running
cell; the DNC host's own services (library, dispatches, jobs) do not. `CellControl` is all a
router may ask of it, and `server.cell.Cell` implements it, so `web_api` depends on this
module and never imports `server` (docs/architecture.md, tests/test_architecture.py).

It lives in `dnc` because that is the host layer both sides already depend on: the cell's
machine registry, transfers and jobs are `dnc`'s, the faces behind `CellControl` are
`server`'s.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol, runtime_checkable

from cnc.machine_data import MachineDataError


class CellError(RuntimeError):
    """Base of the running cell's errors (raised by `server`, answered by `web_api`).

    `kind` is the problem type each is answered with (web_api/problems.py maps it to the
    HTTP status and title, in the one table of every problem type)."""

    kind = "machine-unavailable"


class MachineUnavailable(CellError):
    """A face of the machine cannot be reached or refused the request (text says which)."""


class CommandRefused(MachineUnavailable):
    """A machine command the machine's state forbids, or that no face carries (`command`)."""

    kind = "command-refused"

    def __init__(self, message: str, command: str = "") -> None:
        super().__init__(message)
        self.command = command


class FaultRefused(MachineUnavailable):
    """A fault injection or clear the machine refused (one it cannot model, no face)."""

    kind = "fault-refused"


class InvalidFault(CellError, ValueError):
    """A fault request that is no valid spec; the first line says why, the rest lists the
    valid specs (ValueError, as the spec parser's own errors)."""

    kind = "invalid-fault"


class InvalidMachineData(CellError, MachineDataError):
    """A tool table or offsets document the machine refused: `pointer` is the JSON pointer
    of the bad value in the document sent ("" = the whole), `what` which document (tools |
    offsets). Still a cnc MachineDataError, as the machine's own refusal is."""

    kind = "validation"

    def __init__(self, message: str, pointer: str = "", what: str = "") -> None:
        MachineDataError.__init__(self, message, pointer)
        self.what = what


class FaultRecord(Protocol):
    """An injected fault as the cell keeps it (`as_dict()`: id, machine, type, target, params,
    spec, state, created_at, cleared_at, machine_t, cleared_machine_t: the machine's clock
    when it took the injection and the clear)."""

    def as_dict(self) -> dict[str, Any]: ...


@runtime_checkable
class CellControl(Protocol):
    """What the routers may ask of a running cell. Each call may block on a machine's faces:
    routers run them in a worker thread. Refusals are typed, each its own problem type
    (web_api/problems.py): `CommandRefused`, `FaultRefused`, `InvalidFault`,
    `InvalidMachineData`, `MachineUnavailable` (cannot be reached), dnc's `NotFound` (no
    such machine or fault) and `Conflict` (machine data refused in cycle)."""

    def command(self, name: str, command: str, **args: Any) -> str:
        """A panel or NC command (cycle_start, feed_hold, reset, mode, home, select_program,
        estop...) through the machine's faces; returns what the machine answered
        (CommandRefused: refused, or no face carries it)."""
        ...

    def machine_data(self, name: str, what: str, doc: dict | None = None) -> dict:
        """The machine's tool table or work offsets (`what`: tools | offsets); with `doc`,
        replace them (Conflict: the machine refuses while a program runs;
        InvalidMachineData: a bad value; MachineUnavailable: the DNC port cannot be
        reached)."""
        ...

    def fault_types(self) -> list[dict]:
        """The injectable fault kinds: type, target, params, description, detection, recovery."""
        ...

    def inject(self, name: str, request: dict) -> FaultRecord:
        """Inject a fault (InvalidFault: a bad request, FaultRefused: the machine refused)."""
        ...

    def machine_faults(self, name: str) -> Sequence[FaultRecord]:
        """The faults injected into the machine, active and cleared."""
        ...

    def clear(self, name: str, fault_id: int) -> FaultRecord:
        """Clear an injected fault (dnc.errors.NotFound: no such fault on the machine;
        FaultRefused: the machine refused)."""
        ...
