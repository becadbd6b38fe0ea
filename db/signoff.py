"""Sign-offs: append-only records of an independent decision on a configuration (docs/audit.md).

A sign-off stores the signer's printed name, the UTC time, the meaning of the signature
(21 CFR 11.50(a)), the decision, restrictions and statement, and the evidence it is bound to:
the canonical manifest and its SHA-256 (21 CFR 11.70). The database refuses UPDATE and
DELETE on the table; :func:`create` appends the row and its audit record in one transaction.

Each sign-off is **signed**: the Ed25519 signature (:mod:`railval.db.integrity` key) of its
canonical record (:func:`railval.core.integrity.signoff_record`: id, campaign,
configuration, signer, printed name, time, meaning, decision, restrictions, statement,
justification, contrary mark, evidence hash, software version); the record's SHA-256 is kept
in the row and in its ``signoff.create`` audit row, so ``railval audit verify`` checks the
pair both ways.
Building the manifest (which needs the validation) is the application's part:
:mod:`railval.app.services.signoff`.
"""

from __future__ import annotations

from typing import Any

from sqlalchemy import func, select, text, update
from sqlalchemy.orm import Session

from railval.core.errors import InvalidParameter, NotFound
from railval.core.integrity import evidence_hash, key_fingerprint, sign, signoff_record_hash
from railval.core.integrity import signoff_record as canonical_record
from railval.db import audit, integrity
from railval.db.models import AppUser, AuditHead, Signoff

#: decision → the words printed with the signature
DECISIONS: dict[str, str] = {
    "validated": "validated",
    "restricted": "validated with restrictions",
    "not-validated": "not validated",
}


#: decisions that accept the model (with or without restrictions)
ACCEPTING = ("validated", "restricted")


def contrary_reason(decision: str, validated: bool, in_sample: bool) -> str | None:
    """Why ``decision`` contradicts the objective verdict, or None when it does not.

    Contrary: accepting (``validated`` or ``restricted``) while the DynoTRAIN verdict is NOT
    VALIDATED; ``not-validated`` while it is VALIDATED; accepting an in-sample verdict (the
    configuration, or an ancestor, was calibrated on sections the verdict evaluates, so the
    verdict is not an independent test; docs/validation.md). Such a decision needs a written
    justification and is stored with ``contrary_to_objective`` (docs/audit.md)."""
    if decision in ACCEPTING and not validated:
        return "the decision accepts the model while the objective verdict is NOT VALIDATED"
    if decision == "not-validated" and validated:
        return "the decision rejects the model while the objective verdict is VALIDATED"
    if decision in ACCEPTING and in_sample:
        return ("the decision accepts an in-sample verdict (the parameters of the configuration "
                "or an ancestor were fitted, by a calibration or a diagnosis, on sections the "
                "verdict evaluates)")
    return None


def meaning(decision: str, campaign: str, config: str, evidence_sha256: str,
            contrary: str | None = None) -> str:
    """The meaning of the signature (21 CFR 11.50(a)(3)), stored and shown with it."""
    text = (f"Independent review and approval: I have reviewed the validation evidence "
            f"SHA-256 {evidence_sha256} of configuration {config!r} of campaign "
            f"{campaign!r} and I decide: {DECISIONS[decision]}.")
    if contrary:
        text += (f" This decision is CONTRARY TO THE OBJECTIVE VERDICT ({contrary}); my "
                 "written justification is part of this signature.")
    return text


