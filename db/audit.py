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
    public_key_hex,
    sign,
    signoff_record_hash,
)
from railval.db import integrity, trust
from railval.db.models import AuditEvent, AuditHead, Signoff

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
    seq, prev = _next_seq(session)
    url = integrity.session_url(session)
    key, fp = integrity.signer_for(url)
    db_id, seq, prev = _identity_for(session, url, key, fp, seq, prev)
    row = {
        "seq": seq,
        "at_utc": utc_stamp(),
        "actor": actor_name,
        "action": str(action)[:60],
        "object": str(object)[:400],
        "before_sha256": _digest(before),
        "after_sha256": _digest(after),
        "reason": str(reason or ""),
        "detail": dict(detail or {}),
    }
    h, sig = _append(session, row, prev, key, fp)
    witness = trust.witness_file(db_id)
    pin = None if (url, db_id) in _pinned else {
        "fingerprint": fp, "public_key": public_key_hex(key.public_key()),
        "how": "first use: the key the server signed with"}
    session.info["railval_witness"] = (url, db_id, witness, pin, {
        "seq": row["seq"], "row_hash": h, "at_utc": row["at_utc"], "key_fingerprint": fp,
        "signature": sig, "database_id": db_id})
    return session.scalar(select(AuditEvent).where(AuditEvent.seq == int(seq)))


#: URL → database id, once committed; (URL, id) whose signer and pin were checked
_ids: dict[str, str] = {}
_pinned: set[tuple[str, str]] = set()
_checked: set[tuple[str, str, str]] = set()


def _forget() -> None:
    _ids.clear()
    _pinned.clear()
    _checked.clear()


integrity.FORGET_HOOKS.append(_forget)


def _next_seq(session: Session) -> tuple[int, str]:
    seq, prev = session.execute(
        update(AuditHead).where(AuditHead.id == 1).values(seq=AuditHead.seq + 1)
        .returning(AuditHead.seq, AuditHead.row_hash)
    ).one()
    return int(seq), str(prev)


def _append(session: Session, row: dict[str, Any], prev: str, key, fp: str) -> tuple[str, str]:
    """Insert ``row`` after ``prev``, signed; move the head's hash. → (row hash, signature)"""
    h = chain_hash(prev, row)
    sig = sign(key, "audit-head", head_message(row["seq"], h))
    session.execute(insert(AuditEvent).values(**row, prev_hash=prev, row_hash=h,
                                              signature=sig, key_fingerprint=fp))
    session.execute(update(AuditHead).where(AuditHead.id == 1).values(row_hash=h))
    return h, sig


def identity(session: Session) -> dict[str, Any] | None:
    """The detail of the trail's first ``database.identity`` row (with its ``seq``), or
    ``None`` when the trail names no identity."""
    got = session.execute(select(AuditEvent.seq, AuditEvent.detail)
                          .where(AuditEvent.action == trust.IDENTITY_ACTION)
                          .order_by(AuditEvent.seq).limit(1)).first()
    if got is None or not isinstance(got[1], dict) or "database_id" not in got[1]:
        return None
    return {**got[1], "seq": int(got[0])}


def _identity_for(session: Session, url: str, key, fp: str, seq: int,
                  prev: str) -> tuple[str, int, str]:
    """The database id; the first signed row of a database is its ``database.identity``
    row (written here, at ``seq``, when the trail has none). Refuses a signing key the
    trust anchor does not pin (:func:`railval.db.trust.check_signer`). → (id, seq, prev)
    of the row to write next."""
    db_id = _ids.get(url) or session.info.get("railval_db_id")
    if db_id is None:
        ident = identity(session)
        db_id = ident["database_id"] if ident else None
    if db_id is None:
        found = trust.find_anchor(url, None)  # a database met before (e.g. verified)
        db_id = found[1]["database_id"] if found else trust.new_database_id()
        if (url, db_id, fp) not in _checked:
            trust.check_signer(url, db_id, fp)
        unsigned = int(session.scalar(select(func.count()).select_from(AuditEvent)
                                      .where(AuditEvent.signature.is_(None))) or 0)
        row = {"seq": seq, "at_utc": utc_stamp(), "actor": "system",
               "action": trust.IDENTITY_ACTION, "object": f"database:{db_id}",
               "before_sha256": None, "after_sha256": None,
               "reason": "the database's identity (railval trust anchor)",
               "detail": {"database_id": db_id, "key_fingerprint": fp,
                          "public_key": public_key_hex(key.public_key()),
                          "unsigned_rows_before": unsigned}}
        prev, _sig = _append(session, row, prev, key, fp)
        seq, _ = _next_seq(session)
    session.info["railval_db_id"] = db_id
    if (url, db_id, fp) not in _checked:
        trust.check_signer(url, db_id, fp)
        _checked.add((url, db_id, fp))
    return db_id, seq, prev


@event.listens_for(Session, "after_commit")
def _witness_after_commit(session: Session) -> None:
    """Append the committed transaction's signed head to the witness file."""
    session.info.pop("railval_db_id", None)
    pending = session.info.pop("railval_witness", None)
    if pending is None:
        return
    url, db_id, witness, pin, line = pending
    if witness is not None:
        integrity.append_witness(witness, line)
    try:
        doc = trust.update_anchor(url, db_id, pin=pin, head=line)
    except (OSError, integrity.IntegrityError) as exc:
        import logging

        logging.getLogger("railval.db").error("trust anchor of database %s: cannot record "
                                              "signed head seq %s: %s", db_id, line["seq"], exc)
        return
    _ids[url] = db_id
    if doc.get("pins") or trust.deploy_pins() is not None:
        _pinned.add((url, db_id))


@event.listens_for(Session, "after_rollback")
def _witness_after_rollback(session: Session) -> None:
    session.info.pop("railval_witness", None)
    session.info.pop("railval_db_id", None)


def seal(session: Session, actor: Any, reason: str = "") -> AuditEvent:
    """Append a signed ``audit.seal`` row: it signs the head over every earlier row (those
    written before signing was enabled included) and is kept in the witness file. Its
    detail names the record hash of every unsigned sign-off, binding their decisions too."""
    unsigned = int(session.scalar(select(func.count()).select_from(AuditEvent)
                                  .where(AuditEvent.signature.is_(None))) or 0)
    legacy = {str(so.id): signoff_record_hash({k: getattr(so, k) for k in SIGNOFF_RECORD_FIELDS})
              for so in session.scalars(select(Signoff).where(Signoff.signature.is_(None))
                                        .order_by(Signoff.id))}
    return record(session, actor, "audit.seal", "audit:trail", None, None,
                  reason or "seal the current head",
                  detail={"unsigned_rows_before": unsigned, "unsigned_signoffs": legacy})


def key_rows(session: Session) -> list[dict[str, Any]]:
    """The ``database.identity`` and ``key.rotate`` rows (what names the signing keys)."""
    return [row_dict(ev) for ev in session.scalars(
        select(AuditEvent).where(AuditEvent.action.in_((trust.IDENTITY_ACTION,
                                                        trust.ROTATE_ACTION)))
        .order_by(AuditEvent.seq))]


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
