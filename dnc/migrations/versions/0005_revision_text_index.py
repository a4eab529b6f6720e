"""Text search index keyed by program: one trigram entry per revision, rowid = program, revision.

0004 indexed each distinct content once, so a hit named a content, and finding its programs
took a join over the revisions (one lookup per hit): a text in 1 % of a million revisions
cost tens of milliseconds before the first program was known. Here each revision is indexed
under rowid `program_id << 32 | revision_id`, so the index hands out hits grouped by program
in program order: a page of programs is the first few hits past the cursor, and the search
stops there. The index is contentless (the text is already in `contents`); the triggers
remove an entry by the FTS5 'delete' command with the text it was indexed from, which
contents keeps unchanged (it is addressed by its sha256).

SQLite only. PostgreSQL keeps the pg_trgm index on contents.text from 0004.

Revision ID: 0005
Revises: 0004
Create Date: 2026-11-21
"""

from alembic import op

revision = "0005"
down_revision = "0004"
branch_labels = None
depends_on = None

_KEY = "({r}.program_id << 32) | {r}.id"
_SQLITE_UP = [
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
    # The content-keyed index of 0004 has no reader left; it held a second copy of every text.
    "DROP TRIGGER IF EXISTS contents_fts_insert",
    "DROP TRIGGER IF EXISTS contents_fts_delete",
    "DROP TABLE IF EXISTS contents_fts",
]
_SQLITE_DOWN = [
    "DROP TRIGGER IF EXISTS revision_text_insert",
    "DROP TRIGGER IF EXISTS revision_text_delete",
    "DROP TRIGGER IF EXISTS revision_text_update",
    "DROP TABLE IF EXISTS revision_text",
    # 0004's index as 0004 made it.
    "CREATE VIRTUAL TABLE contents_fts USING fts5(sha256 UNINDEXED, text, tokenize='trigram')",
    "INSERT INTO contents_fts(sha256, text) SELECT sha256, text FROM contents",
    "CREATE TRIGGER contents_fts_insert AFTER INSERT ON contents BEGIN "
    "INSERT INTO contents_fts(sha256, text) VALUES (new.sha256, new.text); END",
    "CREATE TRIGGER contents_fts_delete AFTER DELETE ON contents BEGIN "
    "DELETE FROM contents_fts WHERE sha256 = old.sha256; END",
]


def upgrade() -> None:
    if op.get_bind().dialect.name == "sqlite":
        for statement in _SQLITE_UP:
            op.execute(statement)


def downgrade() -> None:
    if op.get_bind().dialect.name == "sqlite":
        for statement in _SQLITE_DOWN:
            op.execute(statement)
