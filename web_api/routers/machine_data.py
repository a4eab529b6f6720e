"""A machine's tool table and work offsets: read and written at the machine, through its
DNC port (TOOLS / OFFSETS), as an operator does at the control's offset screen.

A write is all or nothing: a bad value is a 422 problem with the JSON pointer into the
body, a machine in cycle refuses it (409, as a real control refuses offset input then),
and every write is in the audit log with who did it.
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Body, Path, Request
from fastapi.concurrency import run_in_threadpool

from dnc.errors import Conflict
from web_api.errors import InvalidBody
from web_api.problems import problem_doc
from web_api.routers.auth import Operator, Viewer
from web_api.routers.machine_commands import cell_of
from web_api.schemas import MachineName

router = APIRouter(tags=["machines"], responses=problem_doc(401, 403, 404, 503))

TOOLS_EXAMPLE = {"tools": {"1": {"length": 0.0, "radius": 5.0, "comment": "10 mm end mill"}}}
OFFSETS_EXAMPLE = {"work_offsets": {"G54": [-300.0, -200.0, -300.0]}, "g92": [0.0, 0.0, 0.0]}


async def _at_machine(
    request: Request, name: str, what: str, doc: dict | None, actor: str = ""
) -> dict:
    """The cell's answer; its refusals are problems of their own (web_api/problems.py):
    InvalidMachineData 422 with the JSON pointer, Conflict 409 (in cycle),
    MachineUnavailable 503."""
    cell = cell_of(request)
    try:
        return await run_in_threadpool(cell.machine_data, name, what, doc)
    except Conflict as exc:  # the machine refused (in cycle): audited like a command refusal
        library = request.app.state.services.library
        await run_in_threadpool(
            library.note_transfer, name, f"machine.{what}_refused", actor=actor, reason=str(exc)
        )
        raise


def _one_key(body: Any, key: str, allowed: tuple[str, ...]) -> None:
    if not isinstance(body, dict) or not set(body) <= set(allowed) or key not in body:
        keys = ", ".join(allowed)
        raise InvalidBody(
            f"the body must be an object with {key!r} (keys: {keys})",
            errors=[{"detail": f"needs {key!r}; keys: {keys}", "pointer": "#", "location": "body"}],
        )


@router.get(
    "/api/machines/{name}/tools",
    summary="The machine's tool offset table (read at the machine)",
    responses={200: {"content": {"application/json": {"example": TOOLS_EXAMPLE}}}},
)
async def get_tools(name: Annotated[MachineName, Path()], request: Request, _: Viewer) -> dict:
    return {"machine": name, "tools": await _at_machine(request, name, "tools", None)}


@router.put(
    "/api/machines/{name}/tools",
    summary="Replace the machine's tool offset table (out of cycle only)",
    responses=problem_doc(409, 422),
)
async def put_tools(
    name: Annotated[MachineName, Path()],
    request: Request,
    principal: Operator,
    body: Annotated[Any, Body(examples=[TOOLS_EXAMPLE])],
) -> dict:
    _one_key(body, "tools", ("tools", "machine"))
    stored = await _at_machine(request, name, "tools", body["tools"], principal.user)
    library = request.app.state.services.library
    await run_in_threadpool(
        library.note_transfer,
        name,
        "machine.tools_written",
        actor=principal.user,
        tools=sorted(int(n) for n in stored),
    )
    return {"machine": name, "tools": stored}


@router.get(
    "/api/machines/{name}/offsets",
    summary="The machine's work offsets (EXT, G54-G59, G54.1 P1-P48) and G92 shift",
    responses={200: {"content": {"application/json": {"example": OFFSETS_EXAMPLE}}}},
)
async def get_offsets(name: Annotated[MachineName, Path()], request: Request, _: Viewer) -> dict:
    return {"machine": name, **await _at_machine(request, name, "offsets", None)}


@router.put(
    "/api/machines/{name}/offsets",
    summary="Set work offsets (those named; the others stay) and the G92 shift",
    responses=problem_doc(409, 422),
)
async def put_offsets(
    name: Annotated[MachineName, Path()],
    request: Request,
    principal: Operator,
    body: Annotated[Any, Body(examples=[OFFSETS_EXAMPLE])],
) -> dict:
    if isinstance(body, dict) and "work_offsets" not in body and "g92" in body:
        body = {**body, "work_offsets": {}}
    _one_key(body, "work_offsets", ("work_offsets", "g92", "machine"))
    doc = {k: v for k, v in body.items() if k != "machine"}
    stored = await _at_machine(request, name, "offsets", doc, principal.user)
    library = request.app.state.services.library
    await run_in_threadpool(
        library.note_transfer,
        name,
        "machine.offsets_written",
        actor=principal.user,
        offsets=sorted(body["work_offsets"]),
        g92="g92" in body,
    )
    return {"machine": name, **stored}
