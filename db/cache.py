"""The result cache: sealed bytes under a key (:mod:`railval.db.integrity`), read and written
in bulk; a value whose seal fails is never returned (it is computed again).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence

from sqlalchemy import delete, or_, select
from sqlalchemy.orm import Session

from railval.db import integrity
from railval.db.models import ResultCache, utcnow

_log = logging.getLogger(__name__)

# -- result cache ------------------------------------------------------------------------
def cache_get(session: Session, key: str) -> bytes | None:
    """The cached bytes under ``key``, or ``None`` (also when the stored value fails its
    seal: :mod:`railval.db.integrity`)."""
    return cache_get_many(session, [key]).get(key)


def cache_get_many(session: Session, keys: list[str], chunk: int = 500) -> dict[str, bytes]:
    """``key → bytes`` of the keys present and authentic (one query per ``chunk`` keys).

    A value whose seal does not match (copied from another key, edited, or written without
    the server secret) is left out, so the caller computes it again; it is logged.
    """
    secret = integrity.session_secret(session)
    out: dict[str, bytes] = {}
    bad = 0
    for i in range(0, len(keys), chunk):
        part = list(keys[i:i + chunk])
        for k, v in session.execute(select(ResultCache.key, ResultCache.value)
                                    .where(ResultCache.key.in_(part))):
            payload = integrity.open_cache_value(secret, k, bytes(v))
            if payload is None:
                bad += 1
            else:
                out[k] = payload
    if bad:
        _log.warning("%d result-cache entries failed their seal and are recomputed", bad)
    return out


def cache_put(session: Session, key: str, value: bytes) -> None:
    """Insert or overwrite ``key`` (one atomic upsert on SQLite and PostgreSQL)."""
    cache_put_many(session, {key: value})


def cache_delete(session: Session, *, keys: Sequence[str] | None = None, prefix: str | None = None) -> int:
    """Delete the cached entries under ``keys`` and/or whose key starts with ``prefix``
    (e.g. ``"en14363:"``, every processed section); returns how many were deleted."""
    conditions = []
    if keys is not None:
        conditions.append(ResultCache.key.in_(list(keys)))
    if prefix is not None:
        conditions.append(ResultCache.key.startswith(prefix, autoescape=True))
    if not conditions:
        return 0
    return int(session.execute(delete(ResultCache).where(or_(*conditions))).rowcount or 0)


#: keys per bulk cache read (SQL IN list)
CACHE_CHUNK = 500


def cache_put_many(session: Session, items: Mapping[str, bytes]) -> None:
    """Insert or overwrite every ``key → value`` of ``items`` in one executemany upsert."""
    if not items:
        return
    dialect = session.get_bind().dialect.name
    if dialect == "postgresql":
        from sqlalchemy.dialects.postgresql import insert
    elif dialect == "sqlite":
        from sqlalchemy.dialects.sqlite import insert
    else:  # pragma: no cover - connect() only admits these two
        raise NotImplementedError(dialect)
    stmt = insert(ResultCache)
    stmt = stmt.on_conflict_do_update(
        index_elements=[ResultCache.key],
        set_={"value": stmt.excluded.value, "created_at": stmt.excluded.created_at},
    )
    now = utcnow()
    secret = integrity.session_secret(session)
    rows = [{"key": k, "value": integrity.seal_cache_value(secret, k, bytes(v)), "created_at": now}
            for k, v in items.items()]
    if dialect == "sqlite" and not session.get_bind().get_execution_options().get("railval_write"):
        # a read unit of work that caches what it computed: on SQLite its deferred
        # transaction cannot wait for another writer, and a cache entry is worth no error —
        # skip it (it is computed again next time)
        from sqlalchemy.exc import OperationalError

        try:
            session.connection().execute(stmt, rows)
        except OperationalError as exc:
            if "locked" not in str(exc.orig) and "busy" not in str(exc.orig):
                raise
            _log.info("result cache not written (database busy): %d entries", len(rows))
        return
    session.connection().execute(stmt, rows)
