"""Configuration.calibration: which sections a calibrated configuration was fitted to (and
which were held out), so that a verdict on fitted sections is flagged in-sample.

Revision ID: 0004_calibration_sections
Revises: 0002_users_audit
Create Date: 2026-11-23 12:00:00

"""
from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

# revision identifiers, used by Alembic.
revision: str = '0004_calibration_sections'
down_revision: str | Sequence[str] | None = '0002_users_audit'
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    """Upgrade schema."""
    with op.batch_alter_table('configuration') as batch:
        batch.add_column(sa.Column('calibration', sa.JSON(), nullable=True))


def downgrade() -> None:
    """Downgrade schema."""
    with op.batch_alter_table('configuration') as batch:
        batch.drop_column('calibration')
