"""Alembic migration environment and revisions of the railval schema."""
