"""Liveness and readiness: the API answers and the database takes a query.

The database probe runs on a thread of its own and is waited for at most
HEALTH_DEADLINE_S: a database that accepts connections and never answers (a frozen server,
a half-open link) gives a 503 within the deadline, never a health check that hangs with it
(container orchestrators then restart the wrong thing, or nothing). One probe at a time: a
probe still hanging is shared by the checks that come meanwhile, so a dead database costs
one thread, not one per check.
"""

from __future__ import annotations

import threading
import weakref
from concurrent.futures import Future
from typing import Annotated

from fastapi import APIRouter, Depends

from dnc.db import ping
from dnc.errors import DatabaseUnavailable
from web_api.problems import problem_doc
from web_api.routers import Services, get_services
from web_api.schemas import Health

router = APIRouter(tags=["health"])

#: the health answer comes within 2 s whatever the database does
HEALTH_DEADLINE_S = 1.5


class DatabaseProbe:
    """`dnc.db.ping` with a deadline, on a daemon thread (a hung one never blocks exit)."""

    def __init__(self, sessions) -> None:
        self._sessions = sessions
        self._lock = threading.Lock()
        self._running: Future | None = None

    def check(self, deadline_s: float = HEALTH_DEADLINE_S) -> None:
        """Return when the database answered; DatabaseUnavailable if it refused or did
        not answer within `deadline_s`."""
        with self._lock:
            probe = self._running
            if probe is None or probe.done():
                probe = self._running = Future()
                threading.Thread(
                    target=self._run, args=(probe,), name="db-health-probe", daemon=True
                ).start()
        try:
            probe.result(timeout=deadline_s)
        except TimeoutError:
            raise DatabaseUnavailable(
                f"database unavailable: no answer within {deadline_s:g} s"
            ) from None

    def _run(self, probe: Future) -> None:
        try:
            ping(self._sessions)
        except BaseException as exc:  # noqa: BLE001 - handed to the waiting check
            probe.set_exception(exc)
        else:
            probe.set_result(None)


_probes: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_probes_lock = threading.Lock()


def probe_for(sessions) -> DatabaseProbe:
    with _probes_lock:
        probe = _probes.get(sessions)
        if probe is None:
            probe = _probes[sessions] = DatabaseProbe(sessions)
        return probe


@router.get(
    "/api/health",
    response_model=Health,
    summary="Health (no key needed): 200 when the database answers, else a 503 problem "
    f"(within {HEALTH_DEADLINE_S:g} s whatever the database does)",
    responses=problem_doc(503),
)
def health(services: Annotated[Services, Depends(get_services)]) -> Health:
    probe_for(services.sessions).check()  # DatabaseUnavailable -> 503 problem
    return Health(
        status="ok",
        database="ok",
        insecure_open=services.settings.insecure_open,
        faults_enabled=services.faults_enabled,
    )
