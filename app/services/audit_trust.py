"""Trust of ``railval audit verify``: which public keys verify, and from where
(docs/audit.md, "Trust anchor"; :mod:`railval.db.trust`).

* the assessor's own: ``--public-key``, ``--trust-fingerprint`` (then nothing is written:
  no key, no secret, no anchor, no witness);
* else the server's: ``$RAILVAL_TRUST_ANCHOR_FILE`` (deploy secret), else the pins of the
  database's anchor in the server's configuration directory, else — first use — the key the
  server signs with, pinned once the trail verifies (and said so);
* extended by the trail's ``key.rotate`` rows (:func:`railval.core.integrity.apply_rotations`).

Also the witness of a database (found by its identity, not the spelling of its URL), the
public key as published (``railval audit key``) and the key rotation
(``railval audit rotate-key``).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from railval.app.services.audit_checks import (
    Finding,
    KeyRing,
    VerifyReport,
    _check_chain,
    _check_row_signatures,
    _check_witness,
    apply_rotations,
    check_anchor,
    known_public_keys,
    witness_signed_from,
)
from railval.core import lazy
from railval.core.errors import RailvalError
from railval.core.integrity import (
    key_fingerprint,
    public_key_from_hex,
    public_key_hex,
    rotation_message,
    sign,
)
from railval.db import audit, integrity, trust

#: deferred (railval.core.lazy): the key classes only for a key rotation
serialization = lazy.module("cryptography.hazmat.primitives.serialization")
ed25519 = lazy.module("cryptography.hazmat.primitives.asymmetric.ed25519")


def _parse_public_keys(public_key: str) -> dict[str, Any]:
    """fingerprint → key of ``--public-key``: hex, or a file holding hex or the JSON of
    `railval audit key --json` (its current key only: older keys are trusted through the
    trail's key rotation rows)."""
    p = Path(public_key)
    text = p.read_text(encoding="utf-8") if p.is_file() else public_key
    hexes = [text]
    try:
        doc = json.loads(text)
        if isinstance(doc, dict):
            hexes = [doc["public_key"]]
    except (ValueError, KeyError):
        pass
    keys = {}
    for h in hexes:
        try:
            pk = public_key_from_hex(str(h).strip())
        except ValueError as exc:
            raise RailvalError(f"--public-key {public_key[:60]}: {exc}") from None
        keys[key_fingerprint(pk)] = pk
    return keys


def trusted_keys(database, public_key: str | None = None) -> dict[str, Any]:
    """fingerprint → public key: ``public_key`` (hex, or a file holding it) when given,
    else the keys pinned for ``database`` (:mod:`railval.db.trust`)."""
    if public_key:
        return _parse_public_keys(public_key)
    with database.session() as s:
        rows = _key_rows(s)
    ring, _how, _found = trust.server_ring(database.url, rows)
    return dict(apply_rotations(ring, rows))


def _fingerprints(values: list[str] | None) -> list[str]:
    out = []
    for v in values or []:
        fp = str(v).strip().lower()
        if len(fp) != 64 or any(c not in "0123456789abcdef" for c in fp):
            raise RailvalError(f"--trust-fingerprint {v[:40]!r}: not a SHA-256 key fingerprint "
                               "(64 hexadecimal characters, `railval audit key`)")
        out.append(fp)
    return out


def _key_rows(session) -> dict[int, dict[str, Any]]:
    return {int(r["seq"]): r for r in audit.key_rows(session)}


def explicit_ring(public_key: str | None, fingerprints: list[str],
                  known: dict[str, Any], report: VerifyReport, where: str) -> KeyRing:
    """The key ring an assessor names: the keys of ``--public-key`` (a hex key or a key file)
    and, for each ``--trust-fingerprint``, the key of that fingerprint in ``known``; a
    fingerprint found nowhere is a finding (``where``: the places ``known`` came from). The one
    home of this rule for a live database (:func:`_resolve_trust`) and an exported bundle
    (:func:`bundle_ring`)."""
    ring = KeyRing(_parse_public_keys(public_key) if public_key else {},
                   "--public-key" if public_key else "")
    for fp in fingerprints:
        if fp in known and fp not in ring:
            ring[fp], ring.windows[fp] = known[fp], [1, float("inf")]
            ring.how[fp] = "--trust-fingerprint"
    missing = [fp for fp in fingerprints if fp not in ring]
    if missing:
        report.findings.append(Finding(
            "signature", "--trust-fingerprint " + ", ".join(f[:16] + "…" for f in missing),
            f"a public key with this fingerprint ({where})", "none"))
    return ring


def _resolve_trust(database, rows: dict[int, dict[str, Any]], report: VerifyReport,
                   public_key: str | None, fingerprints: list[str]
                   ) -> tuple[KeyRing, tuple[Path, dict[str, Any]] | None, bool]:
    """(ring with the trail's rotations applied, the anchor found, assessor mode)."""
    explicit = bool(public_key or fingerprints)
    ring, how, found = trust.server_ring(database.url, rows)
    if explicit:
        known = known_public_keys(rows)
        current = integrity.current_public_key(database.url)
        if current is not None:
            known.setdefault(key_fingerprint(current), current)
        ring = explicit_ring(public_key, fingerprints, known, report,
                             "in the trail's identity or key rotation rows, or the server's "
                             "key file")
    elif how == "first use" and rows:
        report.notes.append(
            f"trust on first use: no pin for this database existed in {trust.trust_dir()}; "
            f"the server's key {next(iter(ring))} is trusted now and pinned if the trail "
            "verifies")
    apply_rotations(ring, rows)
    return ring, found, explicit


def bundle_ring(root: Path, rows: dict[int, dict[str, Any]], public_key: str | None,
                fps: list[str], report: VerifyReport) -> KeyRing:
    """The keys an exported audit bundle ``root`` is verified with: the assessor's
    (:func:`explicit_ring`, the fingerprints looked up in the trail's rows), else the bundle's
    own ``key.json`` with a note to compare its fingerprint; the trail's rotations applied."""
    if public_key or fps:
        ring = explicit_ring(public_key, fps, known_public_keys(rows), report,
                             "in the trail's identity or key rotation rows")
    else:
        ring = KeyRing(_parse_public_keys(str(root / "key.json")), "the bundle's key.json")
        report.notes.append(f"trusting the public key in the bundle (fingerprint "
                            f"{', '.join(ring)}); compare with the fingerprint the "
                            "server's owner published (`railval audit key`), or pass "
                            "--public-key / --trust-fingerprint")
    return apply_rotations(ring, rows)


def _witness_for(database, rows, found, witness: str | None):
    """(witness file path or None, its lines or None) of the database."""
    if witness:
        return Path(witness)
    ident = next((r["detail"] for _, r in sorted(rows.items())
                  if r["action"] == trust.IDENTITY_ACTION), None) or {}
    db_id = ident.get("database_id") or (found[1]["database_id"] if found else None)
    return trust.witness_file(db_id)


def _witness_lines(path: Path | None, report: VerifyReport, quiet: bool = False
                   ) -> list[dict[str, Any]] | None:
    if path is None or not path.is_file():
        if not quiet:
            report.notes.append(
                f"no witness file ({path or 'none recorded for this database'}): a removed "
                "tail is found only with a checkpoint (`--checkpoint`)")
        return None
    try:
        return integrity.read_witness(path)
    except integrity.IntegrityError as exc:
        report.findings.append(Finding("witness", str(path), "signed heads, one per line",
                                       str(exc)))
        return None


def _check_trail(database, s, report: VerifyReport, checkpoint, *, witness, use_witness,
                 public_key, fingerprints) -> tuple[dict[int, dict[str, Any]], KeyRing, bool]:
    """Chain, checkpoint, trust, signatures, witness and anchor, head of one database."""
    rows: dict[int, dict[str, Any]] = {}

    def collect():
        for r in audit.iter_rows(s):
            rows[int(r["seq"])] = r
            yield r

    by_seq = _check_chain(collect(), report, checkpoint)
    ring, found, explicit = _resolve_trust(database, rows, report, public_key, fingerprints)
    report.keys, report.trust = list(ring), ring.describe()
    if not ring and rows:
        report.findings.append(Finding(
            "signature", "signing key", "the public key to verify with (a pin in "
            f"{trust.trust_dir()}, the server's key file "
            f"{integrity.signing_key_path(database.url)}, or --public-key HEX|FILE)", "none"))
    lines = None
    if use_witness:
        wpath = _witness_for(database, rows, found, witness)
        hw = found is not None and bool(found[1].get("witnessed"))
        lines = _witness_lines(wpath, report, quiet=hw or not rows)
        if hw:
            check_anchor(by_seq, lines, found[1], str(found[0]), report)
    good = _check_row_signatures(rows, ring, report, witness_signed_from(lines, ring))
    if lines is not None:
        _check_witness(by_seq, lines, str(wpath), ring, report, rows, good)
    head_seq, head_hash = audit.head(s)
    if not report.findings and (head_seq, head_hash) != (report.head_seq, report.head_hash):
        report.findings.append(Finding(
            "head", "audit_head", f"seq {report.head_seq} hash {report.head_hash}",
            f"seq {head_seq} hash {head_hash} (rows after {report.head_seq} removed?)"))
    return rows, ring, explicit


def _pin_first_use(database, rows, ring: KeyRing, report: VerifyReport) -> None:
    """Trust on first use: the server's key and the verified head go into a new anchor."""
    if not rows or not report.ok or not ring or ring.source != "first use":
        return
    ident = next((r["detail"] for _, r in sorted(rows.items())
                  if r["action"] == trust.IDENTITY_ACTION), None) or {}
    db_id = ident.get("database_id") or trust.new_database_id()
    fp, pk = next(iter(ring.items()))
    top = rows[max(rows)]
    head = {k: top.get(k) for k in ("seq", "row_hash", "at_utc", "key_fingerprint",
                                    "signature")}
    wpath = trust.witness_file(db_id)
    if top.get("signature") and wpath is not None:
        integrity.append_witness(wpath, {**head, "database_id": db_id})
    doc = trust.update_anchor(
        database.url, db_id,
        pin={"fingerprint": fp, "public_key": public_key_hex(pk),
             "how": "first use: railval audit verify"},
        head=head if top.get("signature") else None)
    report.notes.append(f"pinned key {fp} for database {doc['database_id']} in "
                        f"{trust.anchor_file(doc['database_id'])} (trust on first use)")


def key_info(database) -> dict[str, Any]:
    """The trusted public signing key (the pinned key, or the one a trusted key rotated to),
    its fingerprint, where the trust comes from, the key, anchor and witness files, and the
    keys it retired (``audit key``, the bundle's ``key.json``)."""
    with database.session() as s:
        rows = _key_rows(s)
    ring, how, found = trust.server_ring(database.url, rows)
    if how == "none":
        integrity.signing_key(database.url)  # the server makes its key on first use
        ring, how, found = trust.server_ring(database.url, rows)
    apply_rotations(ring, rows)
    current = [fp for fp in ring if ring.windows[fp][1] == float("inf")] or list(ring)
    fp = current[-1]
    file_pk = integrity.current_public_key(database.url)
    retired = [f for f in ring if f != fp]
    ident = next((r["detail"] for _, r in sorted(rows.items())
                  if r["action"] == trust.IDENTITY_ACTION), None) or {}
    db_id = ident.get("database_id") or (found[1]["database_id"] if found else None)
    witness = trust.witness_file(db_id)
    return {"format": "railval-public-key/1", "algorithm": "Ed25519",
            "public_key": public_key_hex(ring[fp]), "fingerprint": fp,
            "trusted_from": ring.how.get(fp, how), "database_id": db_id,
            "retired": retired, "retired_public_keys": [public_key_hex(ring[f]) for f in retired],
            "key_file": str(integrity.signing_key_path(database.url) or "(in memory)"),
            "key_file_fingerprint": key_fingerprint(file_pk) if file_pk is not None else None,
            "anchor_file": str(found[0]) if found else None,
            "witness_file": str(witness) if witness else None}


def rotate_key(database, actor: str, reason: str = "") -> dict[str, Any]:
    """Replace the signing key: a ``key.rotate`` row signed by the current (trusted) key and
    countersigned by the new one; then the new key file and its pin (docs/audit.md)."""
    path = integrity.signing_key_path(database.url)
    if path is None:
        raise RailvalError("an in-memory database has no key file to rotate")
    old = integrity.signing_key(database.url)
    new = ed25519.Ed25519PrivateKey.generate()
    ofp, nfp = key_fingerprint(old.public_key()), key_fingerprint(new.public_key())
    staged = Path(f"{path}.new")
    try:
        fd = os.open(staged, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except OSError as exc:
        raise RailvalError(f"key rotation: cannot write {staged}: {exc.strerror}") from None
    with os.fdopen(fd, "wb") as fh:
        fh.write(new.private_bytes(serialization.Encoding.PEM,
                                   serialization.PrivateFormat.PKCS8,
                                   serialization.NoEncryption()))
    detail = {"old_fingerprint": ofp, "new_fingerprint": nfp,
              "old_public_key": public_key_hex(old.public_key()),
              "new_public_key": public_key_hex(new.public_key()),
              "new_key_signature": sign(new, "key-rotation", rotation_message(ofp, nfp))}
    try:
        with database.session(write=True) as s:
            ev = audit.record(s, actor, trust.ROTATE_ACTION, "audit:signing-key", None, None,
                              reason or "signing key rotation", detail=detail)
            seq, db_id = ev.seq, audit.identity(s)["database_id"]
    except BaseException:
        staged.unlink()
        raise
    trust.update_anchor(database.url, db_id, pin={"fingerprint": nfp,
                        "public_key": detail["new_public_key"], "how": f"rotation row {seq}"})
    os.replace(path, Path(f"{path}.old-{ofp[:16]}"))
    os.replace(staged, path)
    integrity.forget_keys()
    return {"seq": seq, "old_fingerprint": ofp, "new_fingerprint": nfp,
            "old_key_file": f"{path}.old-{ofp[:16]}", "key_file": str(path)}
