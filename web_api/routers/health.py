"""Liveness and readiness: the API answers and the database takes a query."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends
from sqlalchemy import text

from dnc.db import transaction
from web_api.problems import problem_doc
from web_api.routers import Services, get_services
from web_api.schemas import Health

router = APIRouter(tags=["health"])


@router.get(
    "/api/health",
    response_model=Health,
    summary="Health (no key needed): 200 when the database answers, else a 503 problem",
    responses=problem_doc(503),
)
def health(services: Annotated[Services, Depends(get_services)]) -> Health:
    with transaction(services.sessions) as s:  # DatabaseUnavailable -> 503 problem
        s.execute(text("select 1"))
    return Health(
        status="ok",
        database="ok",
        insecure_open=services.settings.insecure_open,
        faults_enabled=services.faults_enabled,
    )
