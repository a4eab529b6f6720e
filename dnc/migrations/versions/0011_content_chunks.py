"""Program text in chunks of whole lines (`content_chunks`), indexed a chunk at a time.

A text was one row (`contents.text`): storing a 15 MB program bound it whole to one
statement, and SQLite's trigram index tokenised it as one document in memory, some 6 bytes
of host memory per byte of program. Each text is now cut into chunks of at most 256 KiB
that end at a line end (dnc/content.py), one row each; `contents` keeps the sha256 and size.

SQLite's search index (0005) keys an entry by `program_id << 32 | chunk id`: one entry per
chunk of each distinct text of a program, so hits still come grouped by program, in
program order. Two revisions of a program with the same text share their entries; the
triggers add them with the first such revision and remove them with the last.
PostgreSQL: the pg_trgm index moves from contents.text to content_chunks.text.

Revision ID: 0011
Revises: 0010
Create Date: 2026-11-26
"""

import sqlalchemy as sa
from alembic import op

revision = "0011"
down_revision = "0010"
branch_labels = None
depends_on = None

CHUNK_CHARS = 1 << 18  # as dnc.content cut them when this migration was written

_OTHER = "SELECT 1 FROM revisions r WHERE r.program_id = {r}.program_id AND r.sha256 = {r}.sha256"
_ADD = (
    "INSERT INTO revision_text(rowid, text) SELECT ({r}.program_id << 32) | c.id, c.text "
    "FROM content_chunks c WHERE c.sha256 = {r}.sha256"
)
_REMOVE = (
    "INSERT INTO revision_text(revision_text, rowid, text) "
    "SELECT 'delete', ({r}.program_id << 32) | c.id, c.text "
    "FROM content_chunks c WHERE c.sha256 = {r}.sha256"
)
_SQLITE_INDEX = [
    "CREATE VIRTUAL TABLE revision_text USING fts5("
    "text, content='', columnsize=0, tokenize='trigram')",
    "INSERT INTO revision_text(rowid, text) SELECT (p.program_id << 32) | c.id, c.text "
    "FROM (SELECT DISTINCT program_id, sha256 FROM revisions) p "
    "JOIN content_chunks c ON c.sha256 = p.sha256 ORDER BY 1",
    "CREATE TRIGGER revision_text_insert AFTER INSERT ON revisions "
    f"WHEN NOT EXISTS ({_OTHER.format(r='new')} AND r.id != new.id) "
    f"BEGIN {_ADD.format(r='new')}; END",
    "CREATE TRIGGER revision_text_delete AFTER DELETE ON revisions "
    f"WHEN NOT EXISTS ({_OTHER.format(r='old')}) BEGIN {_REMOVE.format(r='old')}; END",
    "CREATE TRIGGER revision_text_update AFTER UPDATE OF program_id, sha256 ON revisions "
    "WHEN old.program_id IS NOT new.program_id OR old.sha256 IS NOT new.sha256 BEGIN "
    f"{_REMOVE.format(r='old')} AND NOT EXISTS ({_OTHER.format(r='old')}); "
    f"{_ADD.format(r='new')} AND NOT EXISTS ({_OTHER.format(r='new')} AND r.id != new.id); "
    "END",
]
_SQLITE_DROP_INDEX = [
    "DROP TRIGGER IF EXISTS revision_text_insert",
    "DROP TRIGGER IF EXISTS revision_text_delete",
    "DROP TRIGGER IF EXISTS revision_text_update",
    "DROP TABLE IF EXISTS revision_text",
]
# 0005's index, as 0005 made it (for the downgrade)
_KEY = "({r}.program_id << 32) | {r}.id"
_SQLITE_0005_INDEX = [
    "CREATE VIRTUAL TABLE revision_text USING fts5("
    "text, content='', columnsize=0, tokenize='trigram')",
    "INSERT INTO revision_text(rowid, text) "
    f"SELECT {_KEY.format(r='r')}, c.text FROM revisions r JOIN contents c ON c.sha256 = r.sha256",
    "CREATE TRIGGER revision_text_insert AFTER INSERT ON revisions BEGIN "
    "INSERT INTO revision_text(rowid, text) "
    f"SELECT {_KEY.format(r='new')}, text FROM contents WHERE sha256 = new.sha256; END",
    "CREATE TRIGGER revision_text_delete AFTER DELETE ON revisions BEGIN "
    "INSERT INTO revision_text(revision_text, rowid, text) "
    f"SELECT 'delete', {_KEY.format(r='old')}, text FROM contents WHERE sha256 = old.sha256; END",
    "CREATE TRIGGER revision_text_update AFTER UPDATE OF program_id, sha256 ON revisions BEGIN "
    "INSERT INTO revision_text(revision_text, rowid, text) "
    f"SELECT 'delete', {_KEY.format(r='old')}, text FROM contents WHERE sha256 = old.sha256; "
    "INSERT INTO revision_text(rowid, text) "
    f"SELECT {_KEY.format(r='new')}, text FROM contents WHERE sha256 = new.sha256; END",
]
_PG_TRGM = "SELECT 1 FROM pg_extension WHERE extname = 'pg_trgm'"


