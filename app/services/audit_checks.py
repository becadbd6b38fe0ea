"""The checks of ``railval audit verify`` on plain rows (docs/audit.md): the chain and a
checkpoint, every row's signed head, the witness file, and sign-offs ↔ ``signoff.create``
rows both ways. Shared by the database check and the offline bundle check
(:mod:`railval.app.services.audit`); each check appends :class:`Finding` s to a
:class:`VerifyReport`.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

from railval.core.integrity import (
    IDENTITY_ACTION,
    KeyRing,
    apply_rotations,
    check_checkpoint,
    evidence_hash,
    head_message,
    known_public_keys,
    signoff_record,
    signoff_record_hash,
    verify_chain,
    verify_signature,
)


__all__ = ["Finding", "KeyRing", "VerifyReport", "apply_rotations", "known_public_keys"]


@dataclass
class Finding:
    """One thing that does not hold: what, where, expected vs found."""

    kind: str  # chain | head | checkpoint | signature | witness | signal | signoff
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
    notes: list[str] = field(default_factory=list)
    signed_rows: int = 0
    keys: list[str] = field(default_factory=list)
    witness: str | None = None
    witness_heads: int = 0
    signed_from: int | None = None
    trust: list[dict[str, Any]] = field(default_factory=list)
    seals_checked: bool = True
    seconds: float = 0.0
    source: str = "database"

    @property
    def ok(self) -> bool:
        return not self.findings

    def to_dict(self) -> dict[str, Any]:
        return {"ok": self.ok, "source": self.source, "rows": self.rows,
                "head": {"seq": self.head_seq, "row_hash": self.head_hash},
                "signals_checked": self.signals, "signoffs_checked": self.signoffs,
                "signed_rows": self.signed_rows, "trusted_keys": self.keys,
                "trust": self.trust, "seals_checked": self.seals_checked,
                "witness": self.witness, "witness_heads": self.witness_heads,
                "findings": [f.to_dict() for f in self.findings], "notes": self.notes,
                "seconds": round(self.seconds, 3)}


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


def witness_signed_from(witness: list[dict[str, Any]] | None,
                        keys: dict[str, Any]) -> int | None:
    """The lowest seq of a correctly signed head in the witness: signing was enabled there,
    so no row from it on may lack a signature (stripping every signature does not turn the
    trail into one "written before signing")."""
    best = None
    for w in witness or []:
        seq = int(w["seq"])
        if best is not None and seq >= best:
            continue
        pk = keys.get(str(w.get("key_fingerprint")))
        if pk is not None and verify_signature(pk, "audit-head",
                                               head_message(seq, str(w["row_hash"])),
                                               w.get("signature")):
            best = seq
    return best


def _declared_unsigned(rows: dict[int, dict[str, Any]], good: set[int]) -> dict[int, int]:
    """seq → number of earlier unsigned rows, of the verified rows that say so
    (``database.identity`` and ``audit.seal`` rows, detail ``unsigned_rows_before``)."""
    out = {}
    for seq in good:
        r = rows[seq]
        if r["action"] in (IDENTITY_ACTION, "audit.seal"):
            n = (r.get("detail") or {}).get("unsigned_rows_before")
            if isinstance(n, int) and n > 0:
                out[seq] = n
    return out


def _check_row_signatures(rows: dict[int, dict[str, Any]], keys: dict[str, Any],
                          report: VerifyReport, signed_from: int | None = None) -> set[int]:
    """Every row's signed head verifies with a key trusted for that row; unsigned rows are
    a note only when a verified row after them says so (``unsigned_rows_before`` of a
    ``database.identity`` or ``audit.seal`` row) and before ``signed_from`` (the first head
    in the witness). Returns the seqs whose signature verified; sets ``report.signed_from``."""
    ring = keys if isinstance(keys, KeyRing) else KeyRing(keys)
    good: set[int] = set()
    first_signed: int | None = signed_from
    unsigned: list[int] = []
    bad = 0

    def find(where, expected, found):
        nonlocal bad
        bad += 1
        if bad <= 20:
            report.findings.append(Finding("signature", where, expected, found))

    for seq in sorted(rows):
        r = rows[seq]
        where = f"row seq {seq} ({r['action']}, object {r['object']!r})"
        sig, fp = r.get("signature"), r.get("key_fingerprint")
        if not sig:
            unsigned.append(seq)
            continue
        if first_signed is None or seq < first_signed:
            first_signed = seq
        pk = ring.at(fp, seq)
        if pk is None:
            find(where, "a key this verifier trusts (" + ", ".join(k[:16] + "…" for k in ring)
                 + ")", ring.why(fp, seq))
        elif not verify_signature(pk, "audit-head", head_message(seq, r["row_hash"]), sig):
            report.signed_rows += 1
            find(where, "a valid Ed25519 signature of {seq, row_hash}",
                 "an invalid one: the row was changed or written without the signing key")
        else:
            report.signed_rows += 1
            good.add(seq)
    report.signed_from = first_signed
    _unsigned_rows(rows, unsigned, _declared_unsigned(rows, good), first_signed, report, find)
    return good


def _unsigned_rows(rows, unsigned: list[int], declared: dict[int, int],
                   first_signed: int | None, report: VerifyReport, find) -> None:
    """Unsigned rows: a note when a verified row after them declares them, else findings."""
    if not unsigned:
        return
    stmt = max(declared, default=None)
    ok = [s for s in unsigned if stmt is not None and s < stmt]
    if stmt is not None and len(ok) > declared[stmt]:
        ok = []  # more unsigned rows than the signed statement counted: signatures stripped
    for seq in (s for s in unsigned if s not in set(ok)):
        r = rows[seq]
        what = (f"a signature (rows are signed from seq {first_signed})"
                if first_signed is not None else "a signature, or a signed row declaring "
                "the rows written before signing (`railval audit seal`)")
        find(f"row seq {seq} ({r['action']}, object {r['object']!r})", what,
             "none: the row was written without the signing key")
    if ok:
        report.notes.append(
            f"rows seq {ok[0]}–{ok[-1]} ({len(ok)}) are unsigned, written before signing "
            f"was enabled; the signed row seq {stmt} declares them and chains over them")
    if first_signed is None:
        report.notes.append(
            f"no row is signed ({len(unsigned)} rows): anyone with write access could have "
            "written them; run `railval audit seal` on the server to sign the current head")


def _key_at(keys: dict[str, Any], fp: Any, seq: int | None) -> Any:
    return keys.at(fp, seq) if isinstance(keys, KeyRing) else keys.get(str(fp))


def check_anchor(by_seq: dict[int, str], witness: list[dict[str, Any]] | None,
                 anchor: dict[str, Any], where: str, report: VerifyReport) -> None:
    """The newest head the trust anchor ``anchor`` (at ``where``) recorded as witnessed:
    the chain still holds it, and the witness file (``witness``; ``None``: missing) still
    reaches it — a cut tail, a deleted trail, an older copy restored, a deleted, truncated
    or rewound witness file fail."""
    hw = anchor.get("witnessed")
    if not hw:
        return
    seq, h = int(hw["seq"]), str(hw["row_hash"])
    top = max(by_seq) if by_seq else 0
    label = f"trust anchor {where}: witnessed head seq {seq} ({hw.get('at_utc', '')})"
    if seq > top:
        report.findings.append(Finding(
            "witness", label, f"the chain to hold at least {seq} rows",
            f"{top} rows: the rows after seq {top} were removed (or an older copy restored)"))
    elif by_seq.get(seq) != h:
        report.findings.append(Finding("witness", label, h,
                                       f"{by_seq.get(seq)} (the chain was rewritten)"))
    if witness is None:
        report.findings.append(Finding(
            "witness", label, "the witness file holding the signed heads up to that seq",
            "no witness file: it was deleted"))
        return
    reach = max((int(w["seq"]) for w in witness), default=0)
    if reach < seq or not any(int(w["seq"]) == seq and str(w["row_hash"]) == h
                              for w in witness):
        report.findings.append(Finding(
            "witness", label, f"the witness file to hold the head seq {seq}",
            f"heads up to seq {reach} only: the witness file was truncated or rewound"))


def _check_witness(by_seq: dict[int, str], witness: list[dict[str, Any]], where_file: str,
                   keys: dict[str, Any], report: VerifyReport,
                   rows: dict[int, dict[str, Any]] | None = None,
                   verified: set[int] | None = None) -> None:
    """Every signed head in the witness file is still in the chain with the same hash. A
    line equal to a row whose signature already verified (``verified``) is not verified
    twice."""
    rows, verified = rows or {}, verified or set()
    report.witness = where_file
    report.witness_heads = len(witness)
    top = max(by_seq) if by_seq else 0
    bad = 0
    for i, w in enumerate(witness, 1):
        seq, h = int(w["seq"]), str(w["row_hash"])
        pk = _key_at(keys, w.get("key_fingerprint"), seq)
        label = f"witness {where_file} line {i}: signed head seq {seq} ({w.get('at_utc', '')})"
        same = (seq in verified and rows[seq]["row_hash"] == h
                and rows[seq].get("signature") == w.get("signature")
                and rows[seq].get("key_fingerprint") == w.get("key_fingerprint"))
        if same:
            continue
        if pk is None or not verify_signature(pk, "audit-head", head_message(seq, h),
                                              w.get("signature")):
            report.findings.append(Finding("witness", label, "a head signed by a trusted key",
                                           "an unsigned or wrongly signed line"))
            bad += 1
        elif seq > top:
            report.findings.append(Finding(
                "witness", label, f"the chain to hold at least {seq} rows",
                f"{top} rows: the rows after seq {top} were removed"))
            bad += 1
        elif by_seq.get(seq) != h:
            report.findings.append(Finding(
                "witness", label, h, f"{by_seq.get(seq)} (the chain was rewritten)"))
            bad += 1
        if bad >= 3:
            break


def _signoff_rows(rows: dict[int, dict[str, Any]]
                  ) -> tuple[dict[int, list[dict[str, Any]]], dict[int, tuple[int, str]]]:
    """(sign-off id → its ``signoff.create`` rows, unsigned sign-off id → (seal row, record
    hash) of the first signed ``audit.seal`` row binding it)."""
    created: dict[int, list[dict[str, Any]]] = {}
    sealed: dict[int, tuple[int, str]] = {}
    for r in rows.values():
        if r["action"] == "signoff.create":
            sid = (r.get("detail") or {}).get("signoff")
            if isinstance(sid, int):
                created.setdefault(sid, []).append(r)
    for r in rows.values():
        if r["action"] == "audit.seal" and r.get("signature"):
            for sid, h in ((r.get("detail") or {}).get("unsigned_signoffs") or {}).items():
                sealed.setdefault(int(sid), (int(r["seq"]), str(h)))
    return created, sealed


def _check_unsigned(sod: dict[str, Any], row: dict[str, Any] | None,
                    sealed: dict[int, tuple[int, str]], report: VerifyReport, find) -> None:
    """A sign-off without signature: its audit row, and the seal that binds its record."""
    if row is None:
        find(sod, "inserted", "a signoff.create audit row and a signature",
             "neither: the sign-off was written outside railval")
    elif row.get("signature") or (report.signed_from is not None
                                  and int(row["seq"]) >= report.signed_from):
        find(sod, f"inserted (audit row {row['seq']})",
             "a signature (the trail was signed when its audit row was written)",
             "none: the sign-off was written without the signing key")
    elif row["after_sha256"] != sod["evidence_sha256"]:
        find(sod, f"audit row {row['seq']}", sod["evidence_sha256"], str(row["after_sha256"]))
    elif int(sod["id"]) in sealed:
        seal_seq, h = sealed[int(sod["id"])]
        if signoff_record_hash(sod) != h:
            find(sod, f"edited after the seal (audit row {seal_seq})", h, signoff_record_hash(sod))
        else:
            report.notes.append(
                f"sign-off {sod['id']} ({sod['campaign']}/{sod['configuration']}) is "
                f"unsigned, written before signing was enabled (audit row "
                f"{row['seq']}); its record is bound by the seal, row {seal_seq}")
    else:
        report.notes.append(
            f"sign-off {sod['id']} ({sod['campaign']}/{sod['configuration']}) is "
            f"unsigned, written before signing was enabled (audit row {row['seq']}), "
            "and not sealed: its decision and statement are bound to nothing; run "
            "`railval audit seal`")


def _check_signed(sod: dict[str, Any], row: dict[str, Any] | None, keys: dict[str, Any],
                  find) -> None:
    """A signed sign-off: a trusted key, its signature, and its audit row's record hash."""
    record_hash = signoff_record_hash(sod)
    seq = int(row["seq"]) if row is not None else None
    pk = _key_at(keys, sod.get("key_fingerprint"), seq)
    hint = ""
    if row is not None:
        was = (row.get("detail") or {}).get("decision")
        if was is not None and was != sod["decision"]:
            hint = f"; decision: signed {was!r}, now {sod['decision']!r}"
    if pk is None:
        why = (keys.why(sod.get("key_fingerprint"), seq) if isinstance(keys, KeyRing)
               else f"key {str(sod.get('key_fingerprint'))[:16]}…: signed by a key that is "
               "not trusted")
        find(sod, "signature", "a key this verifier trusts", why)
    elif not verify_signature(pk, "signoff", signoff_record(sod), sod["signature"]):
        find(sod, "edited or forged: its signature does not verify",
             f"the signed record {sod.get('record_sha256')}", f"record {record_hash}{hint}")
    elif row is None:
        find(sod, "audit row signoff.create", "a row naming this sign-off",
             "none: the audit row was removed")
    elif row["after_sha256"] != record_hash:
        find(sod, f"audit row {row['seq']}", str(row["after_sha256"]), f"{record_hash}{hint}")


