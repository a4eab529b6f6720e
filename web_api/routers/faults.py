"""Fault injection (admin only), mounted only when the cell runs with faults enabled.

A fault goes to the machine through its simulation face as a fault spec (see
docs/machine.md): `type` is the fault kind, `target` is `plc`, `drive:<AXIS>` (or `<AXIS>`)
or `bus:<AXIS>`, `params` its parameters, `at` a machine time in seconds (omitted: now) and
`duration` seconds after which the host clears it again.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Path, Request
from fastapi.concurrency import run_in_threadpool
from pydantic import BaseModel, ConfigDict, Field

from web_api.problems import problem_doc
from web_api.routers.auth import Admin, Viewer
from web_api.routers.machine_commands import cell_of
from web_api.schemas import MachineName

router = APIRouter(tags=["faults"], responses=problem_doc(401, 403, 422))


class FaultParam(BaseModel):
    name: str
    unit: str | None = None
    default: float | None = None
    min: float | None = None  # None: unbounded (or a PLC fault / alias without a range)
    max: float | None = None


class FaultType(BaseModel):
    """One injectable kind; drive, bus and node kinds as drives.fault_registry states them."""

    type: str
    target: str
    params: list[FaultParam]
    description: str = ""
    expect: str = ""  # what the master sees
    emcy: list[str] = []  # the drive's EMCY / 0x603F codes, "0x7305"
    error_register: int | None = None  # the 0x1001 bits those codes set
    detection: str = ""  # what reports it and within which bound, or why nothing does
    # the bound in seconds of machine time (default mill) from `detect_from` (the injection,
    # or the next move / tool change / coolant_on / spindle_on / door_lock); None: no bound
    # (undetectable by design, or an alias: see its kind)
    bound_s: float | None = None
    detect_from: str = "injection"
    recovery_class: str = ""  # the row of docs/recovery.md's procedure table
    recovery: str = ""  # what brings the machine back (docs/recovery.md)


class FaultCreate(BaseModel):
    model_config = ConfigDict(extra="forbid")

    type: str = Field(pattern=r"^[a-z_]+$", max_length=64, examples=["encoder"])
    target: str = Field(
        default="plc", pattern=r"^(plc|(drive:|bus:)?[A-Za-z])$", examples=["drive:X"]
    )
    params: dict[str, float] = Field(default_factory=dict, max_length=16)
    at: float | None = Field(default=None, ge=0, le=1e7, allow_inf_nan=False)
    duration: float | None = Field(default=None, gt=0, le=86400, allow_inf_nan=False)


class Fault(BaseModel):
    id: int
    machine: str
    type: str
    target: str
    params: dict[str, float]
    at: float | None
    duration: float | None
    spec: str
    state: str
    created_at: float
    cleared_at: float | None
    # the machine's clock (s) when it took the injection / the clear: a bench judges a
    # detection bound (machine time) by it, not by a loaded host's wall time
    machine_t: float | None = None
    cleared_machine_t: float | None = None


def _defaults(d: dict) -> dict:
    return {"params": {}, "at": None, "duration": None, "target": "plc", **d}


@router.get("/api/fault-types", response_model=list[FaultType], summary="Injectable faults")
async def fault_types(request: Request, _: Viewer) -> list[FaultType]:
    return [FaultType(**t) for t in cell_of(request).fault_types()]


@router.post(
    "/api/machines/{name}/faults",
    response_model=Fault,
    status_code=201,
    summary="Inject a fault into a machine",
    responses=problem_doc(404, 409, 503),
)
async def inject_fault(
    name: Annotated[MachineName, Path()], body: FaultCreate, request: Request, principal: Admin
) -> Fault:
    cell = cell_of(request)
    # InvalidFault (422), FaultRefused (409), NotFound (404): problems of their own
    fault = await run_in_threadpool(cell.inject, name, body.model_dump())
    await run_in_threadpool(
        request.app.state.services.library.note_transfer,
        name,
        "machine.fault_injected",
        actor=principal.user,
        fault_id=fault.id,
        spec=fault.spec,
    )
    return Fault(**_defaults(fault.as_dict()))


@router.get(
    "/api/machines/{name}/faults",
    response_model=list[Fault],
    summary="Faults injected into a machine",
    responses=problem_doc(404, 503),
)
async def list_faults(name: Annotated[MachineName, Path()], request: Request, _: Viewer):
    cell = cell_of(request)
    faults = await run_in_threadpool(cell.machine_faults, name)
    return [Fault(**_defaults(f.as_dict())) for f in faults]


@router.delete(
    "/api/machines/{name}/faults/{fault_id}",
    response_model=Fault,
    summary="Clear an injected fault",
    responses=problem_doc(404, 409, 503),
)
async def clear_fault(
    name: Annotated[MachineName, Path()],
    fault_id: Annotated[int, Path(ge=1, le=2**31 - 1)],
    request: Request,
    principal: Admin,
) -> Fault:
    cell = cell_of(request)
    fault = await run_in_threadpool(cell.clear, name, fault_id)
    await run_in_threadpool(
        request.app.state.services.library.note_transfer,
        name,
        "machine.fault_cleared",
        actor=principal.user,
        fault_id=fault.id,
        spec=fault.spec,
    )
    return Fault(**_defaults(fault.as_dict()))
