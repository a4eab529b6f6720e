"""RFC 9457 problem details: every 4xx/5xx the API sends is `application/problem+json`.

Each problem has a stable `type` URI (`<problem_base><kind>`), so clients branch on the type,
never on the wording of `detail`. Validation problems list each bad field with a JSON
pointer into the request body (`"pointer": "#/number"`) or the name of the bad parameter.

This module is the one place where an error becomes a problem. Every error a service or a
router raises carries its problem type as `kind`: the DNC host's refusals (dnc.errors,
DncError), the running cell's (dnc.cell, CellError) and the API's own (web_api.errors,
WebApiError); a failed transfer (dnc.transfer.TransferError, whose `kind` names the line
trouble) is `transfer-failed`. `PROBLEM_TYPES` gives each type its HTTP status and title;
routers name no status (tests/web_api/test_problem_kinds.py).
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from typing import Any

from fastapi import FastAPI, HTTPException, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import BaseModel, Field
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import Match
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from dnc.cell import CellError, CommandRefused, InvalidMachineData
from dnc.errors import DncError
from dnc.transfer import TransferError
from web_api.errors import WebApiError

PROBLEM_JSON = "application/problem+json"
log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class ProblemType:
    status: int
    title: str


# Every problem type the API answers with: its HTTP status and title (docs/api.md lists them).
PROBLEM_TYPES: dict[str, ProblemType] = {
    # the DNC host's refusals (dnc.errors: each DncError's `kind`)
    "dnc-error": ProblemType(400, "The DNC host refused the request"),
    "invalid-upload": ProblemType(422, "The uploaded program was refused"),
    "upload-too-large": ProblemType(413, "The upload exceeds the size limit"),
    "invalid-cursor": ProblemType(400, "Invalid cursor"),
    "not-found": ProblemType(404, "No such resource"),
    "conflict": ProblemType(409, "Conflicts with the stored state"),
    "workflow": ProblemType(409, "The release workflow forbids this step"),
    "database-unavailable": ProblemType(503, "The database is unavailable"),
    "idempotency-key-reuse": ProblemType(422, "Idempotency-Key reused with a different request"),
    "missing-dependency": ProblemType(409, "A program it calls has no released revision"),
    "post-refused": ProblemType(422, "The post-processor refused the program for this machine"),
    "not-for-machine": ProblemType(
        422, "The machine cannot run the program (an axis it does not have)"
    ),
    "no-machine-can-run": ProblemType(422, "No machine of the cell can run the job's program"),
    # a transfer to or from a machine that failed (dnc.transfer.TransferError)
    "transfer-failed": ProblemType(502, "The transfer to or from the machine failed"),
    # the running cell's refusals (dnc.cell: each CellError's `kind`)
    "machine-unavailable": ProblemType(503, "The machine cannot be reached or refused"),
    "command-refused": ProblemType(409, "Command refused"),
    "fault-refused": ProblemType(409, "Fault refused"),
    "invalid-fault": ProblemType(422, "Invalid fault"),
    # the API's own (web_api.errors: each WebApiError's `kind`), and FastAPI's and
    # Starlette's refusals
    "bad-request": ProblemType(400, "Bad request"),
    "validation": ProblemType(422, "The request is invalid"),
    "malformed-json": ProblemType(400, "The request body is not valid JSON"),
    "unauthenticated": ProblemType(401, "An API key is required"),
    "forbidden": ProblemType(403, "The API key's role does not allow this"),
    "too-many-auth-failures": ProblemType(429, "Too many failed authentications from this address"),
    "unsupported-media-type": ProblemType(415, "Unsupported media type"),
    "invalid-last-event-id": ProblemType(400, "Invalid last event id"),
    "no-cell": ProblemType(503, "No cell"),
    "shutting-down": ProblemType(503, "The server is shutting down"),
    "method-not-allowed": ProblemType(405, "Method not allowed"),
    "internal": ProblemType(500, "Internal server error"),
}
# views of the table by field
STATUS_OF_KIND = {kind: p.status for kind, p in PROBLEM_TYPES.items()}
TITLES = {kind: p.title for kind, p in PROBLEM_TYPES.items()}
_KIND_OF_STATUS = {
    400: "bad-request",
    401: "unauthenticated",
    403: "forbidden",
    404: "not-found",
    405: "method-not-allowed",
    413: "upload-too-large",
    415: "unsupported-media-type",
}
ERROR_ROOTS = (DncError, CellError, WebApiError)
"""The roots of every error answered as a problem of its own (not a 500)."""


def problem_kind(error: BaseException | type[BaseException]) -> str:
    """The problem type of an error (or error class) of ERROR_ROOTS."""
    cls = error if isinstance(error, type) else type(error)
    if issubclass(cls, TransferError):
        return "transfer-failed"  # its own `kind` names the line trouble
    return cls.kind


def dnc_status(exc: BaseException) -> int:
    """The HTTP status of an error of ERROR_ROOTS (400 for a kind the table does not know)."""
    found = PROBLEM_TYPES.get(problem_kind(exc))
    return found.status if found else 400


@dataclass(frozen=True, slots=True)
class ProblemOf:
    """What an error is answered with: problem type, detail, response headers and the
    problem document's extra members."""

    kind: str
    status: int
    detail: str
    headers: dict[str, str]
    extra: dict[str, Any]


