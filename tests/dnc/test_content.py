"""Program text stored in chunks of whole lines (dnc/content.py, migration 0011): cut the
same whatever the arrival, read back exactly, searched in every chunk, never half stored,
and stored from an upload with memory flat in the program's size."""

from __future__ import annotations

import ctypes
import ctypes.util
import tracemalloc
import uuid

import pytest
import sqlalchemy as sa
from hypothesis import given, settings
from hypothesis import strategies as st

from dnc import models as m
from dnc.content import CHUNK_CHARS, line_chunks, split_text
from dnc.db import downgrade, make_engine, migrate, session_factory, transaction
from dnc.library import Library
from dnc.tape import sha256_of
from dnc.upload import ProgramUpload

from .conftest import PG_ABSENT, PG_ADMIN

texts = st.lists(st.sampled_from(["G1 X1", "\n", "N10 G0 Y2", "(LONG COMMENT)", "%"])).map("".join)


@settings(max_examples=300, deadline=None)
@given(texts, st.integers(1, 12), st.lists(st.integers(0, 300), max_size=8))
def test_chunks_end_at_line_ends_and_do_not_depend_on_the_arrival(text, size, cuts):
    whole = list(split_text(text, size))
    assert "".join(whole) == text
    for chunk in whole[:-1]:
        # a chunk ends at a line end, unless one line alone is longer than a chunk
        assert len(chunk) <= size and (chunk.endswith("\n") or "\n" not in chunk)
    bounds = sorted({c % (len(text) + 1) for c in cuts}) + [len(text)]
    pieces = [text[a:b] for a, b in zip([0, *bounds], bounds, strict=False)]
    assert list(line_chunks(pieces, size)) == whole


def big_program(number: int, marker: str, lines: int = 30_000) -> str:
    """A program of several chunks, `marker` on a line in its last chunk."""
    body = "".join(f"N{i} G1 X{i % 50}.{i % 10} Y{i % 7}.5 F300\n" for i in range(lines))
    return f"%\nO{number} (BIG)\n{body}({marker})\nM30\n%\n"


def chunk_rows(sessions, sha: str) -> list[str]:
    with transaction(sessions) as s:
        return list(
            s.scalars(
                sa.select(m.ContentChunk.text)
                .where(m.ContentChunk.sha256 == sha)
                .order_by(m.ContentChunk.seq)
            )
        )


