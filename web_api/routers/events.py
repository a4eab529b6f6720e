"""The event stream: the outbox as server-sent events, and the same over a WebSocket.

Each SSE event carries the outbox id as its `id`, so a reconnecting EventSource sends
`Last-Event-ID` and resumes exactly after the last event it saw (`?after=` does the same
for the first connection). Idle streams get a keep-alive comment every
`events_keepalive_s` so proxies do not cut them.
"""

from __future__ import annotations

import time
from collections.abc import AsyncIterator
from typing import Annotated

import anyio
from fastapi import APIRouter, Depends, Header, Query, WebSocket, WebSocketDisconnect
from fastapi.concurrency import run_in_threadpool
from fastapi.sse import EventSourceResponse, ServerSentEvent

from dnc.outbox import events_after
from web_api.problems import ApiProblem, problem_doc
from web_api.routers import Services, get_services
from web_api.routers.auth import Viewer, websocket_principal
from web_api.settings import Role

router = APIRouter(tags=["events"])
BATCH = 200


def resume_point(last_event_id: str | None, after: int | None) -> int:
    """Where to resume: Last-Event-ID (a reconnect) wins over ?after= (a first connect)."""
    if last_event_id is not None and last_event_id.strip():
        value = last_event_id.strip()
        if not value.isdigit() or int(value) > 2**63 - 1:
            raise ApiProblem(
                400,
                "invalid-last-event-id",
                f"Last-Event-ID {value[:40]!r} is not an event id this stream sent",
            )
        return int(value)
    return after or 0


async def stream_start(
    services: Annotated[Services, Depends(get_services)],
    last_event_id: Annotated[str | None, Header(alias="Last-Event-ID", max_length=40)] = None,
    after: Annotated[int | None, Query(ge=0, le=2**63 - 1)] = None,
) -> tuple[int, list]:
    """The resume point and the first batch, read before the response starts, so a bad
    Last-Event-ID is a 400 problem and a dead database a 503, not a stream that just ends."""
    cursor = resume_point(last_event_id, after)
    return cursor, await run_in_threadpool(events_after, services.sessions, cursor, BATCH)


@router.get(
    "/api/events",
    response_class=EventSourceResponse,
    summary="Server-sent events from the outbox (resumable with Last-Event-ID)",
    responses=problem_doc(400, 401, 403, 422, 503),
)
async def events(
    services: Annotated[Services, Depends(get_services)],
    _: Viewer,
    start: Annotated[tuple[int, list], Depends(stream_start)],
    api_key: Annotated[
        str | None, Query(description="for EventSource, which cannot send headers")
    ] = None,
) -> AsyncIterator[ServerSentEvent]:
    cursor, pending = start
    settings = services.settings
    yield ServerSentEvent(comment="fmscell events", retry=2000)
    quiet_since = time.monotonic()
    while True:
        for event in pending:
            yield ServerSentEvent(raw_data=event.to_json(), id=str(event.id))
            cursor = event.id
            quiet_since = time.monotonic()
        if not pending:
            if time.monotonic() - quiet_since >= settings.events_keepalive_s:
                yield ServerSentEvent(comment="keep-alive")
                quiet_since = time.monotonic()
            await anyio.sleep(settings.events_poll_s)
        pending = await run_in_threadpool(events_after, services.sessions, cursor, BATCH)


@router.websocket("/api/events/ws")
async def events_ws(websocket: WebSocket, after: int = 0) -> None:
    """The same events as JSON text messages; `?after=` resumes; `?api_key=` authenticates.

    A refused key gets one problem+json message and close code 1008 (policy violation).
    """
    services: Services = websocket.app.state.services
    await websocket.accept()
    try:
        websocket_principal(websocket, services.settings, Role.viewer)
    except ApiProblem as exc:
        await websocket.send_json(
            {
                "type": services.settings.problem_base + exc.kind,
                "title": "refused",
                "status": exc.status,
                "detail": exc.detail,
                "instance": websocket.url.path,
            }
        )
        await websocket.close(code=1008, reason=exc.detail[:120])
        return
    cursor = max(0, min(after, 2**63 - 1))
    try:
        while True:
            batch = await run_in_threadpool(events_after, services.sessions, cursor, BATCH)
            for event in batch:
                await websocket.send_text(event.to_json())
                cursor = event.id
            if batch:
                continue
            # Wait for the next poll, noticing a client that goes away meanwhile.
            with anyio.move_on_after(services.settings.events_poll_s):
                message = await websocket.receive()
                if message["type"] == "websocket.disconnect":
                    return
    except WebSocketDisconnect:
        return
