"""Allocation outcomes: a note kept while the machine cuts on, and where a part was rerouted.

The allocation state machine (dnc/allocation.py) ends every allocation `completed`,
`rerouted` (its part made again by the allocation in `rerouted_to`) or `failed`; alarms and
warnings that do not stop the machine are noted on the allocation, not interrupting it.
Allocations interrupted before this migration stay `interrupted`: the next scheduler tick
settles them (rerouted with the job's next allocation, or failed if the job is closed).

Revision ID: 0006
Revises: 0005
Create Date: 2026-11-26
"""

import sqlalchemy as sa
from alembic import op

revision = "0006"
down_revision = "0005"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("allocations") as batch:
        batch.add_column(sa.Column("note", sa.Text, nullable=False, server_default=""))
        batch.add_column(sa.Column("rerouted_to", sa.Integer, nullable=True))


def downgrade() -> None:
    # the two states this revision brings have no place in 0005's vocabulary
    op.execute(
        "UPDATE allocations SET status = 'interrupted' WHERE status IN ('rerouted', 'failed')"
    )
    with op.batch_alter_table("allocations") as batch:
        batch.drop_column("rerouted_to")
        batch.drop_column("note")
