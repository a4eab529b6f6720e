"""Revision kinds: G-code, APT source or CL data; the G-code posted from a source.

A revision of kind `apt` or `cl` is posted for a machine's kind when it is dispatched
(dnc/posting.py); the posted text is stored as a derived revision, and the dispatch sends
that. Every revision before this migration is G-code.

Revision ID: 0008
Revises: 0007
Create Date: 2026-11-26
"""

import sqlalchemy as sa
from alembic import op

revision = "0008"
down_revision = "0007"
branch_labels = None
depends_on = None


def upgrade() -> None:
    # plain ALTER TABLE on both backends: SQLite's batch mode would copy `revisions` and
    # `dispatches`, which other tables reference
    op.add_column(
        "revisions", sa.Column("kind", sa.String(8), nullable=False, server_default="gcode")
    )
    op.add_column(
        "revisions", sa.Column("post_kinds", sa.JSON, nullable=False, server_default="[]")
    )
    op.create_table(
        "derived_revisions",
        sa.Column("id", sa.Integer, nullable=False),
        sa.Column("source_revision_id", sa.Integer, nullable=False),
        sa.Column("machine_kind", sa.String(32), nullable=False),
        sa.Column("post_name", sa.String(64), nullable=False),
        sa.Column("post_version", sa.String(32), nullable=False),
        sa.Column("tolerance_mm", sa.Float, nullable=True),
        sa.Column("sha256", sa.String(64), nullable=False),
        sa.Column("size", sa.Integer, nullable=False),
        sa.Column("lines", sa.Integer, nullable=False),
        sa.Column("machine", sa.String(64), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(
            ["source_revision_id"],
            ["revisions.id"],
            name="fk_derived_revisions_source_revision_id_revisions",
        ),
        sa.ForeignKeyConstraint(
            ["sha256"], ["contents.sha256"], name="fk_derived_revisions_sha256_contents"
        ),
        sa.PrimaryKeyConstraint("id", name="pk_derived_revisions"),
        sa.UniqueConstraint(
            "source_revision_id", "machine_kind", "sha256", name="uq_derived_revisions_post"
        ),
    )
    op.create_index(
        "ix_derived_revisions_source_revision_id", "derived_revisions", ["source_revision_id"]
    )
    # the derived revision a dispatch sends (no foreign key: SQLite cannot add one to an
    # existing table without copying it; dnc/posting.py writes both in one transaction)
    op.add_column("dispatches", sa.Column("derived_id", sa.Integer, nullable=True))


def downgrade() -> None:
    # 0006 knows only G-code: an APT or CL revision would pass for a G-code program there
    sources = (
        op.get_bind()
        .execute(sa.text("SELECT count(*) FROM revisions WHERE kind <> 'gcode'"))
        .scalar()
    )
    if sources:
        raise RuntimeError(
            f"{sources} APT/CL revision(s) in the library: 0006 cannot tell them from G-code; "
            "obsolete and remove them before downgrading"
        )
    op.execute("ALTER TABLE dispatches DROP COLUMN derived_id")
    op.drop_index("ix_derived_revisions_source_revision_id", "derived_revisions")
    op.drop_table("derived_revisions")
    op.execute("ALTER TABLE revisions DROP COLUMN post_kinds")
    op.execute("ALTER TABLE revisions DROP COLUMN kind")