def _split(text: str):
    start, end = 0, len(text)
    while end - start > CHUNK_CHARS:
        cut = text.rfind("\n", start, start + CHUNK_CHARS)
        stop = cut + 1 if cut >= start else start + CHUNK_CHARS
        yield text[start:stop]
        start = stop
    if start < end:
        yield text[start:]


def upgrade() -> None:
    bind = op.get_bind()
    dialect = bind.dialect.name
    chunks = op.create_table(
        "content_chunks",
        sa.Column("id", sa.Integer, nullable=False),
        sa.Column("sha256", sa.String(64), nullable=False),
        sa.Column("seq", sa.Integer, nullable=False),
        sa.Column("text", sa.Text, nullable=False),
        sa.PrimaryKeyConstraint("id", name="pk_content_chunks"),
        sa.ForeignKeyConstraint(
            ["sha256"],
            ["contents.sha256"],
            ondelete="CASCADE",
            name="fk_content_chunks_sha256_contents",
        ),
        sa.UniqueConstraint("sha256", "seq", name="uq_content_chunks_sha256_seq"),
    )
    # one text at a time, not the library at once
    shas = [r[0] for r in bind.execute(sa.text("SELECT sha256 FROM contents ORDER BY sha256"))]
    for sha in shas:
        text = bind.execute(
            sa.text("SELECT text FROM contents WHERE sha256 = :sha"), dict(sha=sha)
        ).scalar_one()
        rows = [dict(sha256=sha, seq=i, text=part) for i, part in enumerate(_split(text))]
        if rows:
            op.bulk_insert(chunks, rows)
    if dialect == "sqlite":
        for statement in _SQLITE_DROP_INDEX + _SQLITE_INDEX:
            op.execute(statement)
        # SQLite 3.35+: in place (batch mode would copy `contents`, which others reference)
        op.execute("ALTER TABLE contents DROP COLUMN text")
    else:
        op.execute("DROP INDEX IF EXISTS ix_contents_text_trgm")
        op.drop_column("contents", "text")
        if dialect == "postgresql" and bind.execute(sa.text(_PG_TRGM)).first():
            op.execute(
                "CREATE INDEX ix_content_chunks_text_trgm ON content_chunks "
                "USING gin (text gin_trgm_ops)"
            )


def downgrade() -> None:
    bind = op.get_bind()
    dialect = bind.dialect.name
    op.add_column("contents", sa.Column("text", sa.Text, nullable=False, server_default=""))
    shas = [r[0] for r in bind.execute(sa.text("SELECT sha256 FROM contents ORDER BY sha256"))]
    for sha in shas:
        parts = bind.execute(
            sa.text("SELECT text FROM content_chunks WHERE sha256 = :sha ORDER BY seq"),
            dict(sha=sha),
        ).scalars()
        bind.execute(
            sa.text("UPDATE contents SET text = :text WHERE sha256 = :sha"),
            dict(text="".join(parts), sha=sha),
        )
    if dialect == "sqlite":
        for statement in _SQLITE_DROP_INDEX + _SQLITE_0005_INDEX:
            op.execute(statement)
    else:
        op.alter_column("contents", "text", server_default=None)
        op.execute("DROP INDEX IF EXISTS ix_content_chunks_text_trgm")
        if dialect == "postgresql" and bind.execute(sa.text(_PG_TRGM)).first():
            op.execute(
                "CREATE INDEX IF NOT EXISTS ix_contents_text_trgm ON contents "
                "USING gin (text gin_trgm_ops)"
            )
    op.drop_table("content_chunks")
