"""Shared fixtures of the REST API tests (imported by the other test_api_* modules) and the
tests of the API's settings, cursors and problem documents.

Every API test runs on SQLite and, when a server answers, PostgreSQL (the DNC fixtures).
"""

from __future__ import annotations

import hashlib
import shutil
from dataclasses import dataclass

import pytest
from fastapi.testclient import TestClient
from pydantic import ValidationError
from sqlalchemy import text

from dnc.db import make_engine, migrate, session_factory
from dnc.dispatch import Dispatches
from dnc.errors import InvalidCursor
from dnc.jobs import Jobs
from dnc.library import Library
from tests.dnc.conftest import BACKENDS, TABLES, fake_checker, pg_url  # noqa: F401
from web_api.app import create_app
from web_api.problems import dnc_status
from web_api.routers import decode_cursor, encode_cursor
from web_api.settings import ApiSettings, Role

ROLES = ("viewer", "operator", "programmer", "admin")
KEYS = {role: f"{role}-key-{'0123456789abcdef'}" for role in ROLES}
UPLOAD_LIMIT = 4096
GOOD = "%\nO1001 (BRACKET)\nN10 G0 X0 Y0\nN20 G1 X10 F100\nN30 M30\n%\n"
PROBLEM = "application/problem+json"
# Request-shape tests never reach the database's dialect: SQLite is enough for them.
SQLITE_ONLY = pytest.mark.parametrize("engine", ["sqlite"], indirect=True)
BASE = "https://fmscell.dev/problems/"


def settings(**over) -> ApiSettings:
    keys = [{"user": f"{r}-user", "role": r, "key": KEYS[r]} for r in ROLES]
    return ApiSettings.from_mapping(
        {
            "api_keys": keys,
            "upload_limit_bytes": UPLOAD_LIMIT,
            "events_poll_s": 0.01,
            **over,
        }
    )


@pytest.fixture(scope="session")
def sqlite_template(tmp_path_factory):
    """One migrated SQLite file; each test gets a copy (migrating per test is slow)."""
    path = tmp_path_factory.mktemp("api-template") / "fmscell.db"
    eng = make_engine(f"sqlite:///{path}")
    migrate(eng)
    with eng.connect() as conn:
        conn.exec_driver_sql("PRAGMA wal_checkpoint(TRUNCATE)")
    eng.dispose()
    return path


@pytest.fixture(params=BACKENDS)
def engine(request, tmp_path):
    if request.param == "sqlite":
        db = tmp_path / "fmscell.db"
        shutil.copy(request.getfixturevalue("sqlite_template"), db)
        eng = make_engine(f"sqlite:///{db}")
    else:
        eng = make_engine(request.getfixturevalue("pg_url"))
        with eng.begin() as conn:
            conn.execute(text(f"TRUNCATE {TABLES} RESTART IDENTITY CASCADE"))
    yield eng
    eng.dispose()


@pytest.fixture
def sessions(engine):
    return session_factory(engine)


@dataclass
class Api:
    client: TestClient
    library: Library
    dispatches: Dispatches
    jobs: Jobs
    sessions: object

    def h(self, role: str = "admin", **extra) -> dict:
        return {"X-API-Key": KEYS[role], **extra}

    def get(self, url: str, role: str = "viewer", **kw):
        return self.client.get(url, headers=self.h(role, **kw.pop("headers", {})), **kw)

    def post(self, url: str, role: str = "admin", **kw):
        return self.client.post(url, headers=self.h(role, **kw.pop("headers", {})), **kw)

    def upload(self, number: int = 1001, text: str = GOOD, **fields) -> dict:
        body = {"number": number, "name": f"part {number}", "text": text, **fields}
        r = self.post("/api/programs", role="programmer", json=body)
        assert r.status_code == 201, r.text
        return r.json()

    def released(self, number: int = 1001, text: str = GOOD) -> int:
        rev = self.upload(number, text)["revision"]["id"]
        r = self.post(f"/api/revisions/{rev}/release", role="programmer", json={"comment": "ok"})
        assert r.status_code == 200, r.text
        return rev


def make_api(sessions, checker=fake_checker, **settings_over) -> Api:  # noqa: F811
    library = Library(sessions, checker=checker, upload_limit=UPLOAD_LIMIT)
    for name, kind in (("mill-1", "mill"), ("mill-2", "mill"), ("lathe-1", "lathe")):
        library.register_machine(name, kind, memory_bytes=64 * 1024)
    dispatches, jobs = Dispatches(sessions), Jobs(sessions)
    provider = settings_over.pop("machines_provider", None)
    opcua = settings_over.pop("opcua_addresses", None)
    app = create_app(
        settings(**settings_over),
        library=library,
        dispatches=dispatches,
        jobs=jobs,
        sessions=sessions,
        machines_provider=provider,
        opcua_addresses=opcua,
    )
    return Api(TestClient(app), library, dispatches, jobs, sessions)


@pytest.fixture
def api(sessions):  # noqa: F811
    a = make_api(sessions)
    with a.client:
        yield a


def assert_problem(r, status: int, kind: str) -> dict:
    assert r.status_code == status, r.text
    assert r.headers["content-type"].startswith(PROBLEM), r.headers["content-type"]
    body = r.json()
    assert body["type"] == BASE + kind, body
    assert body["status"] == status
    assert body["title"] and body["detail"] and body["instance"]
    return body


# ----------------------------------------------------------------------------- settings


def test_roles_are_ordered_and_named_in_configuration():
    assert Role.viewer < Role.operator < Role.programmer < Role.admin
    s = settings()
    assert s.authenticate(KEYS["operator"]).role is Role.operator
    assert s.authenticate(KEYS["operator"]).user == "operator-user"
    assert s.authenticate("not-a-key-of-anyone") is None


def test_a_key_may_be_configured_by_its_sha256():
    digest = hashlib.sha256(b"a-long-secret-key-1234").hexdigest()
    s = ApiSettings.from_mapping(
        {"api_keys": [{"user": "ci", "role": "operator", "key_sha256": digest}]}
    )
    assert s.authenticate("a-long-secret-key-1234").user == "ci"


@pytest.mark.parametrize(
    ("entry", "message"),
    [
        (
            {"user": "x", "role": "boss", "key": "k" * 16},
            r"api_keys\.0\.role\n  Input should be 'viewer', 'operator', 'programmer' or 'admin'",
        ),
        ({"user": "x", "role": "admin"}, "exactly one of key, key_sha256"),
        ({"user": "x", "role": "admin", "key": "short"}, "at least 16"),
    ],
)
def test_bad_key_configuration_names_the_reason(entry, message):
    with pytest.raises(ValidationError, match=message):
        ApiSettings.from_mapping({"api_keys": [entry]})


def test_duplicate_keys_are_refused():
    entry = {"user": "x", "role": "admin", "key": "k" * 16}
    with pytest.raises(ValidationError, match="same key"):
        ApiSettings.from_mapping({"api_keys": [entry, {**entry, "user": "y"}]})


def test_unknown_setting_is_refused_by_name():
    with pytest.raises(ValidationError, match="upload_limit"):
        ApiSettings.from_mapping({"upload_limit": 5})


def test_cursor_round_trip_and_foreign_cursors():
    assert decode_cursor("j", encode_cursor("j", 42)) == 42
    for foreign in ("garbage!", encode_cursor("d", 42), encode_cursor("j", 2**40), "é"):
        with pytest.raises(InvalidCursor) as exc:
            decode_cursor("j", foreign)
        assert dnc_status(exc.value) == 400 and exc.value.kind == "invalid-cursor"
