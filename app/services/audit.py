"""Audit verification, checkpoints and the offline bundle (docs/audit.md).

``railval audit verify`` (:func:`verify_database`) checks, and names the first break of:

1. the **hash chain** of ``audit_event`` (every row recomputed, links, sequence numbers) and
   that ``audit_head`` agrees with the last row;
2. a **checkpoint** file if given: the chain still holds row ``seq`` with the same hash (a
   cut tail or rewritten history is caught even when the attacker fixed the chain);
3. every stored **signal blob** against its SHA-256 content hash;
4. every **sign-off**: its manifest still hashes to its evidence hash, its ``signoff.create``
   audit row names that hash, and the evidence rebuilt from the database today (validation
   recomputed) has the same hash — otherwise the sign-off is stale.

``railval audit export DIR`` (:func:`export_bundle`) writes the bundle that
:func:`verify_bundle` checks without the database: ``audit.jsonl`` (every row),
``signoffs.json`` (sign-offs with their manifests), ``current-evidence.json`` (each signed
configuration's manifest as it is at export), ``head.json``.
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from railval.core.errors import RailvalError
from railval.core.integrity import check_checkpoint, evidence_hash, verify_chain
from railval.db import audit, repo
from railval.db import signoff as db_signoff

BUNDLE_FORMAT = "railval-audit-bundle/1"


@dataclass
class Finding:
    """One thing that does not hold: what, where, expected vs found."""

    kind: str  # chain | head | checkpoint | signal | signoff
    where: str
    expected: str
    found: str

    def __str__(self) -> str:
        return f"{self.kind}: {self.where}: expected {self.expected}, found {self.found}"

    def to_dict(self) -> dict[str, str]:
        return {"kind": self.kind, "where": self.where, "expected": self.expected,
                "found": self.found}


@dataclass
class VerifyReport:
    rows: int = 0
    head_seq: int = 0
    head_hash: str = ""
    signals: int = 0
    signoffs: int = 0
    findings: list[Finding] = field(default_factory=list)
    seconds: float = 0.0
    source: str = "database"

    @property
    def ok(self) -> bool:
        return not self.findings

    def to_dict(self) -> dict[str, Any]:
        return {"ok": self.ok, "source": self.source, "rows": self.rows,
                "head": {"seq": self.head_seq, "row_hash": self.head_hash},
                "signals_checked": self.signals, "signoffs_checked": self.signoffs,
                "findings": [f.to_dict() for f in self.findings],
                "seconds": round(self.seconds, 3)}


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


def _check_chain(rows: Iterable[dict[str, Any]], report: VerifyReport,
                 checkpoint: dict[str, Any] | None) -> dict[int, str]:
    by_seq: dict[int, str] = {}

    def tap():
        for r in rows:
            by_seq[int(r["seq"])] = r["row_hash"]
            yield r

    n, head_hash, brk = verify_chain(tap())
    report.rows = len(by_seq)
    report.head_seq, report.head_hash = n, head_hash
    if brk is not None:
        report.findings.append(Finding(
            "chain", f"row seq {brk.seq}, object {brk.object!r}, field {brk.field}",
            brk.expected, brk.found))
    if checkpoint is not None:
        cbrk = check_checkpoint(by_seq, max(by_seq) if by_seq else 0, checkpoint)
        if cbrk is not None:
            where = (f"checkpoint row seq {cbrk.seq}" if cbrk.seq is not None
                     else "checkpoint: chain length")
            report.findings.append(Finding("checkpoint", where, cbrk.expected, cbrk.found))
    return by_seq


def _check_signoff_binding(sod: dict[str, Any], by_seq_rows: dict[int, dict[str, Any]],
                           report: VerifyReport) -> None:
    """The manifest hashes to the evidence hash and the chain recorded that hash."""
    where = (f"sign-off {sod['id']} ({sod['campaign']}/{sod['configuration']}, "
             f"{sod['printed_name']}, {sod['signed_at_utc']})")
    found = evidence_hash(sod["manifest"])
    if found != sod["evidence_sha256"]:
        report.findings.append(Finding("signoff", where + ": manifest",
                                       sod["evidence_sha256"], found))
        return
    rows = [r for r in by_seq_rows.values() if r["action"] == "signoff.create"
            and (r.get("detail") or {}).get("signoff") == sod["id"]]
    if not rows:
        report.findings.append(Finding("signoff", where + ": audit row signoff.create",
                                       "a row naming this sign-off", "none"))
    elif rows[0]["after_sha256"] != sod["evidence_sha256"]:
        report.findings.append(Finding("signoff", where + f": audit row {rows[0]['seq']}",
                                       sod["evidence_sha256"], str(rows[0]["after_sha256"])))


def verify_database(database, checkpoint: dict[str, Any] | None = None, *,
                    signals: bool = True, full: bool = True) -> VerifyReport:
    """Verify chain, checkpoint, signal blobs and sign-offs (module docstring)."""
    from railval.app.services import signoff as svc

    t0 = time.perf_counter()
    report = VerifyReport(source=database.safe_url)
    with database.session() as s:
        rows = {}

        def collect():
            for r in audit.iter_rows(s):
                rows[int(r["seq"])] = r
                yield r

        _check_chain(collect(), report, checkpoint)
        head_seq, head_hash = audit.head(s)
        if not report.findings and (head_seq, head_hash) != (report.head_seq, report.head_hash):
            report.findings.append(Finding(
                "head", "audit_head", f"seq {report.head_seq} hash {report.head_hash}",
                f"seq {head_seq} hash {head_hash} (rows after {report.head_seq} removed?)"))
        broken: set[tuple[str, str | None, str, str]] = set()
        if signals:
            for camp in repo.list_campaigns(s):
                report.signals += repo.count_signals(s, camp)
                for p in repo.verify_signals(s, camp):
                    broken.add((camp.name, p["configuration"], p["section"], p["channel"]))
                    src = p["configuration"] or "measurement"
                    report.findings.append(Finding(
                        "signal", f"campaign {camp.name!r}, {src}, section {p['section']}, "
                        f"channel {p['channel']}", "its stored SHA-256", p["error"]))
        for so in db_signoff.list_signoffs(s):
            report.signoffs += 1
            sod = db_signoff.as_dict(so)
            n_before = len(report.findings)
            _check_signoff_binding(sod, rows, report)
            if len(report.findings) > n_before:
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
            st = svc.status(s, so, full=full)
            if not st.valid:
                report.findings.append(Finding(
                    "signoff", f"sign-off {so.id} ({so.campaign}/{so.configuration}, "
                    f"{so.printed_name}) is stale", f"evidence {so.evidence_sha256}",
                    "; ".join(st.reasons)))
    report.seconds = time.perf_counter() - t0
    return report


def export_bundle(database, folder: str | Path) -> dict[str, Any]:
    """Write the offline bundle into ``folder`` (created; must be empty if it exists)."""
    from railval.app.services import signoff as svc

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
    return head


def verify_bundle(folder: str | Path, checkpoint: dict[str, Any] | None = None) -> VerifyReport:
    """Verify an exported bundle without the database (chain, checkpoint, sign-offs)."""
    from railval.app.services.signoff import manifest_differences

    t0 = time.perf_counter()
    root = Path(folder)
    report = VerifyReport(source=str(root))
    for name in ("audit.jsonl", "signoffs.json", "current-evidence.json", "head.json"):
        if not (root / name).is_file():
            raise RailvalError(f"audit bundle {root}: {name} is missing")
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

    _check_chain(read(), report, checkpoint)
    head = json.loads((root / "head.json").read_text(encoding="utf-8"))
    if not report.findings and (int(head["seq"]), head["row_hash"]) != (report.head_seq,
                                                                        report.head_hash):
        report.findings.append(Finding("head", "head.json",
                                       f"seq {report.head_seq} hash {report.head_hash}",
                                       f"seq {head['seq']} hash {head['row_hash']}"))
    current = json.loads((root / "current-evidence.json").read_text(encoding="utf-8"))
    for sod in json.loads((root / "signoffs.json").read_text(encoding="utf-8")):
        report.signoffs += 1
        n_before = len(report.findings)
        _check_signoff_binding(sod, rows, report)
        if len(report.findings) > n_before:
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
