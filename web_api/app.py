"""The app factory: one FastAPI app over the DNC host's services, with no global state.

The cell server builds the services (Library, Dispatches, Jobs on one session factory) and
hands them in; the app only translates HTTP to service calls and refusals to problem+json.
"""

from __future__ import annotations

from collections.abc import AsyncIterator, Callable, Mapping
from contextlib import asynccontextmanager
from typing import Any

from fastapi import FastAPI
from fastapi.openapi.utils import get_openapi
from sqlalchemy.orm import Session, sessionmaker

from dnc.cell import CellControl
from dnc.dispatch import Dispatches
from dnc.jobs import Jobs
from dnc.library import Library
from web_api.api_docs import install_api_docs
from web_api.dashboard import dashboard_router
from web_api.event_hub import outbox_hub
from web_api.mtconnect import mtconnect_router
from web_api.problems import BodySizeLimit, Problem, install_problem_handlers, problem_doc
from web_api.ratelimit import AuthFailureLimiter
from web_api.routers import MachinesProvider, Services
from web_api.routers import auth as auth_router
from web_api.routers import dispatches as dispatches_router
from web_api.routers import events as events_router
from web_api.routers import faults as faults_router
from web_api.routers import health as health_router
from web_api.routers import jobs as jobs_router
from web_api.routers import machine_commands as machine_commands_router
from web_api.routers import machine_data as machine_data_router
from web_api.routers import machines as machines_router
from web_api.routers import programs as programs_router
from web_api.routers import revisions as revisions_router
from web_api.schemas import ProgramCreate, RevisionCreate
from web_api.settings import ApiSettings

API_VERSION = "1.0.0"
DESCRIPTION = """\
REST API of the fmscell DNC host: the program library (programs, revisions, release,
diff), dispatches to machines, the FMS job queue and the event stream.

Authenticate with an API key in `X-API-Key` or `Authorization: Bearer`. Roles: viewer
(read), operator (dispatches, jobs, machine commands), programmer (upload, release), admin
(faults). Every error is `application/problem+json` (RFC 9457) with a stable `type`.
"""


def create_app(
    settings: ApiSettings,
    *,
    library: Library,
    dispatches: Dispatches,
    jobs: Jobs,
    sessions: sessionmaker[Session],
    machines_provider: MachinesProvider | None = None,
    opcua_addresses: Callable[[], Mapping[str, str]] | None = None,
    faults_enabled: bool = False,
    mtconnect_agent: Any | None = None,
    cell_control: CellControl | None = None,
) -> FastAPI:
    """The API over the given services.

    `sessions` is the session factory the services use (health checks and the event stream
    read through it). `machines_provider`, when given, returns each machine's live status by
    name and is joined into `/api/machines`; `opcua_addresses` gives each machine's OPC UA
    endpoint (`opcua_address`). `mtconnect_agent` mounts the MTConnect agent
    under `/mtconnect`. `faults_enabled` is reported by `/api/health`; the fault routes
    arrive with the machine endpoints.
    """
    hub = outbox_hub(
        sessions,
        poll_s=settings.events_poll_s,
        capacity=settings.events_ring_size,
        max_age_s=settings.events_ring_age_s,
    )

    @asynccontextmanager
    async def lifespan(_app: FastAPI) -> AsyncIterator[None]:
        # The hub's reader starts with its first subscriber (so a server run without
        # lifespan still streams); shutting down stops it and ends every open stream.
        hub.reopen()
        try:
            yield
        finally:
            hub.close()

    app = FastAPI(
        lifespan=lifespan,
        # /docs and /redoc from the package, not a CDN (web_api/api_docs.py)
        docs_url=None,
        redoc_url=None,
        title="fmscell",
        version=API_VERSION,
        description=DESCRIPTION,
        openapi_tags=[
            {"name": n}
            for n in ("programs", "revisions", "dispatches", "jobs", "machines", "events")
        ],
    )
    app.state.services = Services(
        settings=settings,
        sessions=sessions,
        library=library,
        dispatches=dispatches,
        jobs=jobs,
        machines_provider=machines_provider,
        opcua_addresses=opcua_addresses,
        faults_enabled=faults_enabled,
    )
    app.state.event_hub = hub
    app.state.auth_failures = AuthFailureLimiter(
        settings.auth_failures_max, settings.auth_failures_window_s
    )
    install_problem_handlers(app, settings.problem_base)
    app.add_middleware(BodySizeLimit, limit=settings.request_body_limit, base=settings.problem_base)
    for module in (
        health_router,
        auth_router,
        programs_router,
        revisions_router,
        dispatches_router,
        jobs_router,
        machines_router,
        events_router,
    ):
        app.include_router(module.router)
    # machine commands and fault injection act on the running cell (dnc.cell.CellControl)
    app.state.cell_control = cell_control
    if cell_control is not None:
        app.include_router(machine_commands_router.router)
        app.include_router(machine_data_router.router)
        if faults_enabled:
            app.include_router(faults_router.router)
    if mtconnect_agent is not None:
        app.include_router(mtconnect_router(mtconnect_agent), prefix="/mtconnect")
    app.include_router(dashboard_router())
    install_api_docs(app)
    app.openapi = lambda: _openapi(app)
    return app


def _openapi(app: FastAPI) -> dict:
    """FastAPI's document plus the schemas only referenced from hand-written request bodies
    (uploads take JSON or multipart, so FastAPI cannot derive them)."""
    if app.openapi_schema:
        return app.openapi_schema
    doc = get_openapi(
        title=app.title,
        version=app.version,
        description=app.description,
        routes=app.routes,
        tags=app.openapi_tags,
    )
    schemas = doc.setdefault("components", {}).setdefault("schemas", {})
    for model in (ProgramCreate, RevisionCreate, Problem):
        js = model.model_json_schema(ref_template="#/components/schemas/{model}")
        schemas.update(js.pop("$defs", {}))
        schemas[model.__name__] = js
    # every route that authenticates may answer 429 to an address guessing keys
    too_many = problem_doc(429)[429]
    for operations in doc.get("paths", {}).values():
        for op in operations.values():
            responses = op.get("responses", {}) if isinstance(op, dict) else {}
            if "401" in responses:
                responses.setdefault("429", too_many)
    app.openapi_schema = doc
    return doc