def problem_of(exc: BaseException) -> ProblemOf:
    """The problem an error of ERROR_ROOTS is answered with."""
    kind = problem_kind(exc)
    status = dnc_status(exc)
    headers: dict[str, str] = {}
    extra: dict[str, Any] = {}
    if isinstance(exc, TransferError):
        detail = exc.message
        extra = {"transfer_kind": exc.kind, "alarm": exc.alarm}
    elif isinstance(exc, DncError):
        detail = exc.message
        extra = {k: v for k, v in exc.detail.items() if k not in ("type", "title", "status")}
    elif isinstance(exc, WebApiError):
        detail, headers, extra = exc.detail, exc.headers, exc.extra
    elif isinstance(exc, InvalidMachineData):
        # the pointer into the request body: a tool table travels under `tools`
        where = f"#{'/tools' if exc.what == 'tools' else ''}{exc.pointer}"
        detail = f"1 invalid field(s); first body {where}: {exc.message}"
        extra = {"errors": [{"detail": exc.message, "pointer": where, "location": "body"}]}
    else:  # a CellError: its first line (a fault spec's refusal goes on with the valid specs)
        detail = str(exc).split("\n", 1)[0]
        if isinstance(exc, CommandRefused):
            extra = {"command": exc.command}
    return ProblemOf(kind, status, detail, headers, extra)


class InvalidParam(BaseModel):
    """One bad field: where (a JSON pointer into the body, or a parameter) and why."""

    detail: str
    pointer: str | None = Field(default=None, examples=["#/number"])
    parameter: str | None = Field(default=None, examples=["limit"])
    location: str = Field(examples=["body", "query", "header", "path"])


class Problem(BaseModel):
    """RFC 9457 problem details."""

    type: str = Field(examples=["https://fmscell.dev/problems/not-found"])
    title: str
    status: int
    detail: str
    instance: str
    errors: list[InvalidParam] | None = None
    model_config = {"extra": "allow"}


def problem_response(
    request_path: str,
    base: str,
    status: int,
    kind: str,
    detail: str,
    *,
    headers: dict | None = None,
    **extra: Any,
) -> JSONResponse:
    body = {
        "type": base + kind,
        "title": TITLES.get(kind, kind.replace("-", " ").capitalize()),
        "status": status,
        "detail": detail,
        "instance": request_path,
        **{k: v for k, v in extra.items() if v is not None},
    }
    return JSONResponse(
        json.loads(json.dumps(body, default=str)),
        status_code=status,
        media_type=PROBLEM_JSON,
        headers=headers,
    )


def problem_doc(*statuses: int) -> dict[int, dict]:
    """OpenAPI `responses` entries for the problems a route can answer with."""
    return {
        s: {
            "content": {PROBLEM_JSON: {"schema": {"$ref": "#/components/schemas/Problem"}}},
            "description": f"problem details ({s})",
        }
        for s in statuses
    }


def _pointer(loc: tuple) -> tuple[str, str | None, str | None]:
    where = str(loc[0]) if loc else "body"
    rest = [str(p).replace("~", "~0").replace("/", "~1") for p in loc[1:]]
    if where == "body":
        return where, "#/" + "/".join(rest) if rest else "#", None
    return where, None, rest[0] if rest else None


def validation_problem(request: Request, base: str, errors: list[dict]) -> JSONResponse:
    if any(e.get("type") == "json_invalid" for e in errors):
        e = next(e for e in errors if e.get("type") == "json_invalid")
        ctx = e.get("ctx") or {}
        loc = e.get("loc", ())
        where = f" at character {loc[1]}" if len(loc) > 1 else ""
        return problem_response(
            request.url.path,
            base,
            400,
            "malformed-json",
            f"request body is not valid JSON{where}: {ctx.get('error', e.get('msg'))}",
        )
    params = []
    for e in errors:
        where, pointer, parameter = _pointer(tuple(e.get("loc", ())))
        params.append(
            InvalidParam(
                detail=e.get("msg", "invalid"),
                pointer=pointer,
                parameter=parameter,
                location=where,
            ).model_dump(exclude_none=True)
        )
    first = params[0] if params else {"detail": "invalid request"}
    at = first.get("pointer") or first.get("parameter") or ""
    detail = f"{len(params)} invalid field(s); first {first.get('location', '')} {at}: "
    detail += first["detail"]
    return problem_response(request.url.path, base, 422, "validation", detail, errors=params)


