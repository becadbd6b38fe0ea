"""Sessions the server can end: the table ``app_session`` (docs/security.md, "Sessions").

Before this revision the session cookie held ``user|issued-at`` under an HMAC: a copy of it
stayed valid until it expired (8 h), whatever the user did, because nothing on the server
knew the session. Now the cookie holds a random session id; its SHA-256 is a row of
``app_session`` (user, created, expires, ended, why). Sign-out ends the row; disabling a
user, changing their password or their roles ends all their open rows. Every request reads
the row by its unique hash (one indexed read). Sessions issued before this revision are not
in the table: their users sign in again.

Revision ID: 0010_sessions
Revises: 0009_signal_evidence_index
"""
from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0010_sessions"
down_revision: str | Sequence[str] | None = "0009_signal_evidence_index"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "app_session",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("id_sha256", sa.String(length=64), nullable=False),
        sa.Column("user_id", sa.Integer(), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("expires_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("ended_at", sa.DateTime(timezone=True), nullable=True),
        sa.Column("end_reason", sa.String(length=40), nullable=False),
        sa.ForeignKeyConstraint(["user_id"], ["app_user.id"], ondelete="CASCADE"),
        sa.PrimaryKeyConstraint("id"),
        sa.UniqueConstraint("id_sha256"),
    )
    op.create_index("ix_app_session_user", "app_session", ["user_id"], unique=False)


def downgrade() -> None:
    op.drop_index("ix_app_session_user", table_name="app_session")
    op.drop_table("app_session")
