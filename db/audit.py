"""The audit trail: the one write path that appends a hash-chained row (docs/audit.md).

Every change — import, stored configuration (simulate, calibrate), delete, user and role
changes, login failures, sign-offs, workshop actions and answers — calls :func:`record`
with the session that makes the change, so the audit row commits or rolls back with it.

Row ``i`` stores ``row_hash = SHA-256(prev_hash ‖ canonical JSON of the row)``
(:func:`railval.core.integrity.chain_hash`). Appenders are serialised by an UPDATE of the
one-row ``audit_head`` table (a row lock on PostgreSQL, the write lock on SQLite), and
``prev_hash`` is unique, so two writers can never fork the chain. The database refuses
UPDATE and DELETE on ``audit_event`` and ``signoff`` (triggers created by migration
``0002_users_audit``).

Each row is also **signed** (Ed25519, :mod:`railval.db.integrity`): its ``signature`` covers
``{seq, row_hash}`` — a signed head of the chain up to that row — so nobody without the
signing key can extend the chain or rewrite it. After the transaction commits, its last
signed head is appended to the **witness file** kept beside the key (outside the database):
a removed tail or a rewritten chain is found by comparing with it (docs/audit.md).
"""

from __future__ import annotations

import datetime as dt
import re
from collections.abc import Iterator
from typing import Any

from sqlalchemy import event, func, insert, select, update
from sqlalchemy.orm import Session

from railval.core.integrity import (
    GENESIS,
    SIGNOFF_RECORD_FIELDS,
    chain_hash,
    content_hash,
    head_message,
    sign,
    signoff_record_hash,
)
from railval.db import integrity
from railval.db.models import AuditEvent, AuditHead

__all__ = ["GENESIS", "actor_of", "head", "iter_rows", "record", "row_dict", "utc_stamp"]

_HEX64 = re.compile(r"^[0-9a-f]{64}$")


def utc_stamp(when: dt.datetime | None = None) -> str:
    """ISO 8601 UTC time with microseconds and a ``Z`` (the form stored in the trail)."""
    when = when or dt.datetime.now(dt.UTC)
    if when.tzinfo is None:
        when = when.replace(tzinfo=dt.UTC)
    return when.astimezone(dt.UTC).strftime("%Y-%m-%dT%H:%M:%S.%fZ")


def _digest(value: Any) -> str | None:
    """None stays None, a 64-hex string is taken as a hash, anything else is hashed."""
    if value is None:
        return None
    if isinstance(value, str) and _HEX64.match(value):
        return value
    return content_hash(value)


def _actor_name(actor: Any) -> str:
    name = getattr(actor, "username", actor)
    name = str(name or "").strip()
    if not name:
        raise ValueError("audit record needs an actor (user name, 'local' or 'system')")
    return name[:100]


def record(
    session: Session,
    actor: Any,
    action: str,
    object: str,
    before: Any = None,
    after: Any = None,
    reason: str = "",
    *,
    detail: dict[str, Any] | None = None,
) -> AuditEvent:
    """Append one audit row in ``session``'s transaction and return it.

    ``actor``: a user name or anything with ``.username`` (a
    :class:`railval.core.roles.Principal`). ``action``: dotted verb (``user.add``,
    ``configuration.store``, ``login.failed``…). ``object``: what was acted on
    (``campaign:NAME``, ``configuration:CAMPAIGN/NAME``, ``user:NAME``…). ``before`` /
    ``after``: the content before and after the change, as a SHA-256 hex string or any
    JSON document (hashed canonically); None when there is no such state. ``reason``: free
    text. ``detail``: small JSON facts kept in clear (e.g. the client address of a failed
    login); never secrets. The row is signed; its signed head goes to the witness file when
    the transaction commits — call this outside any savepoint that may roll back alone.
    """
    actor_name = _actor_name(actor)
    if not action or not object:
        raise ValueError("audit record needs an action and an object")
    # Take the head's lock first: every appender waits here for the one before it.
    seq, prev = session.execute(
        update(AuditHead).where(AuditHead.id == 1).values(seq=AuditHead.seq + 1)
        .returning(AuditHead.seq, AuditHead.row_hash)
    ).one()
    row = {
        "seq": int(seq),
        "at_utc": utc_stamp(),
        "actor": actor_name,
        "action": str(action)[:60],
        "object": str(object)[:400],
        "before_sha256": _digest(before),
        "after_sha256": _digest(after),
        "reason": str(reason or ""),
        "detail": dict(detail or {}),
    }
    h = chain_hash(prev, row)
    key, fp, witness = integrity.signer_for(integrity.session_url(session))
    sig = sign(key, "audit-head", head_message(row["seq"], h))
    session.execute(insert(AuditEvent).values(**row, prev_hash=prev, row_hash=h,
                                              signature=sig, key_fingerprint=fp))
    session.execute(update(AuditHead).where(AuditHead.id == 1).values(row_hash=h))
    if witness is not None:
        session.info["railval_witness"] = (witness, {
            "seq": row["seq"], "row_hash": h, "at_utc": row["at_utc"], "key_fingerprint": fp,
            "signature": sig})
    return session.scalar(select(AuditEvent).where(AuditEvent.seq == int(seq)))


