"""Canonical JSON, the audit hash chain and the evidence hash (docs/audit.md).

Pure functions shared by the database side (:mod:`railval.db.audit`,
:mod:`railval.db.signoff`) and the offline verification of an exported bundle, so that both
compute the very same bytes.

* **Canonical JSON** (:func:`canonical_json`): keys sorted, no insignificant white space,
  UTF-8, no NaN/Infinity — the same document always gives the same bytes (the rules of
  RFC 8785 §3.2 for the documents railval writes: strings, integers, finite floats printed by
  Python's shortest round-trip ``repr``, lists and objects).
* **Hash chain** (:func:`chain_hash`): ``h_i = SHA-256(h_{i−1} ‖ canonical JSON of row i)``
  where ``h_{i−1}`` enters as its 64 lower-case hexadecimal ASCII characters and
  ``h_0`` = :data:`GENESIS` (64 zeros). Changing, removing or re-ordering any row changes
  every later hash; cutting the tail is caught by comparing with a checkpoint kept elsewhere
  (Schneier & Kelsey, "Secure audit logs to support computer forensics", ACM TISSEC 2(2),
  1999 — the hash-chain construction).
* **Evidence hash** (:func:`evidence_hash`): SHA-256 of the canonical JSON of an evidence
  manifest (21 CFR 11.70: the signature is linked to its record so that it cannot be moved
  to other evidence).
* **Signatures** (:func:`sign`, :func:`verify_signature`): Ed25519 (RFC 8032) through the
  ``cryptography`` package over a domain-separated message ``b"railval/<kind>/1\\0" ‖
  canonical JSON``. Three kinds: a sign-off's canonical record (:func:`signoff_record`), an
  audit row's signed head ``{seq, row_hash}`` (:func:`head_message`) — the signed tree head
  of Certificate Transparency (RFC 9162 §4.10) reduced to a hash chain — and a key
  rotation's countersignature by the new key (:func:`rotation_message`); nothing else.
  The public key alone verifies, offline; its fingerprint is the SHA-256 of the raw 32-byte
  public key in hex (:func:`key_fingerprint`).
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

GENESIS = "0" * 64

#: the fields of an audit row that enter its hash, in no particular order (keys are sorted)
CHAIN_FIELDS = ("seq", "at_utc", "actor", "action", "object", "before_sha256",
                "after_sha256", "reason", "detail")


def _check_finite(obj: Any, path: str = "$") -> None:
    if isinstance(obj, float) and not math.isfinite(obj):
        raise ValueError(f"{path}: {obj!r} has no canonical JSON form")
    if isinstance(obj, Mapping):
        for k, v in obj.items():
            if not isinstance(k, str):
                raise ValueError(f"{path}: key {k!r} is not a string")
            _check_finite(v, f"{path}.{k}")
    elif isinstance(obj, list | tuple):
        for i, v in enumerate(obj):
            _check_finite(v, f"{path}[{i}]")


def canonical_json(obj: Any) -> bytes:
    """The canonical UTF-8 bytes of a JSON document (sorted keys, compact, finite numbers)."""
    _check_finite(obj)
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), ensure_ascii=False,
                      allow_nan=False).encode("utf-8")


def sha256_hex(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def content_hash(obj: Any) -> str:
    """SHA-256 of the canonical JSON of ``obj`` (the before/after hashes of audit rows)."""
    return sha256_hex(canonical_json(obj))


def chain_payload(row: Mapping[str, Any]) -> dict[str, Any]:
    """The part of an audit row that its hash covers (:data:`CHAIN_FIELDS`)."""
    return {k: row.get(k) for k in CHAIN_FIELDS}


def chain_hash(prev_hash: str, row: Mapping[str, Any]) -> str:
    """``SHA-256(prev_hash ‖ canonical JSON of the row)`` with ``prev_hash`` as hex ASCII."""
    if len(prev_hash) != 64:
        raise ValueError(f"previous hash {prev_hash!r} is not 64 hexadecimal characters")
    return sha256_hex(prev_hash.encode("ascii") + canonical_json(chain_payload(row)))


@dataclass(frozen=True)
class ChainBreak:
    """The first place where a chain does not hold."""

    seq: int | None
    object: str
    field: str
    expected: str
    found: str

    def __str__(self) -> str:
        where = f"row seq {self.seq}" if self.seq is not None else "end of chain"
        return (f"{where} (object {self.object!r}): {self.field} expected {self.expected}, "
                f"found {self.found}")


def verify_chain(rows: Iterable[Mapping[str, Any]]) -> tuple[int, str, ChainBreak | None]:
    """Recompute the chain over ``rows`` (in ``seq`` order) → (rows checked, head, first break).

    Each row needs :data:`CHAIN_FIELDS` plus ``prev_hash`` and ``row_hash``. A break is
    reported when a row's ``prev_hash`` is not the previous row's hash (a row removed or
    inserted before it), when its ``row_hash`` differs from the recomputed hash (a field
    changed), or when ``seq`` does not increase by one.
    """
    prev = GENESIS
    expected_seq = 1
    n = 0
    for row in rows:
        seq = int(row["seq"])
        obj = str(row.get("object", ""))
        if seq != expected_seq:
            return n, prev, ChainBreak(seq, obj, "seq", str(expected_seq), str(seq))
        if row["prev_hash"] != prev:
            return n, prev, ChainBreak(seq, obj, "prev_hash", prev, str(row["prev_hash"]))
        h = chain_hash(prev, row)
        if h != row["row_hash"]:
            return n, prev, ChainBreak(seq, obj, "row_hash", h, str(row["row_hash"]))
        prev = h
        expected_seq += 1
        n += 1
    return n, prev, None


def check_checkpoint(rows_by_seq: Mapping[int, str], head_seq: int,
                     checkpoint: Mapping[str, Any]) -> ChainBreak | None:
    """Compare a checkpoint ``{seq, row_hash}`` with the chain (``seq → row_hash``).

    The chain must still hold row ``seq`` with the same hash; a shorter chain means its tail
    was cut, another hash means history was rewritten.
    """
    seq = int(checkpoint["seq"])
    want = str(checkpoint["row_hash"])
    if seq == 0:
        return None
    if seq > head_seq:
        return ChainBreak(None, "", "length",
                          f"at least {seq} rows (checkpoint {want[:16]}…)",
                          f"{head_seq} rows: the tail after row {head_seq} was removed")
    found = rows_by_seq.get(seq)
    if found != want:
        return ChainBreak(seq, "", "row_hash (checkpoint)", want, str(found))
    return None


#: the fields of a sign-off that its signature covers (21 CFR 11.50, 11.70)
SIGNOFF_RECORD_FIELDS = ("id", "campaign", "configuration", "username", "printed_name",
                         "signed_at_utc", "meaning", "decision", "restrictions", "statement",
                         "justification", "contrary_to_objective", "evidence_sha256",
                         "software_version")


def signoff_record(signoff: Mapping[str, Any]) -> dict[str, Any]:
    """The canonical record of a sign-off that its signature covers.

    ``contrary_to_objective`` enters as a JSON boolean, ``justification`` as text ("" when
    absent) so that a database's 0/1 and ``NULL`` read the same everywhere.
    """
    rec = {k: signoff.get(k) for k in SIGNOFF_RECORD_FIELDS}
    rec["id"] = int(rec["id"])
    rec["contrary_to_objective"] = bool(rec["contrary_to_objective"])
    rec["justification"] = rec["justification"] or ""
    rec["restrictions"] = rec["restrictions"] or ""
    rec["statement"] = rec["statement"] or ""
    return {"format": "railval-signoff/1", **rec}


def signoff_record_hash(signoff: Mapping[str, Any]) -> str:
    """SHA-256 of the canonical JSON of :func:`signoff_record` (kept in the audit row)."""
    return content_hash(signoff_record(signoff))


def head_message(seq: int, row_hash: str) -> dict[str, Any]:
    """What the signature of an audit row (a signed head of the chain) covers."""
    return {"format": "railval-audit-head/1", "seq": int(seq), "row_hash": str(row_hash)}


def rotation_message(old_fingerprint: str, new_fingerprint: str) -> dict[str, Any]:
    """What the *new* key signs in a ``key.rotate`` audit row (the row itself is signed by
    the old key): with both signatures the hand-over is trusted from either end."""
    return {"format": "railval-key-rotation/1", "old_fingerprint": str(old_fingerprint),
            "new_fingerprint": str(new_fingerprint)}


def _message(kind: str, doc: Any) -> bytes:
    return b"railval/" + kind.encode("ascii") + b"/1\0" + canonical_json(doc)


def key_fingerprint(public_key: Any) -> str:
    """SHA-256 (hex) of the raw 32-byte Ed25519 public key."""
    from cryptography.hazmat.primitives import serialization

    raw = public_key.public_bytes(serialization.Encoding.Raw, serialization.PublicFormat.Raw)
    return sha256_hex(raw)


def public_key_from_hex(text: str) -> Any:
    """An Ed25519 public key from its 64 hexadecimal characters (raw 32 bytes)."""
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey

    text = str(text).strip().lower()
    try:
        raw = bytes.fromhex(text)
    except ValueError:
        raise ValueError(f"public key {text[:20]!r}…: not hexadecimal") from None
    if len(raw) != 32:
        raise ValueError(f"public key: {len(raw)} bytes, an Ed25519 public key has 32")
    return Ed25519PublicKey.from_public_bytes(raw)


def public_key_hex(public_key: Any) -> str:
    from cryptography.hazmat.primitives import serialization

    return public_key.public_bytes(serialization.Encoding.Raw,
                                   serialization.PublicFormat.Raw).hex()


def sign(private_key: Any, kind: str, doc: Any) -> str:
    """Hex Ed25519 signature of ``doc`` of ``kind`` (``signoff`` or ``audit-head``)."""
    return private_key.sign(_message(kind, doc)).hex()


def verify_signature(public_key: Any, kind: str, doc: Any, signature: str | None) -> bool:
    """True when ``signature`` (hex) is ``public_key``'s signature of ``doc`` of ``kind``."""
    from cryptography.exceptions import InvalidSignature

    if not signature:
        return False
    try:
        public_key.verify(bytes.fromhex(str(signature)), _message(kind, doc))
    except (InvalidSignature, ValueError):
        return False
    return True


