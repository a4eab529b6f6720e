"""Program dependencies: the other programs each revision calls (M98 P, G65 P, G66 P).

One row per call with a literal program number, read off the revision's text at upload
(cnc.gcode.calls): the number as written, where (line, column of the P word), and whether
it is Fanuc's packed `M98 Pxxxxnnnn` form (repeats and program in one word). Calls are kept
by O number, not by program id: a subprogram may be uploaded after the program that calls
it, and a dispatch resolves each number to the released revision of that moment.
`short_number` is the 4-digit O number a packed call means when no 8-digit program of its
number exists (indexed: which programs call O1000 is two index lookups). Revisions
stored before this migration are scanned here.

Revision ID: 0007
Revises: 0006
Create Date: 2026-11-26
"""

import sqlalchemy as sa
from alembic import op

revision = "0007"
down_revision = "0006"
branch_labels = None
depends_on = None


def upgrade() -> None:
    calls = op.create_table(
        "revision_calls",
        sa.Column(
            "revision_id",
            sa.Integer,
            sa.ForeignKey(
                "revisions.id", ondelete="CASCADE", name="fk_revision_calls_revision_id_revisions"
            ),
            nullable=False,
        ),
        sa.Column("line", sa.Integer, nullable=False),
        sa.Column("col", sa.Integer, nullable=False),
        sa.Column("code", sa.String(3), nullable=False),
        sa.Column("number", sa.Integer, nullable=False),
        sa.Column("packed", sa.Boolean, nullable=False, server_default=sa.false()),
        sa.Column("short_number", sa.Integer, nullable=True),
        sa.PrimaryKeyConstraint("revision_id", "line", "col", name="pk_revision_calls"),
    )
    op.create_index("ix_revision_calls_number", "revision_calls", ["number"])
    op.create_index("ix_revision_calls_short_number", "revision_calls", ["short_number"])
    _scan_stored_revisions(calls)


def _scan_stored_revisions(calls: sa.Table) -> None:
    from cnc.gcode.calls import program_calls

    bind = op.get_bind()
    ids = [r[0] for r in bind.execute(sa.text("SELECT id FROM revisions ORDER BY id"))]
    for at in range(0, len(ids), 500):  # texts a chunk at a time, not the library at once
        texts = bind.execute(
            sa.text(
                "SELECT r.id, c.text FROM revisions r JOIN contents c ON c.sha256 = r.sha256 "
                "WHERE r.id IN :ids"
            ).bindparams(sa.bindparam("ids", expanding=True)),
            dict(ids=ids[at : at + 500]),
        ).all()
        batch = [
            dict(
                revision_id=revision_id,
                line=c.line,
                col=c.col,
                code=c.code,
                number=c.number,
                packed=c.packed,
                short_number=c.short,
            )
            for revision_id, text in texts
            for c in program_calls(text.splitlines()).calls
        ]
        if batch:
            op.bulk_insert(calls, batch)


def downgrade() -> None:
    op.drop_index("ix_revision_calls_short_number", "revision_calls")
    op.drop_index("ix_revision_calls_number", "revision_calls")
    op.drop_table("revision_calls")
