"""Audit verification, checkpoints and the offline bundle (docs/audit.md).

``railval audit verify`` (:func:`verify_database`) checks, and names the first break of:

1. the **hash chain** of ``audit_event`` (every row recomputed, links, sequence numbers) and
   that ``audit_head`` agrees with the last row;
2. a **checkpoint** file if given: the chain still holds row ``seq`` with the same hash (a
   cut tail or rewritten history is caught even when the attacker fixed the chain);
3. every stored **signal blob** against its SHA-256 content hash;
4. every **sign-off**: its manifest still hashes to its evidence hash, its ``signoff.create``
   audit row names that hash, and the evidence rebuilt from the database today (validation
   recomputed) has the same hash — otherwise the sign-off is stale;
5. the **signatures** (Ed25519, public key only): every row's signed head and every
   sign-off's signed record; sign-offs ↔ ``signoff.create`` rows **both ways** (an edited,
   deleted or inserted sign-off is named);
6. the **witness file** kept beside the signing key: every signed head it holds is still in
   the chain with the same hash (a removed tail or a rewritten chain is found without a
   hand-made checkpoint).

Rows and sign-offs written before signing was enabled are reported as *notes* ("unsigned,
written before signing was enabled"), not as failures; ``railval audit seal`` signs the
then-current head over them.

``railval audit export DIR`` (:func:`export_bundle`) writes the bundle that
:func:`verify_bundle` checks without the database: ``audit.jsonl`` (every row),
``signoffs.json`` (sign-offs with their manifests), ``current-evidence.json`` (each signed
configuration's manifest as it is at export), ``head.json``.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

from railval.app.services.audit_checks import (
    Finding,
    VerifyReport,
    _check_chain,
    _check_row_signatures,
    _check_signoffs,
    _check_witness,
    check_anchor,
    witness_signed_from,
)
from railval.app.services.audit_trust import (
    _check_trail,
    _fingerprints,
    _pin_first_use,
    _witness_lines,
    bundle_ring,
    key_info,
    rotate_key,
    trusted_keys,
)
from railval.core import lazy
from railval.core.errors import RailvalError
from railval.db import audit, integrity, repo
from railval.db import signoff as db_signoff

#: deferred (railval.core.lazy): the sign-off service only for the checks that recompute
#: sign-offs
svc = lazy.module("railval.app.services.signoff")
manifest_differences = lazy.function("railval.app.services.signoff", "manifest_differences")

__all__ = ["BUNDLE_FORMAT", "export_bundle", "key_info", "newest", "read_checkpoint",
           "rotate_key", "seal", "trail", "trusted_keys", "verify_bundle", "verify_database",
           "write_checkpoint"]

BUNDLE_FORMAT = "railval-audit-bundle/1"


def read_checkpoint(path: str | Path) -> dict[str, Any]:
    p = Path(path)
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
        int(doc["seq"])
        str(doc["row_hash"])
    except FileNotFoundError:
        raise RailvalError(f"checkpoint {p}: file not found") from None
    except (ValueError, KeyError, TypeError) as exc:
        raise RailvalError(f"checkpoint {p}: not a railval checkpoint (needs JSON with "
                           f"'seq' and 'row_hash'): {exc}") from None
    return doc


def write_checkpoint(database, path: str | Path) -> dict[str, Any]:
    """Write the current head ``{seq, row_hash, at_utc, database}`` to ``path``."""
    with database.session() as s:
        seq, h = audit.head(s)
    doc = {"format": "railval-audit-checkpoint/1", "seq": seq, "row_hash": h,
           "at_utc": audit.utc_stamp(), "database": database.safe_url}
    Path(path).write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
    return doc


def verify_database(database, checkpoint: dict[str, Any] | None = None, *,
                    signals: bool = True, full: bool = True, witness: str | None = None,
                    use_witness: bool = True, public_key: str | None = None,
                    trust_fingerprints: list[str] | None = None) -> VerifyReport:
    """Verify chain, checkpoint, signatures, trust anchor and witness, signal blobs and
    sign-offs (module docstring). ``witness``: another witness file than the anchor's.
    Given its trust (``public_key``, ``trust_fingerprints``) it writes nothing, and without
    the seal secret it checks no seal (says so)."""
    t0 = time.perf_counter()
    report = VerifyReport(source=database.safe_url)
    fps = _fingerprints(trust_fingerprints)
    with database.write_session(deferred=True) as s:  # may fill the result cache
        rows, ring, explicit = _check_trail(database, s, report, checkpoint, witness=witness,
                                            use_witness=use_witness, public_key=public_key,
                                            fingerprints=fps)
        seals = integrity.secret_exists(database.url)
        if not seals and not explicit and any(repo.count_signals(s, c)
                                              for c in repo.list_campaigns(s)):
            report.findings.append(Finding(
                "signal", "seal secret", "the server's secret that sealed the stored arrays "
                f"({integrity.secret_path(database.url)}, or $RAILVAL_SECRET_KEY)",
                "none: it was removed; no seal can be checked"))
        if not seals:
            full = False
            report.notes.append(
                "seals not checked (no secret): the signal and result-cache seals need the "
                "server's secret; the content hashes, the chain, the signatures and the "
                "sign-offs' records and evidence inputs were checked (the validation was "
                "not recomputed: its cache needs the secret)")
        report.seals_checked = seals
        _check_evidence(s, report, rows, ring, signals=signals, full=full, seals=seals)
    if not explicit:
        _pin_first_use(database, rows, ring, report)
    report.seconds = time.perf_counter() - t0
    return report


def _check_evidence(s, report: VerifyReport, rows, ring, *, signals: bool, full: bool,
                    seals: bool) -> None:
    """Signal blobs and seals, and every sign-off (record, audit row, evidence)."""

    broken: set[tuple[str, str | None, str, str]] = set()
    doc = repo.verify_storage(s, blobs=signals, seals=seals)
    if signals:
        report.signals = sum(repo.count_signals(s, c) for c in repo.list_campaigns(s))
    for camp_name, problems in doc["campaigns"].items():
        for p in problems:
            broken.add((camp_name, p["configuration"], p["section"], p["channel"]))
            src = p["configuration"] or "measurement"
            report.findings.append(Finding(
                "signal", f"campaign {camp_name!r}, {src}, section {p['section']}, "
                f"channel {p['channel']}", "its stored SHA-256 and seal", p["error"]))
    sos = db_signoff.list_signoffs(s)
    bad_ids = _check_signoffs([db_signoff.as_dict(so) for so in sos], rows, ring, report)
    for so in sos:
        report.signoffs += 1
        if so.id in bad_ids:
            continue
        bad = sorted(f"{'measurement' if src is None else src} section {sec} {ch}"
                     for camp_name, src, sec, ch in broken if camp_name == so.campaign
                     and src in (None, so.configuration))
        if bad:
            report.findings.append(Finding(
                "signoff", f"sign-off {so.id} ({so.campaign}/{so.configuration}, "
                f"{so.printed_name}) is stale: its evidence includes stored arrays that no "
                "longer match their hashes", f"evidence {so.evidence_sha256}",
                "; ".join(bad[:5])))
            continue
        try:
            st = svc.status(s, so, full=full, check_signature=False)
        except RailvalError as exc:
            st = svc.SignoffStatus(so.id, "stale", [str(exc)])
        if not st.valid:
            report.findings.append(Finding(
                "signoff", f"sign-off {so.id} ({so.campaign}/{so.configuration}, "
                f"{so.printed_name}) is stale", f"evidence {so.evidence_sha256}",
                "; ".join(st.reasons)))


def export_bundle(database, folder: str | Path) -> dict[str, Any]:
    """Write the offline bundle into ``folder`` (created; must be empty if it exists)."""

    out = Path(folder)
    if out.exists() and any(out.iterdir()):
        raise RailvalError(f"audit export: folder {out} is not empty; choose a new folder")
    out.mkdir(parents=True, exist_ok=True)
    n = 0
    with database.session() as s:
        with (out / "audit.jsonl").open("w", encoding="utf-8") as fh:
            for r in audit.iter_rows(s):
                fh.write(json.dumps(r, sort_keys=True, ensure_ascii=False) + "\n")
                n += 1
        seq, h = audit.head(s)
        signoffs = [db_signoff.as_dict(so) for so in db_signoff.list_signoffs(s)]
        current: dict[str, Any] = {}
        for sod in signoffs:
            key = f"{sod['campaign']}/{sod['configuration']}"
            if key in current:
                continue
            settings = dict(sod["manifest"].get("processing") or {})
            settings.pop("version", None)
            try:
                current[key] = svc.input_manifest(s, sod["campaign"], sod["configuration"],
                                                  settings)
            except RailvalError as exc:
                current[key] = {"missing": str(exc)}
    (out / "signoffs.json").write_text(json.dumps(signoffs, indent=1, ensure_ascii=False),
                                       encoding="utf-8")
    (out / "current-evidence.json").write_text(
        json.dumps(current, indent=1, ensure_ascii=False), encoding="utf-8")
    head = {"format": BUNDLE_FORMAT, "seq": seq, "row_hash": h, "rows": n,
            "exported_at_utc": audit.utc_stamp(), "database": database.safe_url,
            "software_version": svc.software_version()}
    (out / "head.json").write_text(json.dumps(head, indent=2) + "\n", encoding="utf-8")
    info = key_info(database)
    (out / "key.json").write_text(json.dumps(info, indent=2) + "\n", encoding="utf-8")
    wpath = Path(info["witness_file"]) if info["witness_file"] else None
    if wpath is not None and wpath.is_file():
        (out / "witness.jsonl").write_bytes(wpath.read_bytes())
    if info["anchor_file"]:
        (out / "anchor.json").write_bytes(Path(info["anchor_file"]).read_bytes())
    return head


def verify_bundle(folder: str | Path, checkpoint: dict[str, Any] | None = None, *,
                  public_key: str | None = None,
                  trust_fingerprints: list[str] | None = None) -> VerifyReport:
    """Verify an exported bundle without the database (chain, checkpoint, signatures,
    the server's anchor and witness, sign-offs both ways). ``public_key``: the hex key (or
    a file holding it) the assessor obtained from the server's owner, ``trust_fingerprints``
    the fingerprints; without them the bundle's ``key.json`` is trusted and a note says to
    compare its fingerprint. Older keys are trusted only through the trail's countersigned
    ``key.rotate`` rows."""

    t0 = time.perf_counter()
    root = Path(folder)
    report = VerifyReport(source=str(root))
    fps = _fingerprints(trust_fingerprints)
    for name in ("audit.jsonl", "signoffs.json", "current-evidence.json", "head.json"):
        if not (root / name).is_file():
            raise RailvalError(f"audit bundle {root}: {name} is missing")
    if not (public_key or fps or (root / "key.json").is_file()):
        raise RailvalError(f"audit bundle {root}: key.json is missing; pass --public-key")
    rows: dict[int, dict[str, Any]] = {}

    def read():
        with (root / "audit.jsonl").open(encoding="utf-8") as fh:
            for line_no, line in enumerate(fh, 1):
                try:
                    r = json.loads(line)
                except json.JSONDecodeError as exc:
                    raise RailvalError(f"audit bundle {root}/audit.jsonl line {line_no}: "
                                       f"{exc}") from None
                rows[int(r["seq"])] = r
                yield r

    by_seq = _check_chain(read(), report, checkpoint)
    keys = bundle_ring(root, rows, public_key, fps, report)
    report.keys, report.trust = list(keys), keys.describe()
    lines = _witness_lines(root / "witness.jsonl", report,
                           quiet=(root / "anchor.json").is_file() or not rows)
    if (root / "anchor.json").is_file():
        try:
            anchor = json.loads((root / "anchor.json").read_text(encoding="utf-8"))
        except ValueError as exc:
            raise RailvalError(f"audit bundle {root}/anchor.json: {exc}") from None
        check_anchor(by_seq, lines, anchor, "anchor.json", report)
    good = _check_row_signatures(rows, keys, report, witness_signed_from(lines, keys))
    if lines is not None:
        _check_witness(by_seq, lines, "witness.jsonl", keys, report, rows, good)
    head = json.loads((root / "head.json").read_text(encoding="utf-8"))
    if not report.findings and (int(head["seq"]), head["row_hash"]) != (report.head_seq,
                                                                        report.head_hash):
        report.findings.append(Finding("head", "head.json",
                                       f"seq {report.head_seq} hash {report.head_hash}",
                                       f"seq {head['seq']} hash {head['row_hash']}"))
    current = json.loads((root / "current-evidence.json").read_text(encoding="utf-8"))
    sods = json.loads((root / "signoffs.json").read_text(encoding="utf-8"))
    bad_ids = _check_signoffs(sods, rows, keys, report)
    for sod in sods:
        report.signoffs += 1
        if int(sod["id"]) in bad_ids:
            continue
        now = current.get(f"{sod['campaign']}/{sod['configuration']}") or {}
        if "missing" in now:
            diffs = [f"evidence no longer exists at export: {now['missing']}"]
        else:
            keys = tuple(k for k in sod["manifest"] if k != "result")
            diffs = manifest_differences(sod["manifest"], now, keys=keys)
        if diffs:
            report.findings.append(Finding(
                "signoff", f"sign-off {sod['id']} ({sod['campaign']}/{sod['configuration']}, "
                f"{sod['printed_name']}) is stale at export", f"evidence {sod['evidence_sha256']}",
                "; ".join(diffs)))
    report.seconds = time.perf_counter() - t0
    return report


def seal(database, actor: str, reason: str = "") -> tuple[int, str, int]:
    """Sign the current head (:func:`railval.db.audit.seal`) → (seq, row hash, number of
    unsigned rows it covered)."""
    with database.session(write=True) as s:
        ev = audit.seal(s, actor, reason)
        return ev.seq, ev.row_hash, int((ev.detail or {}).get("unsigned_rows_before", 0))


def trail(database, *, actor: str | None = None, object_prefix: str | None = None
          ) -> list[dict[str, Any]]:
    """The audit rows in ``seq`` order, optionally of one actor or objects with a prefix."""
    with database.session() as s:
        return list(audit.iter_rows(s, actor=actor, object_prefix=object_prefix))


def newest(database, limit: int) -> tuple[list[dict[str, Any]], int]:
    """The ``limit`` newest audit rows (newest first) and the number of all rows."""
    with database.session() as s:
        return audit.newest_rows(s, limit)
