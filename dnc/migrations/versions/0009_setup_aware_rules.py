"""Setup-aware dispatch rules: decision rule names up to 64 characters, a machine's last
allocation by index.

A scheduler decision records the dispatch rule that made it; `same_program_first then edd`
(a setup-aware rule and the rule it falls back to, chosen per cell in `host.dispatch_rule`)
does not fit the 16 characters FIFO/SPT/EDD/CR needed. Such a rule asks, per free machine,
for the program of the machine's last allocation: an index on (machine, id) makes that one
seek, however long the history.

Revision ID: 0009
Revises: 0008
Create Date: 2026-11-26
"""

import sqlalchemy as sa
from alembic import op

revision = "0009"
down_revision = "0008"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("decisions") as batch:
        batch.alter_column(
            "rule", existing_type=sa.String(16), type_=sa.String(64), existing_nullable=False
        )
    op.create_index("ix_allocations_machine_id", "allocations", ["machine", "id"])


def downgrade() -> None:
    op.drop_index("ix_allocations_machine_id", table_name="allocations")
    # names longer than 16 characters are cut, not refused: the decisions stay readable
    op.execute("UPDATE decisions SET rule = substr(rule, 1, 16) WHERE length(rule) > 16")
    with op.batch_alter_table("decisions") as batch:
        batch.alter_column(
            "rule", existing_type=sa.String(64), type_=sa.String(16), existing_nullable=False
        )
