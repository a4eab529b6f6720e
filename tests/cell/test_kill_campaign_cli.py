"""The kill campaign's exit status when PostgreSQL is asked for and does not answer: a
failure (exit 2) with a SKIP line, unless the run says it may go without (--allow-missing-pg).
No campaign runs here: only the PostgreSQL backend is asked for, and it is made absent."""

from __future__ import annotations

import json

import pytest

from tests.cell.test_kill_campaign import _bench


@pytest.fixture
def bench(monkeypatch):
    module = _bench()
    why = "PostgreSQL not reachable at 127.0.0.1:5432/test: connection refused"
    monkeypatch.setattr(module, "postgres_database", lambda: (None, why, None))
    return module


@pytest.mark.parametrize(
    ("flags", "status", "says"),
    [
        ([], 2, "(exit 2)"),
        (["--allow-missing-pg"], 0, "(allowed by --allow-missing-pg)"),
    ],
)
def test_a_postgresql_that_does_not_answer_is_said_and_fails_unless_allowed(
    bench, capsys, flags, status, says
):
    assert bench.main(["--backends", "postgresql", *flags]) == status
    out, err = capsys.readouterr()
    assert err.strip() == (
        "SKIP postgresql: PostgreSQL not reachable at 127.0.0.1:5432/test: connection refused "
        + says
    )
    assert json.loads(out)["postgresql"] == {
        "skipped": "PostgreSQL not reachable at 127.0.0.1:5432/test: connection refused"
    }
