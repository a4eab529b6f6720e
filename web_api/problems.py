"""RFC 9457 problem details: every 4xx/5xx the API sends is `application/problem+json`.

Each problem has a stable `type` URI (`<problem_base><kind>`), so clients branch on the type,
never on the wording of `detail`. Validation problems list each bad field with a JSON
pointer into the request body (`"pointer": "#/number"`) or the name of the bad parameter.
"""

from __future__ import annotations

import json
import logging
from typing import Any

from fastapi import FastAPI, HTTPException, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import BaseModel, Field
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import Match
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from dnc.cell import CellError
from dnc.errors import DncError
from dnc.transfer import TransferError

PROBLEM_JSON = "application/problem+json"
log = logging.getLogger(__name__)

# The HTTP status of each refusal kind the DNC services raise (dnc.errors: every DncError's
# `kind` is its problem type); the one place a host refusal becomes a problem.
STATUS_OF_KIND = {
    "invalid-upload": 422,
    "upload-too-large": 413,
    "invalid-cursor": 400,
    "not-found": 404,
    "conflict": 409,
    "workflow": 409,
    "database-unavailable": 503,
    "idempotency-key-reuse": 422,
    "missing-dependency": 409,
    "post-refused": 422,
    "not-for-machine": 422,
    "no-machine-can-run": 422,
}
TITLES = {
    "invalid-upload": "The uploaded program was refused",
    "upload-too-large": "The upload exceeds the size limit",
    "invalid-cursor": "Invalid cursor",
    "not-found": "No such resource",
    "conflict": "Conflicts with the stored state",
    "workflow": "The release workflow forbids this step",
    "database-unavailable": "The database is unavailable",
    "idempotency-key-reuse": "Idempotency-Key reused with a different request",
    "missing-dependency": "A program it calls has no released revision",
    "post-refused": "The post-processor refused the program for this machine",
    "not-for-machine": "The machine cannot run the program (an axis it does not have)",
    "no-machine-can-run": "No machine of the cell can run the job's program",
    "validation": "The request is invalid",
    "malformed-json": "The request body is not valid JSON",
    "unauthenticated": "An API key is required",
    "forbidden": "The API key's role does not allow this",
    "method-not-allowed": "Method not allowed",
    "unsupported-media-type": "Unsupported media type",
    "internal": "Internal server error",
    "shutting-down": "The server is shutting down",
    "too-many-auth-failures": "Too many failed authentications from this address",
    "machine-unavailable": "The machine cannot be reached or refused",
    "transfer-failed": "The transfer to or from the machine failed",
}
_KIND_OF_STATUS = {
    400: "bad-request",
    401: "unauthenticated",
    403: "forbidden",
    404: "not-found",
    405: "method-not-allowed",
    413: "upload-too-large",
    415: "unsupported-media-type",
}


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


class ApiProblem(Exception):
    """A refusal raised by the API layer itself (auth, size limits, bad cursors...)."""

    def __init__(
        self, status: int, kind: str, detail: str, *, headers: dict | None = None, **extra: Any
    ) -> None:
        super().__init__(detail)
        self.status, self.kind, self.detail = status, kind, detail
        self.headers, self.extra = headers or {}, extra


def dnc_status(exc: DncError) -> int:
    """The HTTP status of a host refusal (400 for a kind the table does not know)."""
    return STATUS_OF_KIND.get(exc.kind, 400)


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
    async def _dnc(request: Request, exc: DncError) -> JSONResponse:
        extra = {k: v for k, v in exc.detail.items() if k not in ("type", "title", "status")}
        return problem_response(
            request.url.path, base, dnc_status(exc), exc.kind, exc.message, **extra
        )

    @app.exception_handler(TransferError)
    async def _transfer(request: Request, exc: TransferError) -> JSONResponse:
        # a DncError whose `kind` is the line trouble, not a problem type
        return problem_response(
            request.url.path,
            base,
            502,
            "transfer-failed",
            exc.message,
            transfer_kind=exc.kind,
            alarm=exc.alarm,
        )

    @app.exception_handler(CellError)
    async def _cell(request: Request, exc: CellError) -> JSONResponse:
        # the cell's default answer; a router that knows better (a refused command: 409)
        # raises its own ApiProblem
        return problem_response(request.url.path, base, 503, "machine-unavailable", str(exc))

    @app.exception_handler(ApiProblem)
    async def _api(request: Request, exc: ApiProblem) -> JSONResponse:
        return problem_response(
            request.url.path,
            base,
            exc.status,
            exc.kind,
            exc.detail,
            headers=exc.headers,
            **exc.extra,
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
