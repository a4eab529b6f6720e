"""Substring search over program text with a trigram index.

SQLite: an FTS5 table with the trigram tokenizer, filled by a trigger (FTS5 accelerates
`LIKE '%...%'` with it). PostgreSQL: a pg_trgm GIN index on contents.text when the extension
can be created; without it the search still works, by a scan.

Revision ID: 0004
Revises: 0003
Create Date: 2026-11-21
"""

from alembic import op

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None

_SQLITE_UP = [
    "CREATE VIRTUAL TABLE contents_fts USING fts5(sha256 UNINDEXED, text, tokenize='trigram')",
    "INSERT INTO contents_fts(sha256, text) SELECT sha256, text FROM contents",
    "CREATE TRIGGER contents_fts_insert AFTER INSERT ON contents BEGIN "
    "INSERT INTO contents_fts(sha256, text) VALUES (new.sha256, new.text); END",
    "CREATE TRIGGER contents_fts_delete AFTER DELETE ON contents BEGIN "
    "DELETE FROM contents_fts WHERE sha256 = old.sha256; END",
]
_SQLITE_DOWN = [
    "DROP TRIGGER IF EXISTS contents_fts_insert",
    "DROP TRIGGER IF EXISTS contents_fts_delete",
    "DROP TABLE IF EXISTS contents_fts",
]
# Creating an extension needs privileges a hosted database may not grant: then go without.
_PG_UP = [
    "DO $$ BEGIN CREATE EXTENSION IF NOT EXISTS pg_trgm; "
    "EXCEPTION WHEN insufficient_privilege THEN RAISE NOTICE 'pg_trgm not available'; END $$",
    "DO $$ BEGIN IF EXISTS (SELECT 1 FROM pg_extension WHERE extname = 'pg_trgm') THEN "
    "EXECUTE 'CREATE INDEX IF NOT EXISTS ix_contents_text_trgm ON contents "
    "USING gin (text gin_trgm_ops)'; END IF; END $$",
]
_PG_DOWN = ["DROP INDEX IF EXISTS ix_contents_text_trgm"]


def upgrade() -> None:
    dialect = op.get_bind().dialect.name
    for statement in (
        _SQLITE_UP if dialect == "sqlite" else _PG_UP if dialect == "postgresql" else []
    ):
        op.execute(statement)


def downgrade() -> None:
    dialect = op.get_bind().dialect.name
    for statement in (
        _SQLITE_DOWN if dialect == "sqlite" else _PG_DOWN if dialect == "postgresql" else []
    ):
        op.execute(statement)