def create(session: Session, *, user: AppUser, campaign: str, config: str,
           decision: str, restrictions: str, statement: str, manifest: dict[str, Any],
           software_version: str, justification: str = "", in_sample: bool = False) -> Signoff:
    """Append a signed sign-off bound to ``manifest``; audited as ``signoff.create``.

    The objective verdict is ``manifest["result"]["validated"]``; a decision contrary to it
    (:func:`contrary_reason`) is refused without ``justification`` and stored with
    ``contrary_to_objective``."""
    if decision not in DECISIONS:
        raise InvalidParameter(f"decision {decision!r}: choose one of {', '.join(DECISIONS)}")
    restrictions = (restrictions or "").strip()
    if decision == "restricted" and not restrictions:
        raise InvalidParameter("restrictions: a decision 'restricted' (validated with "
                               "restrictions) must state the restrictions")
    if decision != "restricted" and restrictions:
        raise InvalidParameter(f"restrictions: only the decision 'restricted' takes "
                               f"restrictions (decision is {decision!r})")
    justification = (justification or "").strip()
    contrary = contrary_reason(decision, bool((manifest.get("result") or {}).get("validated")),
                               in_sample)
    if contrary and not justification:
        raise InvalidParameter(f"justification: {contrary}; a decision contrary to the "
                               "objective verdict needs a written justification "
                               "(--justification TEXT)")
    h = evidence_hash(manifest)
    # The id is part of the signed record, so it is chosen before the INSERT, under the
    # audit head's lock that serialises every appender (the audit row below takes it too).
    session.execute(update(AuditHead).where(AuditHead.id == 1).values(seq=AuditHead.seq))
    new_id = int(session.scalar(select(func.coalesce(func.max(Signoff.id), 0))) or 0) + 1
    fields = {"id": new_id, "campaign": campaign, "configuration": config,
                  "username": user.username, "printed_name": user.display_name or user.username,
                  "signed_at_utc": audit.utc_stamp(),
                  "meaning": meaning(decision, campaign, config, h, contrary),
                  "decision": decision,
                  "restrictions": restrictions, "statement": (statement or "").strip(),
                  "justification": justification,
                  "contrary_to_objective": contrary is not None, "evidence_sha256": h,
                  "software_version": software_version}
    key = integrity.signing_key(integrity.session_url(session))
    record_hash = signoff_record_hash(fields)
    so = Signoff(**fields, user_id=user.id, manifest=manifest, record_sha256=record_hash,
                 signature=sign(key, "signoff", canonical_record(fields)),
                 key_fingerprint=key_fingerprint(key.public_key()))
    session.add(so)
    session.flush()
    if session.get_bind().dialect.name == "postgresql":  # keep the serial in step
        session.execute(text("SELECT setval(pg_get_serial_sequence('signoff', 'id'), :v)"),
                        {"v": new_id})
    audit.record(session, user.username, "signoff.create",
                 f"configuration:{campaign}/{config}", None, record_hash,
                 statement[:2000] if statement else "",
                 detail={"signoff": so.id, "decision": decision, "evidence_sha256": h,
                         "contrary_to_objective": contrary is not None})
    return so


def list_signoffs(session: Session, campaign: str | None = None,
                  config: str | None = None) -> list[Signoff]:
    q = select(Signoff).order_by(Signoff.id)
    if campaign is not None:
        q = q.where(Signoff.campaign == campaign)
    if config is not None:
        q = q.where(Signoff.configuration == config)
    return list(session.scalars(q))


def get(session: Session, signoff_id: int) -> Signoff:
    so = session.get(Signoff, int(signoff_id))
    if so is None:
        raise NotFound(f"sign-off {signoff_id} not found")
    return so


def _objective(manifest: dict[str, Any] | None) -> str | None:
    """The objective verdict the sign-off was bound to (from its manifest)."""
    result = (manifest or {}).get("result") or {}
    if "validated" not in result:
        return None
    return "VALIDATED" if result["validated"] else "NOT VALIDATED"


def as_dict(so: Signoff) -> dict[str, Any]:
    """A sign-off as a plain record (bundle export, JSON output), manifest included."""
    return {"id": so.id, "campaign": so.campaign, "configuration": so.configuration,
            "username": so.username, "printed_name": so.printed_name,
            "signed_at_utc": so.signed_at_utc, "meaning": so.meaning, "decision": so.decision,
            "decision_text": DECISIONS.get(so.decision, so.decision),
            "restrictions": so.restrictions, "statement": so.statement,
            "justification": so.justification or "",
            "contrary_to_objective": bool(so.contrary_to_objective),
            "objective_verdict": _objective(so.manifest),
            "evidence_sha256": so.evidence_sha256, "software_version": so.software_version,
            "record_sha256": so.record_sha256, "signature": so.signature,
            "key_fingerprint": so.key_fingerprint, "manifest": so.manifest}
