"""Database fixtures: every database test runs on SQLite and, when it answers, PostgreSQL.

PostgreSQL is used when FMSCELL_TEST_PG_URL is set or a server answers on 127.0.0.1:5432
(database `test`). Each pytest worker gets its own scratch database, migrated once; each test
starts from empty tables.
"""

from __future__ import annotations

import os
import uuid

import pytest
from sqlalchemy import create_engine, text

from dnc.db import make_engine, migrate, normalise_url, session_factory
from dnc.library import Library

DEFAULT_PG = "postgresql+psycopg://postgres@127.0.0.1:5432/test"
TABLES = (
    "decisions, allocations, dispatches, derived_revisions, jobs, revision_calls, "
    "outbox, audit_log, program_resources, resources, revisions, content_chunks, contents, "
    "program_tags, programs, machines"
)


def _pg_admin_url() -> tuple[str | None, str]:
    """(admin URL, "") when PostgreSQL answers, else (None, why not)."""
    url = os.environ.get("FMSCELL_TEST_PG_URL")
    candidate = normalise_url(url or DEFAULT_PG)
    try:
        eng = create_engine(candidate, connect_args={"connect_timeout": 2})
        with eng.connect() as conn:
            conn.execute(text("select 1"))
        eng.dispose()
    except Exception as exc:
        if url:  # explicitly asked for: a dead server is a failure, not a skip
            raise
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        return None, f"{DEFAULT_PG.replace('+psycopg', '')}: {first}"
    return candidate, ""


PG_ADMIN, PG_ABSENT = _pg_admin_url()
# The PostgreSQL cases are always collected: without a server each one is a skip that says
# why (pytest -ra lists it), never a case that silently vanishes from the run.
BACKENDS = ["sqlite", "postgresql"]


@pytest.fixture(scope="session")
def pg_url():
    if not PG_ADMIN:
        pytest.skip(f"PostgreSQL not reachable ({PG_ABSENT}); start it or set FMSCELL_TEST_PG_URL")
    name = f"fmscell_{uuid.uuid4().hex[:12]}"
    admin = create_engine(PG_ADMIN, isolation_level="AUTOCOMMIT")
    with admin.connect() as conn:
        conn.execute(text(f'CREATE DATABASE "{name}"'))
    url = PG_ADMIN.rsplit("/", 1)[0] + f"/{name}"
    engine = make_engine(url)
    migrate(engine)
    engine.dispose()
    yield url
    with admin.connect() as conn:
        conn.execute(text(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)'))
    admin.dispose()


@pytest.fixture(params=BACKENDS)
def engine(request, tmp_path):
    if request.param == "sqlite":
        eng = make_engine(f"sqlite:///{tmp_path / 'fmscell.db'}")
        migrate(eng)
    else:
        eng = make_engine(request.getfixturevalue("pg_url"))
        with eng.begin() as conn:
            conn.execute(text(f"TRUNCATE {TABLES} RESTART IDENTITY CASCADE"))
    yield eng
    eng.dispose()


@pytest.fixture
def sessions(engine):
    return session_factory(engine)


def fake_checker(text: str, kind: str) -> list[dict]:
    """A stand-in NC check for library tests: lines containing BAD are errors."""
    return [
        {"line": n, "col": line.index("BAD") + 1, "message": "bad word"}
        for n, line in enumerate(text.splitlines(), start=1)
        if "BAD" in line
    ]


@pytest.fixture
def library(sessions):
    return Library(sessions, checker=fake_checker, upload_limit=64 * 1024)
