"""MTConnect REST endpoints over the cell's agent (`mtconnect.Agent`).

Thin: each route hands the raw query parameters to the agent, which validates them the way
the reference agent does and returns (status, XML). A request with `interval` streams:
`multipart/mixed;boundary=...` parts, each one MTConnectStreams document, as cppagent sends
them. Mount with a prefix, e.g.
`app.include_router(mtconnect_router(agent), prefix="/mtconnect")`.
"""

from __future__ import annotations

import asyncio
import secrets
import time
from collections.abc import AsyncIterator, Awaitable, Callable

from fastapi import APIRouter, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import Response, StreamingResponse

from mtconnect.agent import XML, Agent, RestError, StreamPlan
from mtconnect.printer import EXTENSION_SCHEMA_FILE

_DOC = {
    "probe": "MTConnectDevices: the device model.",
    "current": "MTConnectStreams: the newest observation of every data item "
    "(path, at, deviceType; interval streams).",
    "sample": "MTConnectStreams: observations in sequence order "
    "(from, to, count=100, path, deviceType; interval and heartbeat=10000 stream).",
}


def mtconnect_router(agent: Agent) -> APIRouter:
    """An APIRouter serving /probe, /current, /sample and /{device}/probe|current|sample,
    and the extension schema the Streams documents name (schemas/fmscellStreams_2.5.xsd)."""
    router = APIRouter(tags=["mtconnect"])

    async def serve(kind: str, device: str | None, request: Request) -> Response:
        params = dict(request.query_params)
        try:
            plan = agent.stream_plan(kind, device, params)
        except RestError as exc:
            body = agent.error_document(exc.code, exc.message)
            return Response(content=body, status_code=exc.status, media_type=XML)
        if plan is not None:
            boundary = secrets.token_hex(16)
            return StreamingResponse(
                stream_parts(agent, plan, boundary),
                media_type=f"multipart/mixed;boundary={boundary}",
            )
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

    def schema(name: str, request: Request) -> Response:
        if name != EXTENSION_SCHEMA_FILE:
            body = agent.error_document(
                "INVALID_URI", f"Cannot find handler for: GET {request.url.path}"
            )
            return Response(content=body, status_code=404, media_type=XML)
        return Response(content=agent.extension_schema(), media_type=XML)

    # Streams documents name this schema by a relative location, so it is found beside
    # both /current and /{device}/current.
    @router.get("/schemas/{name}", summary="fmscell's MTConnect extension schema")
    async def extension_schema(name: str, request: Request) -> Response:
        return schema(name, request)

    @router.get("/{device}/schemas/{name}", include_in_schema=False)
    async def extension_schema_beside_device(device: str, name: str, request: Request) -> Response:
        return schema(name, request)

    @router.get("/{device}/{rest:path}", include_in_schema=False)
    async def invalid_uri(device: str, rest: str, request: Request) -> Response:
        body = agent.error_document(
            "INVALID_URI", f"Cannot find handler for: GET {request.url.path}"
        )
        return Response(content=body, status_code=404, media_type=XML)

    return router


def part(boundary: str, body: str) -> bytes:
    data = body.encode()
    head = f"--{boundary}\r\nContent-type: {XML}\r\nContent-length: {len(data)}\r\n\r\n"
    return head.encode() + data + b"\r\n"


async def stream_parts(
    agent: Agent,
    plan: StreamPlan,
    boundary: str,
    *,
    sleep: Callable[[float], Awaitable[None]] = asyncio.sleep,
    clock: Callable[[], float] = time.monotonic,
) -> AsyncIterator[bytes]:
    """The parts of a streamed current or sample, until the client goes away.

    sample: starts at `from` (default: the next sequence, i.e. only new observations); a
    part whenever there is new data, polled every `interval` ms; an empty document when
    nothing arrived for `heartbeat` ms. If the buffer overtakes a slow client, the part is
    the OUT_OF_RANGE error document and the stream ends.
    """
    pause = max(plan.interval_ms, 1) / 1000.0  # interval=0 means "at once", not a busy loop
    if plan.kind == "current":
        while True:
            yield part(boundary, await run_in_threadpool(agent.current_for, plan.wanted))
            await sleep(pause)
    nxt = plan.from_ if plan.from_ is not None else agent.buffer.next_sequence
    last_sent: float | None = None
    while True:
        try:
            page = await run_in_threadpool(
                lambda n=nxt: agent.sample_page(
                    plan.device, count=plan.count, from_=n, wanted=plan.wanted
                )
            )
        except RestError as exc:
            yield part(boundary, agent.error_document(exc.code, exc.message))
            return
        now = clock()
        if page.count or last_sent is None or (now - last_sent) * 1000 >= plan.heartbeat_ms:
            yield part(boundary, page.xml)
            last_sent = now
        nxt = page.next_sequence
        if page.end_of_buffer:
            await sleep(pause)
