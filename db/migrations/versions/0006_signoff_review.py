"""Sign-off: the written justification of a decision and the mark that the decision is
contrary to the objective DynoTRAIN verdict (validated while NOT VALIDATED, not validated
while VALIDATED, or validated on an in-sample verdict).

Columns are added with ``ALTER TABLE ... ADD COLUMN`` (not a batch copy) so that the
append-only triggers of ``signoff`` stay in place on SQLite.

Revision ID: 0006_signoff_review
Revises: 0003_workshops
"""
from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0006_signoff_review"
down_revision: str | Sequence[str] | None = "0003_workshops"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.add_column("signoff", sa.Column("justification", sa.Text(), nullable=False,
                                       server_default=""))
    op.add_column("signoff", sa.Column("contrary_to_objective", sa.Boolean(), nullable=False,
                                       server_default=sa.false()))


def downgrade() -> None:
    with op.batch_alter_table("signoff") as batch:
        batch.drop_column("contrary_to_objective")
        batch.drop_column("justification")
