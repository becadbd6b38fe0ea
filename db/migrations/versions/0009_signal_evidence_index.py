"""SQLite: a covering index of the signal rows' evidence — (recording, channel, content hash,
provenance) — so that a validation reads the content hashes and seals of its signals
without walking the blobs.

On SQLite a row's columns are stored in order and ``signal.sha256`` and
``signal.provenance`` (which holds the seal) come after the blob: reading them from the table
follows the blob's whole overflow chain (≈ 34 pages of 4 KiB for a 20 000-sample signal).
Read from this index they cost an index entry each (docs/validation.md, Throughput: the
first, one-core part of a new configuration's validation, ≈ 4 → ≈ 2 ms). PostgreSQL stores
large values apart from the row (TOAST) and has no b-tree on ``json``: nothing to do there.
The index is not in :mod:`railval.db.models` (it exists on one backend only); the model
comparison of the tests knows it by name.

Revision ID: 0009_signal_evidence_index
Revises: 0008_panelists
"""
from collections.abc import Sequence

from alembic import op

revision: str = "0009_signal_evidence_index"
down_revision: str | Sequence[str] | None = "0008_panelists"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

#: the index's name (``railval.db.models.SQLITE_ONLY_INDEXES`` lists it)
NAME = "ix_signal_evidence"


def upgrade() -> None:
    if op.get_bind().dialect.name == "sqlite":
        op.execute(f"CREATE INDEX IF NOT EXISTS {NAME} "
                   "ON signal (recording_id, channel_id, sha256, provenance)")


def downgrade() -> None:
    if op.get_bind().dialect.name == "sqlite":
        op.execute(f"DROP INDEX IF EXISTS {NAME}")
