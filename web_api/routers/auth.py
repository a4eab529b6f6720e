"""API-key authentication and role checks, as FastAPI dependencies.

A key comes in the `X-API-Key` header or as `Authorization: Bearer <key>`. The event
stream also takes `?api_key=` because a browser's EventSource and WebSocket cannot set
headers. No key gives 401, a key whose role is too low gives 403 (both problem+json); an
address that presented too many unknown keys gets 429 (web_api/ratelimit.py).
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, Request, WebSocket
from fastapi.security import APIKeyHeader, HTTPAuthorizationCredentials, HTTPBearer

from web_api.errors import Forbidden, TooManyAuthFailures, Unauthenticated
from web_api.problems import problem_doc
from web_api.ratelimit import AuthFailureLimiter
from web_api.routers import Services, get_services
from web_api.schemas import WhoAmI
from web_api.settings import ApiSettings, Principal, Role

_api_key_header = APIKeyHeader(name="X-API-Key", auto_error=False, scheme_name="ApiKey")
_bearer = HTTPBearer(auto_error=False, scheme_name="Bearer")
ANONYMOUS = Principal(user="anonymous", role=Role.admin)
CHALLENGE = {"WWW-Authenticate": 'Bearer realm="fmscell"'}


def identify(
    settings: ApiSettings,
    presented: str | None,
    *,
    limiter: AuthFailureLimiter | None = None,
    address: str | None = None,
) -> Principal:
    """The caller behind `presented` (a key or None), or Unauthenticated (a 401 problem);
    TooManyAuthFailures (429) while `address` has too many failed authentications
    (web_api/ratelimit.py)."""
    if settings.insecure_open:
        return ANONYMOUS
    if not presented:
        raise Unauthenticated(
            "no API key: send it as X-API-Key or Authorization: Bearer", headers=CHALLENGE
        )
    address = address or "unknown"
    if limiter is not None and (wait := limiter.retry_after(address)) is not None:
        raise TooManyAuthFailures(
            f"{limiter.limit} failed authentications from {address} within"
            f" {limiter.window_s:g} s: try again in {wait} s",
            headers={"Retry-After": str(wait)},
            retry_after_s=wait,
        )
    principal = settings.authenticate(presented)
    if principal is None:
        if limiter is not None:
            limiter.failed(address)
        raise Unauthenticated("the API key is not known", headers=CHALLENGE)
    return principal


def _limiter(app) -> AuthFailureLimiter | None:
    return getattr(app.state, "auth_failures", None)


def authorise(principal: Principal, needed: Role, action: str) -> Principal:
    if principal.role < needed:
        raise Forbidden(
            f"{action} needs the {needed.name} role; {principal.user!r} is a {principal.role.name}",
            needed_role=needed.name,
            role=principal.role.name,
        )
    return principal


def require(needed: Role, action: str):
    """A dependency giving the caller's Principal if their role is at least `needed`."""

    def dependency(
        request: Request,
        services: Annotated[Services, Depends(get_services)],
        api_key: Annotated[str | None, Depends(_api_key_header)] = None,
        bearer: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)] = None,
    ) -> Principal:
        presented = api_key or (bearer.credentials if bearer else None)
        if presented is None and request.url.path.startswith("/api/events"):
            presented = request.query_params.get("api_key")
        principal = identify(
            services.settings,
            presented,
            limiter=_limiter(request.app),
            address=request.client.host if request.client else None,
        )
        return authorise(principal, needed, action)

    return dependency


def websocket_principal(websocket: WebSocket, settings: ApiSettings, needed: Role) -> Principal:
    """The same check for a WebSocket handshake (header, bearer or `?api_key=`)."""
    presented = websocket.headers.get("x-api-key") or websocket.query_params.get("api_key")
    auth = websocket.headers.get("authorization", "")
    if not presented and auth.lower().startswith("bearer "):
        presented = auth[7:].strip()
    principal = identify(
        settings,
        presented,
        limiter=_limiter(websocket.app),
        address=websocket.client.host if websocket.client else None,
    )
    return authorise(principal, needed, "reading events")


Viewer = Annotated[Principal, Depends(require(Role.viewer, "reading"))]
Operator = Annotated[Principal, Depends(require(Role.operator, "dispatching and running jobs"))]
Programmer = Annotated[
    Principal, Depends(require(Role.programmer, "uploading and releasing programs"))
]
Admin = Annotated[Principal, Depends(require(Role.admin, "fault injection"))]

router = APIRouter(tags=["auth"], responses=problem_doc(401, 403))


@router.get("/api/whoami", response_model=WhoAmI, summary="The caller's user and role")
def whoami(principal: Viewer) -> WhoAmI:
    return WhoAmI(user=principal.user, role=principal.role.name)
