"""What a program needs of a machine, and what a machine has: the scheduler allocates a
job's parts only to machines that can run its program (dnc/requirements.py).

`revisions.axes`: the axes a machine needs to run a G-code revision (its kind's linear
axes and every rotary axis a block moves or sets), found by the upload check; NULL for an
APT/CL source (its post kinds say what it needs) and when not known. G-code revisions
stored before this migration are scanned here (the NC check runs only on the texts that
name a rotary address of their kind at all). `jobs.needs`: the kinds and axes a job's
machine must have, fixed when the job is queued (NULL: a job queued before, judged by its
machine kind alone). `machines.axes`: a registered machine's configured axes (NULL: not
known, judged by its kind alone).

Revision ID: 0010
Revises: 0009
Create Date: 2026-11-26
"""

import sqlalchemy as sa
from alembic import op

revision = "0010"
down_revision = "0009"
branch_labels = None
depends_on = None


def upgrade() -> None:
    # plain ALTER TABLE ADD COLUMN on both backends (nullable, no copy of the tables)
    op.add_column("revisions", sa.Column("axes", sa.JSON, nullable=True))
    op.add_column("jobs", sa.Column("needs", sa.JSON, nullable=True))
    op.add_column("machines", sa.Column("axes", sa.JSON, nullable=True))
    _scan_stored_revisions()


def _scan_stored_revisions() -> None:
    from dnc.checker import needed_axes

    bind = op.get_bind()
    revisions = sa.table("revisions", sa.column("id"), sa.column("axes", sa.JSON))
    rows = bind.execute(
        sa.text(
            "SELECT r.id, p.machine_kind FROM revisions r JOIN programs p ON p.id = r.program_id"
            " WHERE r.kind = 'gcode' ORDER BY r.id"
        )
    ).all()
    kinds = dict(rows)
    ids = list(kinds)
    for at in range(0, len(ids), 200):  # texts a chunk at a time, not the library at once
        texts = bind.execute(
            sa.text(
                "SELECT r.id, c.text FROM revisions r JOIN contents c ON c.sha256 = r.sha256 "
                "WHERE r.id IN :ids"
            ).bindparams(sa.bindparam("ids", expanding=True)),
            dict(ids=ids[at : at + 200]),
        ).all()
        for revision_id, text in texts:
            axes = list(needed_axes(text, kinds[revision_id]))
            bind.execute(revisions.update().where(revisions.c.id == revision_id).values(axes=axes))


def downgrade() -> None:
    op.execute("ALTER TABLE machines DROP COLUMN axes")
    op.execute("ALTER TABLE jobs DROP COLUMN needs")
    op.execute("ALTER TABLE revisions DROP COLUMN axes")