def evidence_hash(manifest: Mapping[str, Any]) -> str:
    """SHA-256 of the canonical JSON of an evidence manifest (21 CFR 11.70)."""
    return content_hash(dict(manifest))


# -- the keys a verification trusts --------------------------------------------------------
IDENTITY_ACTION = "database.identity"
ROTATE_ACTION = "key.rotate"
_INF = float("inf")


class KeyRing(dict):
    """fingerprint → public key of the keys a verification trusts, with the window of
    audit rows (``seq`` from, to) each may sign and where the trust came from."""

    def __init__(self, keys: dict[str, Any] | None = None, source: str = ""):
        super().__init__(keys or {})
        self.windows: dict[str, list[float]] = {fp: [1, _INF] for fp in self}
        self.how: dict[str, str] = {fp: source for fp in self}
        self.source = source

    def at(self, fp: Any, seq: int | None) -> Any:
        """The public key of ``fp`` when it may sign row ``seq`` (any row: ``None``)."""
        pk = self.get(str(fp))
        if pk is None or seq is None:
            return pk
        lo, hi = self.windows[str(fp)]
        return pk if lo <= seq <= hi else None

    def why(self, fp: Any, seq: int | None) -> str:
        """Why ``fp`` does not verify row ``seq`` (the text of a finding)."""
        fp = str(fp)
        if fp in self and seq is not None:
            lo, hi = self.windows[fp]
            return (f"key {fp[:16]}… is trusted for rows {int(lo)}–"
                    f"{'' if hi == _INF else int(hi)} only (a key rotation row retired it)")
        return f"key {fp[:16]}…: signed by a key that is not trusted"

    def describe(self) -> list[dict[str, Any]]:
        return [{"fingerprint": fp, "source": self.how.get(fp, ""),
                 "rows_from": int(self.windows[fp][0]),
                 "rows_to": None if self.windows[fp][1] == _INF else int(self.windows[fp][1])}
                for fp in self]


