"""Database engine, sessions and migrations for the DNC host.

The embedded default is a SQLite file in WAL mode (readers never block the writer, which
matters while machines report status during a transfer). `FMSCELL_DATABASE_URL` selects
PostgreSQL (`postgresql+psycopg://...`). The schema is owned by Alembic: `migrate()` brings
any database to head, so there is no `create_all` path that could drift from the migrations.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from sqlalchemy import Engine, create_engine, event, text
from sqlalchemy.exc import OperationalError
from sqlalchemy.orm import Session, sessionmaker

from dnc.errors import DatabaseUnavailable

DEFAULT_URL = "sqlite:///fmscell.db"
MIGRATIONS = Path(__file__).with_name("migrations")


def database_url(explicit: str | None = None) -> str:
    return explicit or os.environ.get("FMSCELL_DATABASE_URL") or DEFAULT_URL


def normalise_url(url: str) -> str:
    # Users write postgresql://; we ship psycopg 3, not psycopg2 (SQLAlchemy's default).
    if url.startswith("postgresql://"):
        return "postgresql+psycopg://" + url.removeprefix("postgresql://")
    return url


#: a database that does not answer must not hang the host: how long to wait for a new
#: connection (TCP connect, TLS, authentication; also for a free pooled connection) ...
CONNECT_TIMEOUT_S = 5.0
#: ... and for one statement (PostgreSQL statement_timeout; SQLite's busy timeout, the time
#: a statement waits for another process's write lock)
STATEMENT_TIMEOUT_S = 30.0


def make_engine(
    url: str | None = None,
    *,
    connect_timeout_s: float = CONNECT_TIMEOUT_S,
    statement_timeout_s: float = STATEMENT_TIMEOUT_S,
    **kwargs: object,
) -> Engine:
    """An engine with connect and statement time-outs (a hung database costs a request at
    most those, as DatabaseUnavailable, never a thread for ever)."""
    url = normalise_url(database_url(url))
    if url.startswith("sqlite"):
        if ":memory:" not in url and url.rstrip("/") != "sqlite:":
            # One pooled connection per transfer thread (twenty dispatches at once): past the
            # pool the overflow connections were opened and closed per transaction, 10 ms each.
            kwargs = {"pool_size": 20, "max_overflow": 20, **kwargs}
        engine = create_engine(url, connect_args={"timeout": statement_timeout_s}, **kwargs)
        event.listen(engine, "connect", _sqlite_pragmas)
        _one_writer_at_a_time(engine)
    else:
        engine = create_engine(
            url,
            pool_pre_ping=True,
            pool_timeout=connect_timeout_s,
            connect_args=postgresql_timeouts(connect_timeout_s, statement_timeout_s),
            **kwargs,
        )
    return engine


def postgresql_timeouts(connect_timeout_s: float, statement_timeout_s: float) -> dict:
    """libpq connection parameters: connect_timeout (whole seconds, at least 2, as libpq
    takes no less) bounds connecting; statement_timeout and lock_timeout (server side, ms)
    bound each statement; TCP keepalives notice a peer that is gone within about 20 s."""
    ms = max(1, round(statement_timeout_s * 1000))
    return {
        "connect_timeout": max(2, int(-(-connect_timeout_s // 1))),
        "options": f"-c statement_timeout={ms} -c lock_timeout={ms}",
        "keepalives": 1,
        "keepalives_idle": 10,
        "keepalives_interval": 5,
        "keepalives_count": 2,
    }


#: Each SQLite connection's page cache, KiB. SQLite's default, 2000 KiB, fills with every page
#: the connection writes or reads until it holds 2 MB: in a running cell the database grows
#: a couple of MB an hour, so each pooled connection (up to 40) grew the host's memory for
#: an hour or more. 512 KiB holds the hot pages (the b-tree interiors, the newest outbox
#: rows); the rest comes from the operating system's file cache, which is shared and not
#: the process's own.
SQLITE_CACHE_KIB = 512


def _sqlite_pragmas(dbapi_conn, _record) -> None:  # noqa: ANN001 - DB-API connection
    cur = dbapi_conn.cursor()
    cur.execute("PRAGMA journal_mode=WAL")
    cur.execute("PRAGMA foreign_keys=ON")
    cur.execute("PRAGMA synchronous=NORMAL")
    cur.execute(f"PRAGMA cache_size=-{SQLITE_CACHE_KIB}")  # negative: KiB, not pages
    cur.close()


_WRITES = ("INSERT", "UPDATE", "DELETE", "REPLAC")
WRITER_WAIT_S = 30.0


def _one_writer_at_a_time(engine: Engine) -> None:
    """Queue this process's SQLite writers on a lock instead of SQLite's busy handler.

    SQLite has one writer at a time. A writer that finds the file locked sleeps in the busy
    handler, 1, 2, 5, 10 ... 100 ms, however soon the lock is free: with twenty transfer
    threads committing their state changes, those sleeps were most of a dispatch's time.
    pysqlite begins the transaction at the first INSERT/UPDATE/DELETE, so the lock is taken
    there and released at commit or rollback; a waiting writer wakes the moment it is free.
    After WRITER_WAIT_S the writer goes on without it and SQLite's own locking decides (the
    same 30 s busy time-out), so a thread that writes on two connections at once cannot
    hang here. Other processes writing the same file still meet the busy handler.
    """
    lock = threading.Lock()

    def take(conn, _cursor, statement, *_args) -> None:  # noqa: ANN001 - SQLAlchemy event
        if statement.lstrip()[:6].upper() in _WRITES and not conn.info.get("writer"):
            conn.info["writer"] = lock.acquire(timeout=WRITER_WAIT_S)

    def release(conn) -> None:  # noqa: ANN001
        if conn.info.pop("writer", False):
            lock.release()

    def release_on_checkin(_dbapi_conn, record) -> None:  # noqa: ANN001
        # A connection returned without commit or rollback (the pool resets it itself).
        if record.info.pop("writer", False):
            lock.release()

    event.listen(engine, "before_cursor_execute", take)
    event.listen(engine, "commit", release)
    event.listen(engine, "rollback", release)
    event.listen(engine.pool, "checkin", release_on_checkin)


def _alembic_config(engine: Engine):
    from alembic.config import Config

    cfg = Config()
    cfg.set_main_option("script_location", str(MIGRATIONS))
    cfg.attributes["engine"] = engine
    return cfg


def migrate(engine: Engine, revision: str = "head") -> None:
    """Upgrade the schema to `revision` (default: the newest)."""
    from alembic import command

    try:
        command.upgrade(_alembic_config(engine), revision)
    except OperationalError as exc:
        raise DatabaseUnavailable(f"cannot migrate the database: {exc.orig}") from exc


def downgrade(engine: Engine, revision: str = "base") -> None:
    from alembic import command

    command.downgrade(_alembic_config(engine), revision)


def session_factory(engine: Engine) -> sessionmaker[Session]:
    return sessionmaker(engine, expire_on_commit=False)


@contextmanager
def transaction(factory: sessionmaker[Session]) -> Iterator[Session]:
    """One unit of work: commits on success, rolls back everything on any error.

    A database that is down surfaces as DatabaseUnavailable, never as a half-written change.
    """
    session = factory()
    try:
        yield session
        session.commit()
    except OperationalError as exc:
        session.rollback()
        raise DatabaseUnavailable(f"database unavailable: {exc.orig}") from exc
    except BaseException:
        session.rollback()
        raise
    finally:
        session.close()


def ping(factory: sessionmaker[Session]) -> None:
    """One round trip to the database (the readiness probe): returns when it answered,
    DatabaseUnavailable when it refused."""
    with transaction(factory) as s:
        s.execute(text("select 1"))
