"""Signatures: Ed25519 signatures of audit rows (signed heads) and of sign-off records.

``audit_event.signature`` / ``key_fingerprint``: the signature of ``{seq, row_hash}`` and the
SHA-256 of the public key that made it. ``signoff.signature`` / ``key_fingerprint`` /
``record_sha256``: the signature of the sign-off's canonical record and that record's
SHA-256 (also in its ``signoff.create`` audit row). Rows written before this revision keep
NULL: ``railval audit verify`` reports them as written before signing was enabled
(docs/audit.md, "Signatures").

Columns are added with ``ALTER TABLE ... ADD COLUMN`` (not a batch copy) so that the
append-only triggers of ``signoff`` and ``audit_event`` stay in place on SQLite.

Revision ID: 0007_signatures
Revises: 0006_signoff_review
"""
from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0007_signatures"
down_revision: str | Sequence[str] | None = "0006_signoff_review"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    for table in ("audit_event", "signoff"):
        op.add_column(table, sa.Column("signature", sa.String(128), nullable=True))
        op.add_column(table, sa.Column("key_fingerprint", sa.String(64), nullable=True))
    op.add_column("signoff", sa.Column("record_sha256", sa.String(64), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("signoff") as batch:
        batch.drop_column("record_sha256")
        batch.drop_column("key_fingerprint")
        batch.drop_column("signature")
    with op.batch_alter_table("audit_event") as batch:
        batch.drop_column("key_fingerprint")
        batch.drop_column("signature")