def test_a_large_program_is_stored_in_chunks_and_read_back_exactly(sessions):
    library = Library(sessions, upload_limit=1 << 24)
    text = big_program(7, "DEEP INSIDE")
    _, rev = library.create_program(number=7, name="big", text=text)
    rows = chunk_rows(sessions, rev.sha256)
    assert len(rows) == -(-len(text) // CHUNK_CHARS) and len(rows) >= 3
    assert all(r.endswith("\n") for r in rows)
    assert library.revision_text(rev.id) == text
    info, chunks = library.revision_chunks(rev.id)
    assert info.size == len(text) and "".join(chunks) == text
    # the search finds text in the last chunk and the first, not what is in no program
    assert [p.number for p in library.search(text="deep inside").items] == [7]
    assert [p.number for p in library.search(text="O7 (BIG)").items] == [7]
    assert library.search(text="NOT THERE").items == []


def test_two_revisions_of_one_text_share_the_index_until_the_last_goes(tmp_path):
    """SQLite's FTS5 index (PostgreSQL's pg_trgm index follows its table by itself)."""
    engine = make_engine(f"sqlite:///{tmp_path / 'i.db'}")
    migrate(engine)
    lib = Library(session_factory(engine), upload_limit=1 << 24)
    text = big_program(3, "SHARED", lines=12_000)
    prog, _ = lib.create_program(number=3, name="a", text=text)
    lib.add_revision(prog.id, "%\nO3\nG0 X0\n%\n")
    lib.add_revision(prog.id, text)  # the same text again: one set of entries
    with engine.connect() as conn:
        entries = conn.exec_driver_sql("SELECT count(*) FROM revision_text_idx").scalar()
    assert entries > 0
    with engine.begin() as conn:
        conn.exec_driver_sql(f"DELETE FROM revisions WHERE program_id = {prog.id} AND seq = 3")
    assert [p.number for p in lib.search(text="shared").items] == [3]
    with engine.begin() as conn:
        conn.exec_driver_sql(f"DELETE FROM revisions WHERE program_id = {prog.id} AND seq = 1")
    assert lib.search(text="shared").items == []
    with engine.begin() as conn:
        conn.exec_driver_sql("INSERT INTO revision_text(revision_text) VALUES ('integrity-check')")
    engine.dispose()


def test_a_store_that_fails_half_way_leaves_nothing(sessions, monkeypatch):
    """The chunks go in the upload's one transaction: a failure after some of them are
    written stores no content, no chunk, no program (and the next upload goes through)."""
    library = Library(sessions, upload_limit=1 << 24)
    text = big_program(9, "HALF")

    def failing(self):
        yield from list(split_text(text))[:2]
        raise OSError("disk gone")

    with ProgramUpload(limit=1 << 24) as up:
        up.feed(text.encode())
        monkeypatch.setattr(ProgramUpload, "chunks", failing)
        with pytest.raises(OSError, match="disk gone"):
            library.create_program(number=9, name="half", text=up)
    with transaction(sessions) as s:
        for model in (m.Content, m.ContentChunk, m.Program, m.Revision):
            assert s.scalar(sa.select(sa.func.count()).select_from(model)) == 0
    monkeypatch.undo()
    _, rev = library.create_program(number=9, name="half", text=text)
    assert library.revision_text(rev.id) == text


def _migration_round_trip(url: str) -> None:
    eng = make_engine(url)
    migrate(eng)
    lib = Library(session_factory(eng))
    big = big_program(1, "LAST LINES")
    _, r1 = lib.create_program(number=1, name="big", text=big)
    _, r2 = lib.create_program(number=2, name="small", text="%\nO2 (FACE)\nG0 X0\n%\n")
    downgrade(eng, "0010")
    with eng.connect() as conn:
        assert "content_chunks" not in sa.inspect(conn).get_table_names()
        stored = dict(conn.execute(sa.text("SELECT sha256, text FROM contents")).all())
    assert stored == {r1.sha256: big, r2.sha256: "%\nO2 (FACE)\nG0 X0\n%\n"}
    migrate(eng)
    assert lib.revision_text(r1.id) == big and sha256_of(big) == r1.sha256
    assert [p.number for p in lib.search(text="last lines").items] == [1]
    assert [p.number for p in lib.search(text="(face)").items] == [2]
    eng.dispose()


def test_0011_moves_stored_texts_into_chunks_and_back_on_sqlite(tmp_path):
    _migration_round_trip(f"sqlite:///{tmp_path / 'c.db'}")


@pytest.mark.skipif(not PG_ADMIN, reason=f"PostgreSQL not reachable ({PG_ABSENT})")
def test_0011_moves_stored_texts_into_chunks_and_back_on_postgres():
    name = f"fmscell_{uuid.uuid4().hex[:12]}"
    admin = sa.create_engine(PG_ADMIN, isolation_level="AUTOCOMMIT")
    with admin.connect() as conn:
        conn.execute(sa.text(f'CREATE DATABASE "{name}"'))
    try:
        _migration_round_trip(PG_ADMIN.rsplit("/", 1)[0] + f"/{name}")
    finally:
        with admin.connect() as conn:
            conn.execute(sa.text(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)'))
        admin.dispose()


def _sqlite_library():
    """The SQLite library Python's sqlite3 module runs on (its memory statistics)."""
    try:
        lib = ctypes.CDLL(ctypes.util.find_library("sqlite3") or "libsqlite3.so.0")
        lib.sqlite3_memory_highwater.restype = ctypes.c_int64
        return lib
    except OSError:
        return None


def _store_peak(lib: Library, number: int, data: bytes, sqlite) -> int:
    """Bytes of memory at the peak of an upload's store: Python's and SQLite's."""
    with ProgramUpload(limit=64 << 20, name="big.nc") as up:
        for i in range(0, len(data), 1 << 20):
            up.feed(data[i : i + (1 << 20)])
        up.finish()
        sqlite.sqlite3_memory_highwater(1)  # reset to what is in use now
        base_sqlite = sqlite.sqlite3_memory_highwater(0)
        tracemalloc.start()
        try:
            _, rev = lib.create_program(number=number, name="big", text=up)
            _, python = tracemalloc.get_traced_memory()
        finally:
            tracemalloc.stop()
    assert rev.size == len(data) and rev.sha256 == sha256_of(data.decode())
    return python + sqlite.sqlite3_memory_highwater(0) - base_sqlite


def test_the_memory_of_a_stored_upload_is_flat_in_its_size(tmp_path):
    """Issue 14, item 11: storing a 15 MB program took some 6 bytes of host memory per
    byte (the text bound whole to one row, SQLite's trigram index of it built in memory).
    Python's and SQLite's own peak while a 2 MB and an 8 MB upload are checked, stored and
    indexed: the larger costs less than 0.1 byte more per extra byte of program."""
    sqlite = _sqlite_library()
    if sqlite is None:
        pytest.skip("no libsqlite3 to read SQLite's memory statistics from")
    eng = make_engine(f"sqlite:///{tmp_path / 'mem.db'}")
    migrate(eng)
    from .test_upload_stream import _counting_checker

    lib = Library(session_factory(eng), checker=_counting_checker, upload_limit=64 << 20)
    lib.create_program(number=1, name="warm", text=big_program(1, "WARM", lines=2000))
    moves = "".join(f"G1 X{i % 50}.{i % 10} Y{i % 7} F300\n" for i in range(20000))

    def upload(number: int, mb: int) -> bytes:
        body = moves * (mb * (1 << 20) // len(moves) + 1)
        return f"%\nO{number} (BIG)\n{body}M30\n%\n".encode()

    small = _store_peak(lib, 2, upload(2, 2), sqlite)
    large = _store_peak(lib, 8, upload(8, 8), sqlite)
    per_byte = (large - small) / (6 << 20)
    assert per_byte < 0.1, f"{small / 1e6:.1f} MB, {large / 1e6:.1f} MB: {per_byte:.2f} B/B"
    assert large < 16 << 20, f"{large / 1e6:.1f} MB to store 8 MB"
    eng.dispose()
