"""Machine commands: cycle start, feed hold, reset, E-stop, home, program select, mode.

Each travels through a face of the machine (the Modbus remote panel, the simulation face's
E-stop button), the same way a cell controller on another computer would send it. A command
the machine's state forbids, or that no face carries, is the cell's CommandRefused (a 409
`command-refused` problem, web_api/problems.py) saying why.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, Path, Request
from fastapi.concurrency import run_in_threadpool
from pydantic import BaseModel, ConfigDict, Field, model_validator

from dnc.cell import CellControl, CommandRefused
from dnc.tape import MAX_PROGRAM_NUMBER
from web_api.errors import NoCell
from web_api.problems import problem_doc
from web_api.routers.auth import Operator
from web_api.schemas import MachineName

router = APIRouter(tags=["machines"], responses=problem_doc(401, 403, 422))


class MachineCommand(BaseModel):
    """One command; `number` goes with select_program, `mode` with mode, `release` with
    estop (release the E-stop button instead of pressing it)."""

    model_config = ConfigDict(extra="forbid")

    command: Literal["cycle_start", "feed_hold", "reset", "estop", "home", "select_program", "mode"]
    number: int | None = Field(
        default=None, ge=1, le=MAX_PROGRAM_NUMBER, description="O number (1..99999999)"
    )
    mode: Literal["AUTO", "MDI", "JOG", "REF"] | None = None
    release: bool = False

    @model_validator(mode="after")
    def _arguments(self) -> MachineCommand:
        if self.command == "select_program" and self.number is None:
            raise ValueError("select_program needs number (the O number)")
        if self.command == "mode" and self.mode is None:
            raise ValueError("mode needs mode (AUTO, MDI, JOG or REF)")
        return self


class CommandAccepted(BaseModel):
    machine: str
    command: str
    detail: str


def cell_of(request: Request) -> CellControl:
    cell: CellControl | None = getattr(request.app.state, "cell_control", None)
    if cell is None:
        raise NoCell("this API runs without a cell: no machine is connected")
    return cell


@router.post(
    "/api/machines/{name}/commands",
    response_model=CommandAccepted,
    status_code=202,
    summary="Send a command to a machine through its faces",
    responses=problem_doc(404, 409, 503),
)
async def machine_command(
    name: Annotated[MachineName, Path()],
    body: MachineCommand,
    request: Request,
    principal: Operator,
) -> CommandAccepted:
    cell = cell_of(request)
    args: dict[str, Any] = {}
    if body.command == "select_program":
        args["number"] = body.number
    elif body.command == "mode":
        args["mode"] = body.mode
    elif body.command == "estop":
        args["release"] = body.release
    library = request.app.state.services.library
    try:
        detail = await run_in_threadpool(cell.command, name, body.command, **args)
    except CommandRefused as exc:  # audited, then answered as the refusal it is
        await run_in_threadpool(
            library.note_transfer,
            name,
            "machine.command_refused",
            actor=principal.user,
            command=body.command,
            reason=str(exc),
            **args,
        )
        raise
    # who did what to which machine: the audit log and the event stream
    await run_in_threadpool(
        library.note_transfer,
        name,
        "machine.command",
        actor=principal.user,
        command=body.command,
        detail=detail,
        **args,
    )
    return CommandAccepted(machine=name, command=body.command, detail=detail)
