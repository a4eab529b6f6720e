"""Schemathesis against the app's own OpenAPI document: generated requests for every
operation (bounded examples, SQLite), asserting no 5xx and that every response conforms
to the documented status codes, content types and schemas."""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

import pytest
import schemathesis
from hypothesis import HealthCheck, settings
from schemathesis.generation.modes import GenerationMode
from schemathesis.specs.openapi import checks as oas

from dnc.db import make_engine, migrate, session_factory
from dnc.dispatch import Dispatches
from dnc.jobs import Jobs
from dnc.library import Library
from tests.dnc.conftest import fake_checker
from tests.web_api.test_api_common import GOOD, KEYS
from tests.web_api.test_api_common import settings as api_settings
from web_api.app import create_app

EXAMPLES = 25


def build_app(directory: Path):
    """A cell's API on a fresh SQLite file, seeded so that ids 1..2 exist."""
    eng = make_engine(f"sqlite:///{directory / 'fmscell.db'}")
    migrate(eng)
    s = session_factory(eng)
    library = Library(s, checker=fake_checker, upload_limit=4096)
    for name, kind in (("mill-1", "mill"), ("lathe-1", "lathe")):
        library.register_machine(name, kind)
    _, rev = library.create_program(number=1, name="seed", text=GOOD)
    library.release(rev.id, approver="seed", comment="seed")
    library.create_program(number=2, name="draft", text=GOOD + "(draft)\n")
    jobs = Jobs(s)
    jobs.create(revision_id=rev.id, quantity=2)
    Dispatches(s).request(key="seed", revision_id=rev.id, machine="mill-1")
    app = create_app(
        api_settings(),
        library=library,
        dispatches=Dispatches(s),
        jobs=jobs,
        sessions=s,
        machines_provider=lambda: {"mill-1": {"execution": "READY"}},
    )
    return app, eng


# Schemathesis parametrizes at collection time, so the app exists at import; its database
# lives in a temporary directory removed when the module's tests are done.
_DIR = Path(tempfile.mkdtemp(prefix="fmscell-st-"))
APP, _ENGINE = build_app(_DIR)
schema = schemathesis.openapi.from_asgi("/openapi.json", APP).exclude(
    path="/api/events"  # an endless stream; tested in test_api_events
)


@pytest.fixture(scope="module", autouse=True)
def _cleanup():
    yield
    _ENGINE.dispose()
    shutil.rmtree(_DIR, ignore_errors=True)


CHECKS = [
    schemathesis.checks.not_a_server_error,
    oas.status_code_conformance,
    oas.content_type_conformance,
    oas.response_headers_conformance,
    oas.response_schema_conformance,
]


@schema.parametrize()
@settings(
    max_examples=EXAMPLES,
    deadline=None,
    suppress_health_check=list(HealthCheck),
    derandomize=True,
)
def test_generated_requests_conform(case):
    if case.meta and case.meta.generation.mode is GenerationMode.NEGATIVE:
        # Invalid requests: only "never a 5xx, always a documented problem".
        checks = CHECKS[:3]
    else:
        checks = CHECKS
    case.call_and_validate(headers={"X-API-Key": KEYS["admin"]}, checks=checks)
