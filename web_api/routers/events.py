"""The event stream: the outbox as server-sent events, and the same over a WebSocket.

Each SSE event carries the outbox id as its `id`, so a reconnecting EventSource sends
`Last-Event-ID` and resumes exactly after the last event it saw (`?after=` does the same
for the first connection). Idle streams get a keep-alive comment every
`events_keepalive_s` so proxies do not cut them.

Clients read from the app's event hub (web_api.event_hub): one reader of the outbox per
process, however many clients watch. `events_fanout: poll` brings back the old way, each
client polling the outbox itself, as the benchmark's peer.
"""

from __future__ import annotations

import time
from collections.abc import AsyncIterator
from typing import Annotated

import anyio
from fastapi import (
    APIRouter,
    Depends,
    FastAPI,
    Header,
    Query,
    Request,
    WebSocket,
    WebSocketDisconnect,
)
from fastapi.concurrency import run_in_threadpool
from starlette.responses import StreamingResponse

from dnc.outbox import events_after
from web_api.errors import InvalidLastEventId, ShuttingDown
from web_api.event_hub import HubClosed, PollingStream, Stream
from web_api.problems import ERROR_ROOTS, problem_doc, problem_of
from web_api.routers import Services, get_services
from web_api.routers.auth import Viewer, websocket_principal
from web_api.settings import ApiSettings, Role

router = APIRouter(tags=["events"])


class EventStream(StreamingResponse):
    """`text/event-stream` written by our own generator (not FastAPI's SSE encoder): the
    hub's events are encoded once and each batch goes out in one write."""

    media_type = "text/event-stream"


BATCH = 200


def resume_point(last_event_id: str | None, after: int | None) -> int:
    """Where to resume: Last-Event-ID (a reconnect) wins over ?after= (a first connect)."""
    if last_event_id is not None and last_event_id.strip():
        value = last_event_id.strip()
        if not value.isdigit() or int(value) > 2**63 - 1:
            raise InvalidLastEventId(
                f"Last-Event-ID {value[:40]!r} is not an event id this stream sent",
            )
        return int(value)
    return after or 0


async def open_stream(app: FastAPI, cursor: int) -> Stream:
    """A stream after `cursor` from the app's hub (or, in `poll` fan-out, its own poller).

    Opening reads the database (the hub's anchor, or the first poll) or, with the hub's
    reader running, takes its last read's failure, so a dead database is a 503 problem
    before the response starts, not a stream that stays silent."""
    services: Services = app.state.services
    settings = services.settings
    if app.state.event_hub.closed:
        raise ShuttingDown("the server is shutting down")
    if settings.events_fanout == "poll":
        await run_in_threadpool(events_after, services.sessions, cursor, 1)
        return PollingStream(
            lambda after, limit: events_after(services.sessions, after, limit),
            cursor,
            settings.events_poll_s,
            BATCH,
            closed=lambda: app.state.event_hub.closed,
        )
    # HubClosed, a ShuttingDown: the app closed meanwhile
    return await run_in_threadpool(app.state.event_hub.subscribe, cursor)


async def stream_start(
    request: Request,
    last_event_id: Annotated[str | None, Header(alias="Last-Event-ID", max_length=40)] = None,
    after: Annotated[int | None, Query(ge=0, le=2**63 - 1)] = None,
) -> Stream:
    """The resume point and the client's stream, opened before the response starts."""
    return await open_stream(request.app, resume_point(last_event_id, after))


@router.get(
    "/api/events",
    response_class=EventStream,
    summary="Server-sent events from the outbox (resumable with Last-Event-ID)",
    responses={
        200: {
            "description": "one event per outbox row: `id:` its outbox id, `data:` its JSON; "
            "`: keep-alive` comments while quiet"
        },
        **problem_doc(400, 401, 403, 422, 503),
    },
)
async def events(
    services: Annotated[Services, Depends(get_services)],
    _: Viewer,
    stream: Annotated[Stream, Depends(stream_start)],
    api_key: Annotated[
        str | None, Query(description="for EventSource, which cannot send headers")
    ] = None,
) -> EventStream:
    # A dropped client ends with one failed write here; FastAPI's own SSE encoder ran a
    # producer and a keep-alive task per connection, and tearing those down on a drop
    # logged BrokenResourceError.
    return EventStream(
        sse_body(stream, services.settings),
        headers={"Cache-Control": "no-cache", "X-Accel-Buffering": "no"},
    )


async def sse_body(stream: Stream, settings: ApiSettings) -> AsyncIterator[bytes]:
    try:
        yield b": fmscell events\nretry: 2000\n\n"
        quiet_since = time.monotonic()
        while True:
            # Wake for events or when the keep-alive is due, never more often than a poll.
            quiet = time.monotonic() - quiet_since
            wait = max(settings.events_poll_s, settings.events_keepalive_s - quiet)
            try:
                batch = await stream.next_batch(wait)
            except HubClosed:
                return  # the server shuts down; the client's EventSource reconnects later
            if batch:
                yield b"".join(p.sse for p in batch)
                quiet_since = time.monotonic()
            elif time.monotonic() - quiet_since >= settings.events_keepalive_s:
                yield b": keep-alive\n\n"
                quiet_since = time.monotonic()
    finally:
        stream.close()


@router.websocket("/api/events/ws")
async def events_ws(websocket: WebSocket, after: int = 0) -> None:
    """The same events as JSON text messages; `?after=` resumes; `?api_key=` authenticates.

    A refused key gets one problem+json message and close code 1008 (policy violation); a
    database that cannot be read, one problem+json message and 1011.
    """
    services: Services = websocket.app.state.services
    await websocket.accept()

    async def refuse(exc_status: int, kind: str, detail: str, code: int) -> None:
        await websocket.send_json(
            {
                "type": services.settings.problem_base + kind,
                "title": "refused",
                "status": exc_status,
                "detail": detail,
                "instance": websocket.url.path,
            }
        )
        await websocket.close(code=code, reason=detail[:120])

    try:
        websocket_principal(websocket, services.settings, Role.viewer)
    except ERROR_ROOTS as exc:
        p = problem_of(exc)
        await refuse(p.status, p.kind, p.detail, 1008)
        return
    try:
        stream = await open_stream(websocket.app, max(0, min(after, 2**63 - 1)))
    except ERROR_ROOTS as exc:
        p = problem_of(exc)
        await refuse(p.status, p.kind, p.detail, 1011)
        return

    async def send_events(done: anyio.CancelScope) -> None:
        try:
            while True:
                for event in await stream.next_batch(services.settings.events_keepalive_s or 1):
                    await websocket.send_text(event.json)
        except HubClosed:
            await websocket.close(code=1001, reason="server shutting down")
        except (WebSocketDisconnect, RuntimeError):  # the client went away mid-send
            pass
        done.cancel()

    async def watch_disconnect(done: anyio.CancelScope) -> None:
        # Nothing is expected from the client; reading notices that it went away.
        try:
            while (await websocket.receive())["type"] != "websocket.disconnect":
                pass
        except (WebSocketDisconnect, RuntimeError):
            pass
        done.cancel()

    try:
        async with anyio.create_task_group() as tg:
            tg.start_soon(send_events, tg.cancel_scope)
            tg.start_soon(watch_disconnect, tg.cancel_scope)
    finally:
        stream.close()
