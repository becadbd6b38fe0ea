"""Independent sign-off of a configuration's validation, bound to its evidence (docs/audit.md).

The **evidence manifest** of a configuration is one JSON document holding

* ``measurement`` and ``simulation``: section → channel → SHA-256 content hash of every
  stored signal of both sides (and of each distance axis),
* ``configuration``: parent, lineage, effects and parameters of the configuration,
* ``sections`` and ``vehicle``: the campaign records the processing reads (evaluated range,
  radius, speed, zone; vehicle kind and static wheel load),
* ``processing``: the EN 14363 processing version and settings (filter order, bootstrap
  size and seed),
* ``result``: the validation result — per quantity the values, limits and verdict — as
  computed for the signature,
* ``software_version``: the railval version that computed it.

Its **evidence hash** is SHA-256 over its canonical JSON
(:func:`railval.core.integrity.evidence_hash`). A sign-off stores both; it is *valid* while
the manifest rebuilt from the database today has the same hash, and *stale* otherwise
(21 CFR 11.70: the signature cannot be moved to other evidence). The quick status
(:func:`status`, used by pages, lists and the report) rebuilds everything except the result;
``full=True`` (``railval audit verify``) recomputes the validation too.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from importlib.metadata import PackageNotFoundError, version
from typing import Any
from urllib.parse import urlencode

import numpy as np
from sqlalchemy.orm import Session

from railval.core import lazy
from railval.core.errors import InvalidParameter, NotFound, RailvalError
from railval.core.integrity import (
    apply_rotations,
    evidence_hash,
    head_message,
    signoff_record,
    signoff_record_hash,
    verify_signature,
)
from railval.core.processing import DEFAULT_ORDER, PROCESSING_VERSION
from railval.core.roles import PermissionDenied, require
from railval.db import audit, integrity, repo, trust, users
from railval.db import signoff as db_signoff
from railval.db.models import Signoff

#: deferred (railval.core.lazy): validation, diagnosis and the view model (numba, scipy:
#: up to ~890 more modules), sign-in and the workshop tables only for the requests that
#: reach them, not for `railval signoff list`
validate_configuration = lazy.function("railval.app.services.validation", "validate_configuration")
sessions = lazy.module("railval.app.services.sessions")
calibration_provenance = lazy.function("railval.app.services.validation", "calibration_provenance")
diagnosis_runs = lazy.function("railval.app.services.diagnosis", "diagnosis_runs")
InSample = lazy.function("railval.app.views", "InSample")
wsdb = lazy.module("railval.db.workshops")

SCHEMA = "railval-evidence/1"
#: the processing settings a sign-off is computed with (the defaults of ``railval validate``)
SETTINGS: dict[str, Any] = {"filter_order": DEFAULT_ORDER, "n_boot": 1000, "seed": 0}
_INPUT_KEYS = ("schema", "campaign", "configuration", "measurement", "simulation",
               "configuration_record", "sections", "vehicle", "processing", "software_version")


def software_version() -> str:
    try:
        return version("railval")
    except PackageNotFoundError:  # pragma: no cover - always installed in this project
        return "unknown"


def _plain(obj: Any) -> Any:
    """JSON-clean copy: numpy scalars → Python, non-finite floats → their repr string."""
    def default(v):
        if isinstance(v, np.generic):
            return v.item()
        if isinstance(v, np.ndarray):
            return v.tolist()
        raise TypeError(f"not JSON serialisable: {type(v).__name__}")

    return repo._jsonable(json.loads(json.dumps(obj, default=default)))


def input_manifest(session: Session, campaign: str, config: str,
                   settings: dict[str, Any] | None = None) -> dict[str, Any]:
    """The manifest without the validation result (cheap: no blob is read)."""
    settings = {**SETTINGS, **(settings or {})}
    camp = repo.get_campaign(session, campaign)
    conf = repo.get_configuration(session, camp, config)
    chain = repo.lineage(session, camp, conf.name)
    sections = [
        {"id": s.id, "radius_m": s.radius_m, "cant_mm": s.cant_mm, "speed_kmh": s.speed_kmh,
         "zone": int(s.zone), "eval_start_m": s.eval_start_m, "eval_end_m": s.eval_end_m,
         "curve_direction": s.curve_direction}
        for s in repo.section_infos(session, camp)
    ]
    return _plain({
        "schema": SCHEMA,
        "campaign": camp.name,
        "configuration": conf.name,
        "measurement": repo.source_hashes(session, camp, None),
        "simulation": repo.source_hashes(session, camp, conf.name),
        "configuration_record": {
            "parent": chain[-2].name if len(chain) > 1 else None,
            "lineage": [c.name for c in chain],
            "effects": conf.effects or {}, "parameters": conf.parameters or {},
        },
        "sections": sections,
        "vehicle": repo.vehicle_info(session, camp),
        "processing": {"version": PROCESSING_VERSION, **settings},
        "software_version": software_version(),
    })


def validation_result(session: Session, campaign: str, config: str,
                      settings: dict[str, Any] | None = None) -> dict[str, Any]:
    """The validation result (values, limits, verdict) as it enters the manifest."""

    settings = {**SETTINGS, **(settings or {})}
    res = validate_configuration(session, campaign, config,
                                 order=settings["filter_order"], n_boot=settings["n_boot"],
                                 seed=settings["seed"])
    d = res.to_dict()
    d.pop("info", None)
    return _plain(d)


def evidence_manifest(session: Session, campaign: str, config: str,
                      settings: dict[str, Any] | None = None) -> dict[str, Any]:
    """The complete evidence manifest (runs the validation, from the result cache if warm)."""
    m = input_manifest(session, campaign, config, settings)
    m["result"] = validation_result(session, m["campaign"], m["configuration"], settings)
    return m


# -- status ------------------------------------------------------------------------------
@dataclass
class SignoffStatus:
    """``valid`` while the evidence is unchanged, else ``stale`` with the reasons."""

    signoff_id: int
    status: str
    reasons: list[str] = field(default_factory=list)
    current_sha256: str | None = None

    @property
    def valid(self) -> bool:
        return self.status == "valid"

    def to_dict(self) -> dict[str, Any]:
        return {"signoff": self.signoff_id, "status": self.status, "reasons": self.reasons,
                "current_evidence_sha256": self.current_sha256}


def _short(h: Any) -> str:
    return str(h)[:12] + "…" if isinstance(h, str) and len(h) == 64 else json.dumps(h)[:80]


#: relative tolerance of a recomputed validation result against the signed one: the inputs
#: (content hashes, processing, configuration) are compared exactly; the result is recomputed
#: from them, and another numpy/scipy build may sum in another order (the last one or two of
#: the 16 digits of a float64; IEEE 754 addition is not associative) — such a result is the
#: same evidence, a difference beyond 1e-9 is not
RESULT_REL_TOL = 1e-9


def same_numbers(a: Any, b: Any, rel_tol: float = RESULT_REL_TOL) -> bool:
    """``a`` and ``b`` (JSON values) equal, with numbers equal within ``rel_tol`` relative
    (``math.isclose``, absolute 1e-12 near zero); keys, lengths, strings, booleans and None exact."""
    if isinstance(a, bool) or isinstance(b, bool) or a is None or b is None:
        return type(a) is type(b) and a == b
    if isinstance(a, int) and isinstance(b, int):  # counts (n, sections): exact
        return a == b
    if isinstance(a, int | float) and isinstance(b, int | float):
        return math.isclose(a, b, rel_tol=rel_tol, abs_tol=1e-12) or (a != a and b != b)
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same_numbers(a[k], b[k], rel_tol) for k in a)
    if isinstance(a, list | tuple) and isinstance(b, list | tuple):
        return len(a) == len(b) and all(same_numbers(x, y, rel_tol) for x, y in zip(a, b))
    return a == b


def manifest_differences(signed: dict[str, Any], now: dict[str, Any], *,
                         keys: tuple[str, ...] | None = None, limit: int = 5) -> list[str]:
    """Readable differences between two manifests (first ``limit`` per part); the recomputed
    ``result`` is compared within :data:`RESULT_REL_TOL` (:func:`same_numbers`), the inputs exactly."""
    out: list[str] = []
    for key in keys or tuple(sorted(set(signed) | set(now))):
        a, b = signed.get(key), now.get(key)
        if a == b or (key == "result" and same_numbers(a, b)):
            continue
        if key in ("measurement", "simulation") and isinstance(a, dict) and isinstance(b, dict):
            n = 0
            for sid in sorted(set(a) | set(b)):
                ca, cb = a.get(sid) or {}, b.get(sid) or {}
                for ch in sorted(set(ca) | set(cb)):
                    if ca.get(ch) != cb.get(ch) and n < limit:
                        out.append(f"{key} section {sid} {ch}: signed {_short(ca.get(ch))}, "
                                   f"now {_short(cb.get(ch))}")
                        n += 1
        elif isinstance(a, dict) and isinstance(b, dict):
            for sub in sorted(set(a) | set(b)):
                if a.get(sub) != b.get(sub):
                    out.append(f"{key}.{sub}: signed {json.dumps(a.get(sub))[:120]}, "
                               f"now {json.dumps(b.get(sub))[:120]}")
        else:
            out.append(f"{key}: signed {json.dumps(a)[:120]}, now {json.dumps(b)[:120]}")
    return out


def _server_keys(session: Session):
    """The keys the server trusts (pins or ``$RAILVAL_TRUST_ANCHOR_FILE``, extended by the
    trail's ``key.rotate`` rows), once per unit of work; ``None``: no trust anchor here."""
    if "railval_trusted_keys" not in session.info:
        rows = {int(r["seq"]): r for r in audit.key_rows(session)}
        ring, how, _found = trust.server_ring(integrity.session_url(session), rows)
        session.info["railval_trusted_keys"] = (
            None if how in ("none", "first use") else apply_rotations(ring, rows))
    return session.info["railval_trusted_keys"]


def _unsigned_problem(session: Session, so: Signoff, keys) -> str | None:
    """An unsigned sign-off holds only when a signed ``audit.seal`` row (verified with a
    trusted key) binds its record hash (written before signing was enabled, then sealed)."""
    if "railval_seals" not in session.info:
        session.info["railval_seals"] = list(audit.iter_rows(session, action="audit.seal"))
    want = signoff_record_hash(db_signoff.as_dict(so))
    for r in session.info["railval_seals"]:
        bound = ((r.get("detail") or {}).get("unsigned_signoffs") or {}).get(str(so.id))
        pk = (keys or {}).get(str(r.get("key_fingerprint")))
        if bound == want and pk is not None and verify_signature(
                pk, "audit-head", head_message(int(r["seq"]), r["row_hash"]), r["signature"]):
            return None
    return ("unsigned, and no signed seal binds its record: it was written or edited "
            "outside railval, or before signing and never sealed (`railval audit verify`)")


def _signature_problem(session: Session, so: Signoff) -> str | None:
    """Why the sign-off's signature does not hold with a key the server trusts (``None``:
    it holds). A key that is not pinned (a replaced key file, a ``.retired`` file) or no
    trust anchor at all never makes it valid."""
    keys = _server_keys(session)
    fp = str(so.key_fingerprint)
    if not so.signature:
        return _unsigned_problem(session, so, keys)
    if keys is None:
        return ("its signature cannot be checked here: no trust anchor for this database "
                "(no pin in the server's configuration directory, no "
                "$RAILVAL_TRUST_ANCHOR_FILE); run `railval audit verify` on the server, or "
                "with --public-key")
    pk = keys.get(fp)
    if pk is None:
        return (f"signed by a key that is not trusted (fingerprint {fp[:16]}…; trusted: "
                + ", ".join(k[:16] + "…" for k in keys) + ")")
    if not verify_signature(pk, "signoff", signoff_record(db_signoff.as_dict(so)),
                            so.signature):
        return ("the sign-off's record does not match its signature: it was edited "
                "outside railval (run `railval audit verify`)")
    return None


def status(session: Session, so: Signoff, *, full: bool = False,
           check_signature: bool = True) -> SignoffStatus:
    """Is the sign-off still bound to the current evidence, signed by a trusted key?
    (``full``: recompute the result; ``check_signature=False``: the caller checked the
    signature already, as ``railval audit verify`` does with its own trust.)"""
    reasons: list[str] = []
    stored = dict(so.manifest or {})
    problem = _signature_problem(session, so) if check_signature else None
    if problem:
        reasons.append(problem)
    if evidence_hash(stored) != so.evidence_sha256:
        reasons.append(f"stored manifest does not hash to the signed evidence hash "
                       f"{so.evidence_sha256} (found {evidence_hash(stored)})")
    settings = dict(stored.get("processing") or {})
    settings.pop("version", None)
    try:
        now = input_manifest(session, so.campaign, so.configuration, settings)
        if full:
            now["result"] = validation_result(session, so.campaign, so.configuration, settings)
    except NotFound as exc:
        return SignoffStatus(so.id, "stale", reasons + [f"evidence no longer exists: {exc}"])
    keys = None if full else _INPUT_KEYS
    reasons += manifest_differences(stored, now, keys=keys)
    current = evidence_hash(now) if full else None
    return SignoffStatus(so.id, "stale" if reasons else "valid", reasons, current)


def statuses(session: Session, campaign: str | None = None, config: str | None = None
             ) -> list[tuple[Signoff, SignoffStatus]]:
    """Every sign-off (optionally of one campaign/configuration) with its quick status."""
    return [(so, status(session, so)) for so in
            db_signoff.list_signoffs(session, campaign, config)]


# -- signing -----------------------------------------------------------------------------
class SignoffRefused(RailvalError):
    """The password did not match, the role is missing or the signer is not independent."""


def independence_problem(session: Session, username: str, campaign: str,
                         config: str) -> str | None:
    """Why ``username`` is not independent of the configuration (stored or replaced it)."""
    for row in audit.iter_rows(session, actor=username,
                               object=f"configuration:{campaign}/{config}"):
        if row["action"] in ("configuration.store", "configuration.replace"):
            return (f"{username} stored configuration {config!r} "
                    f"(audit row {row['seq']}, {row['at_utc']}); the sign-off must come "
                    "from an independent reviewer")
    return None


def sign(database, username: str, password: str, campaign: str, config: str, *,
         decision: str, restrictions: str = "", statement: str = "", justification: str = "",
         source: str = "") -> dict:
    """Verify the password again (21 CFR 11.200(a)(1)), check role and independence, build
    the evidence manifest and append the sign-off; returns it as a record.

    A decision contrary to the objective verdict (:func:`railval.db.signoff.contrary_reason`)
    is refused without ``justification`` and stored marked ``contrary_to_objective``.

    A wrong password is recorded (``login.failed``) and counts towards the sign-in rate
    limit. Raises :class:`SignoffRefused` or :class:`PermissionDenied`.
    """

    # the one sign-in: the hash is verified outside the write transaction, a failure recorded
    result = sessions.sign_in(database, username, password, source=source or "signoff",
                              record_success=False)
    if not result.ok:
        raise SignoffRefused(f"sign-off refused: {result.message}")
    with database.session(actor=username, write=True) as s:
        user = users.get_user(s, username)
        try:
            require(users.principal(user), "signoff.create")
        except PermissionDenied as exc:
            raise SignoffRefused(f"sign-off refused: {exc}") from None
        camp = repo.get_campaign(s, campaign)
        conf = repo.get_configuration(s, camp, config)
        problem = independence_problem(s, username, camp.name, conf.name)
        if problem:
            raise SignoffRefused(f"sign-off refused: {problem}")
        manifest = evidence_manifest(s, camp.name, conf.name)
        try:
            so = db_signoff.create(s, user=user, campaign=camp.name, config=conf.name,
                                   decision=decision, restrictions=restrictions,
                                   statement=statement, manifest=manifest,
                                   software_version=software_version(),
                                   justification=justification,
                                   in_sample=_in_sample(s, camp, conf.name))
        except InvalidParameter as exc:
            raise SignoffRefused(f"sign-off refused: {exc}") from None
        return db_signoff.as_dict(so)


def _in_sample(session: Session, campaign, config: str) -> bool:
    return bool(calibration_provenance(session, campaign, config)["in_sample"])


# -- what is signed ----------------------------------------------------------------------
#: app pages a signer opens from the summary (``/app?page=…``)
EVIDENCE_PAGES = ("dashboard", "compare", "report", "diagnose")


def signing_summary(session: Session, campaign: str, config: str) -> dict[str, Any]:
    """What a signer sees before the password (the sign-off page and ``signoff create``):
    the objective verdict with its 12 quantities (normalised mean and std against the
    limits), coverage, definition-sensitive and in-sample marks, supplementary results, the
    newest diagnosis run, workshop results on this configuration, earlier sign-offs with
    their status, links to the evidence pages, and per decision whether it would be
    contrary to the objective verdict. Computed with the settings the signature binds
    (:data:`SETTINGS`)."""

    camp, conf = repo.resolve(session, campaign, config)  # once: the references travel on
    res = validate_configuration(session, camp, conf, order=SETTINGS["filter_order"],
                                 n_boot=SETTINGS["n_boot"], seed=SETTINGS["seed"])
    d = _plain({k: v for k, v in res.to_dict().items() if k != "info"})
    info = res.info
    quantities = [{k: q.get(k) for k in ("quantity", "unit", "n", "mean", "std", "mean_limit",
                                         "std_limit", "mean_norm", "std_norm", "pass",
                                         "robust", "definition_sensitive")}
                  for q in d["quantities"]]
    cov = d["coverage"]
    in_sample = bool(info.get("in_sample"))
    ins = InSample.of(info)
    runs = diagnosis_runs(session, camp, conf)
    newest = runs[0] if runs else None
    diagnosis = None if newest is None else {
        "run": newest["id"], "created_at": newest["created_at"], "top": newest["top"],
        "explained": newest["explained"], "separable": newest["separable"],
        "current": newest.get("current"), "verdict": newest["verdict"]}
    so_items = []
    for so, st in statuses(session, camp.name, conf.name):
        rec = db_signoff.as_dict(so)
        so_items.append({k: rec[k] for k in ("id", "decision", "decision_text", "printed_name",
                                             "username", "signed_at_utc", "evidence_sha256",
                                             "contrary_to_objective", "justification")}
                        | {"status": st.status})
    query = {"campaign": camp.name, "configuration": conf.name}
    return {
        "campaign": camp.name, "configuration": conf.name,
        "objective": {
            "validated": bool(d["validated"]),
            "verdict": "VALIDATED" if d["validated"] else "NOT VALIDATED",
            "coverage": {k: cov.get(k) for k in ("ok", "sections", "zones", "shortfalls")},
            "definition_sensitive": d["definitions"]["verdict_sensitive"],
            "sensitive_quantities": d["definitions"]["sensitive_quantities"],
            "in_sample": in_sample, "fit_sections": info.get("fit_sections", []),
            "calibrated_in": info.get("calibrated_in", []),
            "in_sample_note": ins.note() if ins is not None else "",
            "held_out_check": info.get("held_out_check", "") if in_sample else "",
            "std_ddof": d["std_ddof"], "warnings": d["warnings"],
        },
        "quantities": quantities,
        "supplementary": [{k: q.get(k) for k in ("quantity", "name", "unit", "n", "mean",
                                                 "std", "mean_rel", "std_rel")}
                          for q in (d.get("supplementary") or {}).get("quantities", [])],
        "diagnosis": diagnosis,
        "workshops": wsdb.configuration_results(session, camp.id, conf.name),
        "signoffs": so_items,
        "links": {p: f"/app?{urlencode({**query, 'page': p})}" for p in EVIDENCE_PAGES},
        "contrary_if": {dec: db_signoff.contrary_reason(dec, bool(d["validated"]), in_sample)
                        for dec in db_signoff.DECISIONS},
        "settings": dict(SETTINGS),
    }



# -- units of work for the pages and verbs (they reach the database only through these) --
def summary_of(database, campaign: str, config: str) -> dict[str, Any]:
    """:func:`signing_summary` in a unit of work of its own."""
    with database.write_session(deferred=True) as s:  # may fill the result cache
        return signing_summary(s, campaign, config)


def records(database, campaign: str | None = None, config: str | None = None
            ) -> list[tuple[dict[str, Any], SignoffStatus]]:
    """Every sign-off (of ``campaign``, ``configuration`` when given) as its record
    (:func:`railval.db.signoff.as_dict`) with its status, oldest first."""
    with database.write_session(deferred=True) as s:  # may fill the result cache
        return [(db_signoff.as_dict(so), st) for so, st in statuses(s, campaign, config)]


def record(database, signoff_id: int) -> tuple[dict[str, Any], SignoffStatus]:
    """One sign-off's record with its status; :class:`NotFound` for an unknown id."""
    with database.write_session(deferred=True) as s:  # may fill the result cache
        so = db_signoff.get(s, signoff_id)
        st = status(s, so)
        return db_signoff.as_dict(so), st
