"""MTConnect REST endpoints over the cell's agent (`server.mtconnect.Agent`).

Thin: each route hands the raw query parameters to `Agent.request`, which validates them
the way the reference agent does and returns (status, XML). Mount with a prefix, e.g.
`app.include_router(mtconnect_router(agent), prefix="/mtconnect")`.
"""

from __future__ import annotations

from fastapi import APIRouter, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import Response

from server.mtconnect.agent import XML, Agent

_DOC = {
    "probe": "MTConnectDevices: the device model.",
    "current": "MTConnectStreams: the newest observation of every data item "
    "(path, at, deviceType).",
    "sample": "MTConnectStreams: observations in sequence order "
    "(from, to, count=100, path, heartbeat=10000, deviceType).",
}


def mtconnect_router(agent: Agent) -> APIRouter:
    """An APIRouter serving /probe, /current, /sample and /{device}/probe|current|sample."""
    router = APIRouter(tags=["mtconnect"])

    async def serve(kind: str, device: str | None, request: Request) -> Response:
        params = dict(request.query_params)
        status, body = await run_in_threadpool(agent.request, kind, device, params)
        return Response(content=body, status_code=status, media_type=XML)

    def handlers(kind: str):
        async def all_devices(request: Request) -> Response:
            return await serve(kind, None, request)

        async def one_device(device: str, request: Request) -> Response:
            return await serve(kind, device, request)

        return all_devices, one_device

    for kind in ("probe", "current", "sample"):
        all_devices, one_device = handlers(kind)
        router.add_api_route(
            f"/{kind}",
            all_devices,
            methods=["GET"],
            summary=f"MTConnect {kind}",
            description=_DOC[kind],
            response_class=Response,
        )
        router.add_api_route(
            f"/{{device}}/{kind}",
            one_device,
            methods=["GET"],
            summary=f"MTConnect {kind} of one device",
            description=_DOC[kind],
            response_class=Response,
        )

    @router.get("/{device}/{rest:path}", include_in_schema=False)
    async def invalid_uri(device: str, rest: str, request: Request) -> Response:
        body = agent.error_document(
            "INVALID_URI", f"Cannot find handler for: GET {request.url.path}"
        )
        return Response(content=body, status_code=404, media_type=XML)

    return router
