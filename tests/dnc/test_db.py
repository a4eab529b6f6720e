"""Migrations, concurrency and a database that is down."""

from __future__ import annotations

import threading

import pytest
import sqlalchemy as sa
from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext

from dnc.db import downgrade, make_engine, migrate, normalise_url, session_factory
from dnc.errors import DatabaseUnavailable
from dnc.library import Library
from dnc.models import Base

from .conftest import PG_ABSENT, PG_ADMIN

PROG = "%\nO{n}\nG0 X0\nM30\n%\n"


def test_migrated_schema_matches_the_models(engine):
    def ours(obj, name, type_, reflected, compare_to):
        # The text search index (SQLite FTS5 table, pg_trgm index) is kept by migrations
        # 0004, 0005 and 0011, not by a model.
        return not (name or "").startswith(
            ("revision_text", "ix_contents_text_trgm", "ix_content_chunks_text_trgm")
        )

    with engine.connect() as conn:
        context = MigrationContext.configure(conn, opts={"include_object": ours})
        assert compare_metadata(context, Base.metadata) == []


def test_migrations_go_down_to_base_and_up_again(tmp_path):
    eng = make_engine(f"sqlite:///{tmp_path / 'm.db'}")
    migrate(eng)
    assert "revisions" in sa.inspect(eng).get_table_names()
    downgrade(eng, "base")
    assert sa.inspect(eng).get_table_names() == ["alembic_version"]
    migrate(eng)
    assert "audit_log" in sa.inspect(eng).get_table_names()


def test_sqlite_runs_in_wal_mode(tmp_path):
    eng = make_engine(f"sqlite:///{tmp_path / 'w.db'}")
    with eng.connect() as conn:
        assert conn.exec_driver_sql("PRAGMA journal_mode").scalar() == "wal"


def test_every_sqlite_connection_takes_the_small_page_cache(tmp_path):
    # SQLite's default (2000 KiB a connection) filled with the growing database for an hour
    # or more in a running cell, the host's RSS growing with it (issue 14's soak)
    eng = make_engine(f"sqlite:///{tmp_path / 'c.db'}")
    with eng.connect() as one, eng.connect() as two:
        for conn in (one, two):
            assert conn.exec_driver_sql("PRAGMA cache_size").scalar() == -512


def test_postgres_url_uses_psycopg3():
    assert normalise_url("postgresql://u@h/db") == "postgresql+psycopg://u@h/db"


def test_database_down_gives_a_clear_error_and_writes_nothing(tmp_path):
    # A port nobody listens on: the connection is refused at once.
    eng = make_engine("postgresql+psycopg://postgres@127.0.0.1:1/none")
    lib = Library(session_factory(eng))
    with pytest.raises(DatabaseUnavailable, match="database unavailable"):
        lib.create_program(number=1, name="A", text=PROG.format(n=1))


