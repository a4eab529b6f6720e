"""Dispatches: put a released revision on a machine, once per Idempotency-Key."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, Header, Path, Query, Request
from fastapi.responses import JSONResponse

from web_api.problems import problem_doc
from web_api.routers import Services, decode_cursor, encode_cursor, get_services, next_link
from web_api.routers.auth import Operator, Viewer
from web_api.schemas import DbId, Dispatch, DispatchPage, DispatchRequest, MachineName

router = APIRouter(tags=["dispatches"], responses=problem_doc(400, 401, 403, 422, 503))
Svc = Annotated[Services, Depends(get_services)]
IdempotencyKey = Annotated[
    str,
    Header(
        alias="Idempotency-Key",
        min_length=1,
        max_length=128,
        pattern=r"^[\x21-\x7e]+$",
        description="client-chosen key; the same key and body again returns the first "
        "dispatch (200), the same key with another body is refused (422)",
    ),
]


def dispatch_out(info) -> Dispatch:
    return Dispatch.model_validate(info, from_attributes=True)


@router.post(
    "/api/dispatches",
    status_code=202,
    response_model=Dispatch,
    summary="Dispatch a released revision to a machine (accepted; the transfer runs after)",
    responses={
        200: {"model": Dispatch, "description": "replay of an earlier request with this key"},
        **problem_doc(404, 409),
    },
)
def create_dispatch(
    body: DispatchRequest, key: IdempotencyKey, services: Svc, principal: Operator
) -> JSONResponse:
    info, created = services.dispatches.request(
        key=key,
        revision_id=body.revision_id,
        machine=body.machine,
        mode=body.mode,
        start=body.start,
        requested_by=principal.user,
    )
    headers = {"Location": f"/api/dispatches/{info.id}"}
    if not created:
        headers["Idempotent-Replayed"] = "true"
    return JSONResponse(
        dispatch_out(info).model_dump(mode="json"),
        status_code=202 if created else 200,
        headers=headers,
    )


@router.get(
    "/api/dispatches",
    response_model=DispatchPage,
    summary="Dispatch history, newest first (cursor pagination; Link header)",
)
def list_dispatches(
    request: Request,
    services: Svc,
    _: Viewer,
    machine: Annotated[MachineName | None, Query()] = None,
    state: Annotated[
        str | None, Query(pattern="^(pending|transferring|verifying|starting|done|failed)$")
    ] = None,
    cursor: Annotated[str | None, Query(max_length=64)] = None,
    limit: Annotated[int, Query(ge=1, le=500)] = 50,
) -> JSONResponse:
    limit = min(limit, services.settings.page_limit_max)
    before = decode_cursor("d", cursor) if cursor else None
    rows = services.dispatches.list(machine=machine, state=state, before=before, limit=limit + 1)
    nxt = encode_cursor("d", rows[limit - 1].id) if len(rows) > limit else None
    body = DispatchPage(items=[dispatch_out(r) for r in rows[:limit]], next_cursor=nxt)
    return JSONResponse(body.model_dump(mode="json"), headers=next_link(request, nxt))


@router.get(
    "/api/dispatches/{dispatch_id}",
    response_model=Dispatch,
    summary="One dispatch: state, bytes sent, verification",
    responses=problem_doc(404),
)
def get_dispatch(dispatch_id: Annotated[DbId, Path()], services: Svc, _: Viewer) -> Dispatch:
    return dispatch_out(services.dispatches.get(dispatch_id))