@event.listens_for(Session, "after_commit")
def _witness_after_commit(session: Session) -> None:
    """Append the committed transaction's signed head to the witness file."""
    pending = session.info.pop("railval_witness", None)
    if pending is not None:
        integrity.append_witness(*pending)


@event.listens_for(Session, "after_rollback")
def _witness_after_rollback(session: Session) -> None:
    session.info.pop("railval_witness", None)


def seal(session: Session, actor: Any, reason: str = "") -> AuditEvent:
    """Append a signed ``audit.seal`` row: it signs the head over every earlier row (those
    written before signing was enabled included) and is kept in the witness file. Its
    detail names the record hash of every unsigned sign-off, binding their decisions too."""
    from railval.db.models import Signoff

    unsigned = int(session.scalar(select(func.count()).select_from(AuditEvent)
                                  .where(AuditEvent.signature.is_(None))) or 0)
    legacy = {str(so.id): signoff_record_hash({k: getattr(so, k) for k in SIGNOFF_RECORD_FIELDS})
              for so in session.scalars(select(Signoff).where(Signoff.signature.is_(None))
                                        .order_by(Signoff.id))}
    return record(session, actor, "audit.seal", "audit:trail", None, None,
                  reason or "seal the current head",
                  detail={"unsigned_rows_before": unsigned, "unsigned_signoffs": legacy})


def actor_of(session: Session) -> str:
    """The actor of the unit of work (``Database.session(actor=...)``), else ``system``."""
    return str(session.info.get("actor") or "system")


def head(session: Session) -> tuple[int, str]:
    """(number of rows, hash of the newest row) as recorded in ``audit_head``."""
    row = session.execute(select(AuditHead.seq, AuditHead.row_hash).where(AuditHead.id == 1)).one()
    return int(row[0]), str(row[1])


def row_dict(ev: AuditEvent) -> dict[str, Any]:
    """An audit row as the plain dict the chain and the bundle use."""
    return {
        "seq": ev.seq, "at_utc": ev.at_utc, "actor": ev.actor, "action": ev.action,
        "object": ev.object, "before_sha256": ev.before_sha256, "after_sha256": ev.after_sha256,
        "reason": ev.reason, "detail": dict(ev.detail or {}), "prev_hash": ev.prev_hash,
        "row_hash": ev.row_hash, "signature": ev.signature,
        "key_fingerprint": ev.key_fingerprint,
    }


def iter_rows(session: Session, *, batch: int = 2000, **filters: Any) -> Iterator[dict[str, Any]]:
    """Every audit row in ``seq`` order as dicts (read in batches of ``batch``).

    ``filters``: exact matches on ``actor``, ``action`` or ``object``; ``object_prefix``.
    """
    conds = []
    for key in ("actor", "action", "object"):
        if filters.get(key) is not None:
            conds.append(getattr(AuditEvent, key) == filters[key])
    if filters.get("object_prefix"):
        conds.append(AuditEvent.object.startswith(filters["object_prefix"], autoescape=True))
    last = 0
    while True:
        rows = list(session.scalars(
            select(AuditEvent).where(AuditEvent.seq > last, *conds)
            .order_by(AuditEvent.seq).limit(batch)
        ))
        if not rows:
            return
        for ev in rows:
            yield row_dict(ev)
        last = rows[-1].seq


def count_since(session: Session, action: str, since_utc: str, *, object: str | None = None,
                source: str | None = None) -> int:
    """Rows of ``action`` at or after ``since_utc`` (optionally for one object or source)."""
    conds = [AuditEvent.action == action, AuditEvent.at_utc >= since_utc]
    if object is not None:
        conds.append(AuditEvent.object == object)
    rows = session.execute(select(AuditEvent.detail).where(*conds)).scalars()
    if source is None:
        return sum(1 for _ in rows)
    return sum(1 for d in rows if (d or {}).get("source") == source)


def count(session: Session) -> int:
    return int(session.scalar(select(func.count()).select_from(AuditEvent)) or 0)


def newest_rows(session: Session, limit: int) -> tuple[list[dict[str, Any]], int]:
    """The ``limit`` newest audit rows, newest first, and the number of all rows: one
    ordered, limited query (a page shows the newest rows without reading the whole trail)."""
    rows = [row_dict(ev) for ev in session.scalars(
        select(AuditEvent).order_by(AuditEvent.seq.desc()).limit(max(0, int(limit))))]
    return rows, count(session)
