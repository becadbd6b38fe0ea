"""Opening the database a request names, and who acts on it (docs/database.md).

The CLI's verbs and ``railval serve`` call these instead of :mod:`railval.db.engine`
(docs/design.md §2: services are the only door to the database).
"""

from __future__ import annotations

from typing import Any

from sqlalchemy import inspect

from railval.core import lazy
from railval.db import engine

#: deferred (railval.core.lazy): backup and restore (the ORM models) only for those verbs;
#: every verb that opens a database loads this module
write_backup = lazy.function("railval.db.backup", "backup")
read_backup = lazy.function("railval.db.backup", "restore")


def open_database(url: str | None, *, upgrade: bool | None = False):
    """The :class:`railval.db.engine.Database` at ``url`` (else ``$RAILVAL_DB``, else the
    embedded SQLite file). ``upgrade=True`` migrates an empty or older schema, ``False``
    refuses it (:class:`railval.db.engine.DatabaseNotInitialised`), ``None`` checks nothing."""
    database = engine.connect(url)
    if upgrade is not None:
        database.ensure_initialised(upgrade=upgrade)
    return database


def initialise(url: str | None) -> dict[str, Any]:
    """Create or upgrade the schema → ``{database, revision, previous_revision}``."""
    database = engine.connect(url)
    try:
        before = database.current_revision()
        head = database.init()
        return {"database": database.safe_url, "revision": head, "previous_revision": before}
    finally:
        database.dispose()


def set_default_actor(name: str) -> None:
    """Who the audit trail names for databases opened from now on (the CLI's acting user)."""
    engine.default_actor = name


def default_actor() -> str:
    """The acting user set by :func:`set_default_actor` (``"system"`` by default)."""
    return engine.default_actor


def has_user_table(database) -> bool:
    """True when the schema holds the user table (a database migrated far enough)."""
    return "app_user" in inspect(database.engine).get_table_names()


def backup(url: str | None, folder: str) -> dict[str, Any]:
    """Back the database at ``url`` up into ``folder`` (:func:`railval.db.backup.backup`)."""

    database = engine.connect(url)
    try:
        return write_backup(database, folder, actor=engine.default_actor)
    finally:
        database.dispose()


def restore(url: str | None, folder: str) -> dict[str, Any]:
    """Restore the backup in ``folder`` into the empty database at ``url``
    (:func:`railval.db.backup.restore`)."""

    database = engine.connect(url)
    try:
        return read_backup(database, folder, actor=engine.default_actor)
    finally:
        database.dispose()
