"""The API's routers and what they share: the services of one app instance.

Services live on `app.state.services` (set by `create_app`), never in module globals, so
two apps in one process (tests, a host and its replacement) never share state.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from fastapi import Request
from sqlalchemy.orm import Session, sessionmaker

from dnc.cursor import decode_cursor as decode_cursor
from dnc.cursor import encode_cursor as encode_cursor
from dnc.dispatch import Dispatches
from dnc.jobs import Jobs
from dnc.library import Library
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

# The routers page with dnc.cursor, the host's one cursor (imported above for them); a
# foreign cursor is InvalidCursor, a 400 `invalid-cursor` problem (web_api.problems).


def next_link(request: Request, next_cursor: str | None) -> dict[str, str]:
    """RFC 8288 `Link: <...>; rel="next"` keeping the request's other query parameters."""
    if not next_cursor:
        return {}
    url = request.url.include_query_params(cursor=next_cursor)
    return {"Link": f'<{url.path}?{url.query}>; rel="next"'}
