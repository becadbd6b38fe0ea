"""Alembic environment of railval: the target metadata is :data:`railval.db.models.Base.metadata`.

Runs programmatically from :meth:`railval.db.engine.Database.init`, which hands over an open
connection in ``config.attributes["connection"]``; from the ``alembic`` command line it
connects to ``sqlalchemy.url``. SQLite uses batch mode (table rebuilds for ALTER).
"""

from __future__ import annotations

from alembic import context
from sqlalchemy import create_engine

from railval.db.models import Base

config = context.config
target_metadata = Base.metadata


def _configure(connection) -> None:
    context.configure(
        connection=connection,
        target_metadata=target_metadata,
        render_as_batch=connection.dialect.name == "sqlite",
        compare_type=True,
    )
    with context.begin_transaction():
        context.run_migrations()


def run_migrations_offline() -> None:
    context.configure(
        url=config.get_main_option("sqlalchemy.url"),
        target_metadata=target_metadata,
        literal_binds=True,
        render_as_batch=True,
    )
    with context.begin_transaction():
        context.run_migrations()


def run_migrations_online() -> None:
    connection = config.attributes.get("connection")
    if connection is not None:
        _configure(connection)
        return
    engine = create_engine(config.get_main_option("sqlalchemy.url"))
    with engine.begin() as conn:
        _configure(conn)
    engine.dispose()


if context.is_offline_mode():
    run_migrations_offline()
else:
    run_migrations_online()
