"""The API's routers and what they share: the services of one app instance.

Services live on `app.state.services` (set by `create_app`), never in module globals, so
two apps in one process (tests, a host and its replacement) never share state.
"""

from __future__ import annotations

import base64
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from fastapi import Request
from sqlalchemy.orm import Session, sessionmaker

from dnc.dispatch import Dispatches
from dnc.jobs import Jobs
from dnc.library import Library
from web_api.problems import ApiProblem
from web_api.settings import ApiSettings

MachinesProvider = Callable[[], Mapping[str, Mapping[str, Any]]]
"""() -> {machine name: live status}; supplied by the cell server once machines run."""


@dataclass(frozen=True, slots=True)
class Services:
    settings: ApiSettings
    sessions: sessionmaker[Session]
    library: Library
    dispatches: Dispatches
    jobs: Jobs
    machines_provider: MachinesProvider | None = None
    opcua_addresses: Callable[[], Mapping[str, str]] | None = None
    faults_enabled: bool = False


def get_services(request: Request) -> Services:
    return request.app.state.services


# ------------------------------------------------------------------------------ pagination

_MAX_ID = 2**31 - 1


def encode_cursor(prefix: str, last_id: int) -> str:
    """An opaque cursor: the last id seen, so pages stay stable under concurrent inserts."""
    return base64.urlsafe_b64encode(f"{prefix}{last_id}".encode()).decode().rstrip("=")


def decode_cursor(prefix: str, cursor: str) -> int:
    """The id inside a cursor of ours, or a 400 problem saying the cursor is not one."""
    try:
        raw = base64.urlsafe_b64decode(cursor + "=" * (-len(cursor) % 4)).decode("ascii")
        if not raw.startswith(prefix) or not raw[len(prefix) :].isdigit():
            raise ValueError
        value = int(raw[len(prefix) :])
        if value > _MAX_ID:
            raise ValueError
        return value
    except (ValueError, UnicodeDecodeError):
        raise ApiProblem(
            400,
            "invalid-cursor",
            f"cursor {cursor[:80]!r} is not a cursor this list gave out; "
            "start again without a cursor",
        ) from None


def next_link(request: Request, next_cursor: str | None) -> dict[str, str]:
    """RFC 8288 `Link: <...>; rel="next"` keeping the request's other query parameters."""
    if not next_cursor:
        return {}
    url = request.url.include_query_params(cursor=next_cursor)
    return {"Link": f'<{url.path}?{url.query}>; rel="next"'}