def install_problem_handlers(app: FastAPI, base: str) -> None:
    """Turn every refusal (ours, FastAPI's, Starlette's, unexpected crashes) into a problem."""

    @app.exception_handler(DncError)
    @app.exception_handler(CellError)
    @app.exception_handler(WebApiError)
    async def _refused(request: Request, exc: Exception) -> JSONResponse:
        p = problem_of(exc)
        return problem_response(
            request.url.path, base, p.status, p.kind, p.detail, headers=p.headers, **p.extra
        )

    @app.exception_handler(RequestValidationError)
    async def _validation(request: Request, exc: RequestValidationError) -> JSONResponse:
        return validation_problem(request, base, list(exc.errors()))

    @app.exception_handler(StarletteHTTPException)
    async def _http(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        kind = _KIND_OF_STATUS.get(exc.status_code, f"http-{exc.status_code}")
        detail = exc.detail if isinstance(exc.detail, str) else json.dumps(exc.detail)
        if exc.status_code == 404 and detail == "Not Found":
            detail = f"no route {request.method} {request.url.path}"
        headers = exc.headers
        if exc.status_code == 405:
            allowed = allowed_methods(request)
            detail = f"{request.method} is not allowed on {request.url.path}"
            if allowed:
                detail += f"; allowed: {', '.join(allowed)}"
                headers = {**(headers or {}), "Allow": ", ".join(allowed)}
        return problem_response(
            request.url.path, base, exc.status_code, kind, detail, headers=headers
        )

    @app.exception_handler(Exception)
    async def _crash(request: Request, exc: Exception) -> JSONResponse:
        log.exception("unhandled error on %s %s", request.method, request.url.path)
        return problem_response(
            request.url.path,
            base,
            500,
            "internal",
            f"the server failed on this request ({type(exc).__name__}); it has been logged",
        )


_METHODS = ("GET", "HEAD", "POST", "PUT", "PATCH", "DELETE", "OPTIONS")


def allowed_methods(request: Request) -> list[str]:
    """Every method some route of the app takes on this request's path (RFC 9110 §15.5.6:
    the Allow header of a 405 lists them all). Starlette answers with the methods of the
    first route whose path matched, so a path served by a GET route and a POST route said
    only "POST" to a PUT. Each method is tried against the whole route table (included
    routers nest their routes), which costs nothing on the paths that answer."""
    routes = request.app.router.routes
    allowed = []
    for method in _METHODS:
        scope = {**request.scope, "method": method}
        if any(route.matches(scope)[0] == Match.FULL for route in routes):
            allowed.append(method)
    return allowed


class BodySizeLimit:
    """Refuses a request body larger than `limit` bytes with a 413 problem, before reading it.

    A declared Content-Length above the limit is refused at once; a chunked body is counted
    as it arrives and refused as soon as it crosses the limit, so memory stays bounded.
    """

    def __init__(self, app: ASGIApp, *, limit: int, base: str) -> None:
        self.app, self.limit, self.base = app, limit, base

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        declared = dict(scope.get("headers") or []).get(b"content-length")
        if declared is not None and declared.isdigit() and int(declared) > self.limit:
            await self._refuse(scope, receive, send, int(declared))
            return
        seen = 0

        async def counting_receive() -> Message:
            nonlocal seen
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > self.limit:
                    # An HTTPException passes FastAPI's body parsing untouched and reaches
                    # the problem handler as a 413.
                    raise HTTPException(413, self._message(f"at least {seen}"))
            return message

        await self.app(scope, counting_receive, send)

    def _message(self, amount: str) -> str:
        return (
            f"request body of {amount} bytes exceeds the limit of {self.limit} bytes "
            "(configure upload_limit_bytes, or drip-feed the program from a file)"
        )

    async def _refuse(self, scope: Scope, receive: Receive, send: Send, size: int) -> None:
        response = problem_response(
            scope.get("path", ""),
            self.base,
            413,
            "upload-too-large",
            self._message(str(size)),
            limit=self.limit,
        )
        await response(scope, receive, send)