def _check_signoffs(sods: list[dict[str, Any]], rows: dict[int, dict[str, Any]],
                    keys: dict[str, Any], report: VerifyReport) -> set[int]:
    """Sign-offs ↔ ``signoff.create`` rows both ways; returns the ids with findings."""
    created, sealed = _signoff_rows(rows)
    bad: set[int] = set()

    def find(sod, what, expected, found):
        where = (f"sign-off {sod['id']} ({sod['campaign']}/{sod['configuration']}, "
                 f"{sod.get('decision_text') or sod['decision']}, by {sod['printed_name']}, "
                 f"{sod['signed_at_utc']})")
        report.findings.append(Finding("signoff", f"{where}: {what}", expected, found))
        bad.add(int(sod["id"]))

    ids = set()
    for sod in sods:
        ids.add(int(sod["id"]))
        found = evidence_hash(sod["manifest"])
        if found != sod["evidence_sha256"]:
            find(sod, "manifest", sod["evidence_sha256"], found)
            continue
        audit_rows = created.get(int(sod["id"]), [])
        row = audit_rows[0] if audit_rows else None
        if len(audit_rows) > 1:
            find(sod, "audit rows " + ", ".join(str(r["seq"]) for r in audit_rows),
                 "one signoff.create row", f"{len(audit_rows)}: a row was inserted")
        if sod.get("signature"):
            _check_signed(sod, row, keys, find)
        else:
            _check_unsigned(sod, row, sealed, report, find)
    for sid, audit_rows in sorted(created.items()):
        if sid not in ids:
            r = audit_rows[0]
            d = r.get("detail") or {}
            report.findings.append(Finding(
                "signoff", f"sign-off {sid} ({r['object'].removeprefix('configuration:')}, "
                f"{d.get('decision', '?')}, by {r['actor']}, {r['at_utc']}; audit row "
                f"{r['seq']})", "the sign-off this audit row records",
                "none: the sign-off was deleted"))
    return bad
