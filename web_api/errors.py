"""The REST API's own refusals, every one a WebApiError (the package's one root).

Each class carries a stable `kind`, its problem type; web_api/problems.py gives each kind
its HTTP status and title, in the one table that also holds the host's refusals
(dnc.errors) and the running cell's (dnc.cell). A router raises one of these, or lets a
service's error pass; it never names an HTTP status itself (tests/web_api/
test_problem_kinds.py checks both).
"""

from __future__ import annotations

from typing import Any


class WebApiError(Exception):
    """A request the API itself refuses (auth, media type, request shape, no cell...).

    `detail` is the problem's detail; `headers` go on the response (WWW-Authenticate,
    Retry-After); `extra` become members of the problem document."""

    kind = "bad-request"

    def __init__(self, detail: str, *, headers: dict[str, str] | None = None, **extra: Any):
        super().__init__(detail)
        self.detail = detail
        self.headers = headers or {}
        self.extra = extra


class Unauthenticated(WebApiError):
    """No API key, or one the settings do not know."""

    kind = "unauthenticated"


class Forbidden(WebApiError):
    """The key's role is below what the route needs."""

    kind = "forbidden"


class TooManyAuthFailures(WebApiError):
    """The client address presented too many unknown keys (web_api/ratelimit.py)."""

    kind = "too-many-auth-failures"


class UnsupportedMediaType(WebApiError):
    kind = "unsupported-media-type"


class InvalidBody(WebApiError):
    """A request body whose shape the route refuses; `errors` lists each bad field with
    its JSON pointer, as FastAPI's own validation problems do."""

    kind = "validation"


class InvalidLastEventId(WebApiError):
    kind = "invalid-last-event-id"


class NoCell(WebApiError):
    """The API runs without a cell: no machine is connected."""

    kind = "no-cell"


class ShuttingDown(WebApiError):
    """The app is shutting down: new streams are refused, open ones end."""

    kind = "shutting-down"