@pytest.mark.skipif(not PG_ADMIN, reason=f"PostgreSQL not reachable ({PG_ABSENT})")
def test_ten_concurrent_writers_on_postgres(pg_url):
    eng = make_engine(pg_url, pool_size=10, max_overflow=5)
    with eng.begin() as conn:
        conn.execute(sa.text("TRUNCATE programs, revisions, contents, program_tags CASCADE"))
    lib = Library(session_factory(eng))
    prog, _ = lib.create_program(number=1, name="shared", text=PROG.format(n=1))
    errors: list[Exception] = []
    barrier = threading.Barrier(10)

    def writer(i: int) -> None:
        barrier.wait()
        try:
            lib.create_program(number=100 + i, name=f"p{i}", text=PROG.format(n=100 + i))
            for attempt in range(20):  # revisions of one program race for the next seq
                try:
                    lib.add_revision(prog.id, PROG.format(n=1) + f"(w{i})\n")
                    break
                except Exception as exc:  # Conflict: retry as a client would
                    if attempt == 19:
                        raise exc
        except Exception as exc:
            errors.append(exc)

    threads = [threading.Thread(target=writer, args=(i,)) for i in range(10)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert errors == []
    revs = lib.revisions(prog.id)
    assert sorted(r.seq for r in revs) == list(range(1, 12))
    assert len(lib.search(limit=100).items) == 11
    eng.dispose()


def test_text_index_survives_a_round_trip_through_0004_and_follows_revisions(tmp_path):
    """0005 fills the program-keyed index from the revisions already there, its downgrade
    restores 0004's index, and the triggers keep the index with the revisions."""
    eng = make_engine(f"sqlite:///{tmp_path / 't.db'}")
    migrate(eng)
    lib = Library(session_factory(eng))
    prog, _ = lib.create_program(number=1, name="A", text="%\nO1 (FACE MILL)\nG0 X0\n%\n")
    lib.add_revision(prog.id, "%\nO1 (DRILL)\nG0 X0\n%\n")
    downgrade(eng, "0004")
    with eng.connect() as conn:
        tables = sa.inspect(conn).get_table_names()
        assert "contents_fts" in tables and "revision_text" not in tables
        found = "SELECT count(*) FROM contents_fts WHERE contents_fts MATCH '\"face mill\"'"
        assert conn.exec_driver_sql(found).scalar() == 1
    migrate(eng)
    assert "contents_fts" not in sa.inspect(eng).get_table_names()
    assert [p.number for p in lib.search(text="face mill").items] == [1]
    with eng.begin() as conn:  # a revision moved to another program, then one removed
        other, _ = lib.create_program(number=2, name="B", text="%\nO2\nG0 X0\n%\n")
        conn.exec_driver_sql(f"UPDATE revisions SET program_id = {other.id} WHERE seq = 2")
    assert [p.number for p in lib.search(text="(drill)").items] == [2]
    with eng.begin() as conn:
        conn.exec_driver_sql(f"DELETE FROM revisions WHERE program_id = {other.id} AND seq = 2")
    assert lib.search(text="(drill)").items == []
    assert [p.number for p in lib.search(text="face mill").items] == [1]


def test_0006_allocation_outcomes_down_and_up_again(tmp_path):
    """0006's downgrade folds `rerouted` and `failed` back into 0005's `interrupted`; after
    the upgrade the scheduler settles those again (rerouted with the job's next allocation,
    failed once the job is closed)."""
    from datetime import UTC, datetime

    from dnc.jobs import Jobs, Scheduler
    from dnc.scheduler import MachineView

    from .conftest import fake_checker

    t0 = datetime(2026, 11, 26, 6, 0, tzinfo=UTC)
    eng = make_engine(f"sqlite:///{tmp_path / 'm.db'}")
    migrate(eng)
    sessions = session_factory(eng)
    lib = Library(sessions, checker=fake_checker)
    lib.register_machine("mill1", "mill")
    _, rev = lib.create_program(number=1, name="p", text=PROG.format(n="0001"))
    lib.release(rev.id, approver="a", comment="ok")
    jobs = Jobs(sessions, now=lambda: t0)
    job = jobs.create(revision_id=rev.id, quantity=1)
    state = {"s": "idle"}
    sched = Scheduler(sessions, lambda: [MachineView("mill1", "mill", state["s"], 0)])
    sched.tick()  # allocation 1, dispatched
    state["s"] = "alarm"
    sched.tick()  # interrupted (its dispatch called off)
    state["s"] = "idle"
    sched.tick()  # allocation 2 reroutes it
    jobs.cancel(job.id)
    sched.tick()  # allocation 2 called off, then failed: the job is closed
    assert [a["status"] for a in jobs.allocations(job.id)] == ["rerouted", "failed"]

    downgrade(eng, "0005")
    columns = {c["name"] for c in sa.inspect(eng).get_columns("allocations")}
    assert not {"note", "rerouted_to"} & columns
    with eng.connect() as conn:
        statuses = conn.execute(sa.text("SELECT status FROM allocations ORDER BY id")).scalars()
        assert list(statuses) == ["interrupted", "interrupted"]

    migrate(eng)
    sched.tick()
    assert [a["status"] for a in jobs.allocations(job.id)] == ["failed", "failed"]
    eng.dispose()


def test_0007_program_dependencies_scans_the_revisions_stored_before_it(tmp_path):
    """0007 reads the calls off every revision already stored; its downgrade drops them."""
    eng = make_engine(f"sqlite:///{tmp_path / 'd.db'}")
    migrate(eng)
    lib = Library(session_factory(eng))
    _, main = lib.create_program(
        number=1, name="main", text="%\nO1\nM98 P2 L2\nG65 P9001 A1.\nM30\n%\n"
    )
    _, sub = lib.create_program(number=2, name="sub", text="%\nO2\nG0 X0\nM99\n%\n")
    before = lib.calls(main.id)
    downgrade(eng, "0006")
    assert "revision_calls" not in sa.inspect(eng).get_table_names()
    migrate(eng)
    assert lib.calls(main.id) == before
    assert [(c["code"], c["number"], c["line"]) for c in before] == [
        ("M98", 2, 3),
        ("G65", 9001, 4),
    ]
    assert lib.calls(sub.id) == []
    eng.dispose()


def test_0010_machine_requirements_scans_the_g_code_stored_before_it(tmp_path):
    """0010 finds the axes each G-code revision already stored needs (the NC check only
    where a rotary address is named), leaves sources and machines unknown; its downgrade
    drops the columns."""
    from dnc.checker import nc_checker

    eng = make_engine(f"sqlite:///{tmp_path / 'r.db'}")
    migrate(eng)
    lib = Library(session_factory(eng), checker=nc_checker)
    texts = {
        40: "%\nO40\nG0 X0 Y0 Z20 A0\nG1 X20 A90 F600\nM30\n%\n",
        41: "%\nO41 (PART A1)\nG0 X0 Y0 Z20\nM30\n%\n",  # an A in a comment only
        42: "%\nO42\nG65 P9010 A1. B2.\nM30\n%\n",  # macro arguments
        43: "%\nO43\nG0 X10 Z2\nM30\n%\n",
    }
    revs = {
        n: lib.create_program(
            number=n, name=f"p{n}", text=t, machine_kind="lathe" if n == 43 else "mill"
        )[1].id
        for n, t in texts.items()
    }
    lib.register_machine("mill1", "mill", axes=("X", "Y", "Z"))
    downgrade(eng, "0009")
    assert "axes" not in {c["name"] for c in sa.inspect(eng).get_columns("revisions")}
    migrate(eng)
    got = {n: lib.get_revision(r).axes for n, r in revs.items()}
    assert got == {
        40: ["X", "Y", "Z", "A"],
        41: ["X", "Y", "Z"],
        42: ["X", "Y", "Z"],
        43: ["X", "Z"],
    }
    assert lib.machine("mill1")["axes"] is None  # registered again by the cell at its start
    eng.dispose()