def _rotation_keys(detail: dict[str, Any]) -> tuple[str, Any, str, Any] | None:
    """(old fingerprint, old key, new fingerprint, new key) of a ``key.rotate`` row."""
    try:
        old = public_key_from_hex(str(detail["old_public_key"]))
        new = public_key_from_hex(str(detail["new_public_key"]))
    except (KeyError, ValueError, TypeError):
        return None
    return key_fingerprint(old), old, key_fingerprint(new), new


def _rotate_once(ring: KeyRing, r: dict[str, Any]) -> bool:
    """Apply one ``key.rotate`` row: forward when its old key (trusted at that row) signed
    it — the new key is trusted after it, the old one retired; backward when its new key
    (trusted) countersigned it — the old key is trusted for the rows up to it."""
    keys = _rotation_keys(r.get("detail") or {})
    if keys is None:
        return False
    ofp, opk, nfp, npk = keys
    seq, changed = int(r["seq"]), False
    if (ring.at(ofp, seq) is not None and str(r.get("key_fingerprint")) == ofp
            and verify_signature(opk, "audit-head", head_message(seq, r["row_hash"]),
                                 r.get("signature"))):
        if ring.windows[ofp][1] > seq:
            ring.windows[ofp][1], changed = seq, True
        if nfp not in ring:
            ring[nfp], ring.windows[nfp] = npk, [seq + 1, _INF]
            ring.how[nfp] = f"key.rotate row {seq}, signed by trusted key {ofp[:16]}…"
            changed = True
    if nfp in ring and ring.windows[nfp][1] > seq and verify_signature(
            npk, "key-rotation", rotation_message(ofp, nfp), (r.get("detail") or {})
            .get("new_key_signature")):
        if ring.windows[nfp][0] < seq + 1:
            ring.windows[nfp][0], changed = seq + 1, True
        if ofp not in ring:
            ring[ofp], ring.windows[ofp] = opk, [1, seq]
            ring.how[ofp] = f"key.rotate row {seq}, countersigned by trusted key {nfp[:16]}…"
            changed = True
    return changed


def apply_rotations(ring: KeyRing, rows: dict[int, dict[str, Any]]) -> KeyRing:
    """Extend ``ring`` through the trail's authentic ``key.rotate`` rows (to a fixed
    point: each pass only adds a key or narrows a window)."""
    rotations = [rows[s] for s in sorted(rows) if rows[s]["action"] == ROTATE_ACTION]
    for _ in range(2 * len(rotations) + 1):
        if not any([_rotate_once(ring, r) for r in rotations]):
            break
    return ring


def known_public_keys(rows: dict[int, dict[str, Any]]) -> dict[str, Any]:
    """fingerprint → public key named by the trail (identity and rotation rows): what a
    ``--trust-fingerprint`` is matched against."""
    out: dict[str, Any] = {}
    for r in rows.values():
        d = r.get("detail") or {}
        for k in ("public_key", "old_public_key", "new_public_key"):
            if r["action"] in (IDENTITY_ACTION, ROTATE_ACTION) and d.get(k):
                try:
                    pk = public_key_from_hex(str(d[k]))
                except ValueError:
                    continue
                out[key_fingerprint(pk)] = pk
    return out
