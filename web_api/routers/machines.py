"""The machine registry, joined with live status when the cell server provides it."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, Path
from fastapi.concurrency import run_in_threadpool

from web_api.problems import problem_doc
from web_api.routers import Services, get_services
from web_api.routers.auth import Viewer
from web_api.schemas import Machine, MachineName

router = APIRouter(tags=["machines"], responses=problem_doc(401, 403, 422, 503))
Svc = Annotated[Services, Depends(get_services)]


def _opcua(services: Services) -> dict:
    return dict(services.opcua_addresses()) if services.opcua_addresses else {}


async def _live(services: Services) -> dict:
    if services.machines_provider is None:
        return {}
    return dict(await run_in_threadpool(services.machines_provider))


@router.get("/api/machines", response_model=list[Machine], summary="Every registered machine")
async def list_machines(services: Svc, _: Viewer) -> list[Machine]:
    registry = await run_in_threadpool(services.library.machines)
    live = await _live(services)
    opcua = _opcua(services)
    return [
        Machine(**x, status=live.get(x["name"]), opcua_address=opcua.get(x["name"]))
        for x in registry
    ]


@router.get(
    "/api/machines/{name}",
    response_model=Machine,
    summary="One machine",
    responses=problem_doc(404),
)
async def get_machine(name: Annotated[MachineName, Path()], services: Svc, _: Viewer) -> Machine:
    entry = await run_in_threadpool(services.library.machine, name)
    live = await _live(services)
    return Machine(**entry, status=live.get(name), opcua_address=_opcua(services).get(name))
