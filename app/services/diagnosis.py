"""Service: rank the effects missing from a configuration and the vehicle-template
parameters that may be mis-set by the share of its residual they explain on held-out
sections (docs/design.md §7, docs/diagnosis.md, :mod:`railval.core.diagnosis`); the
simulations and the scoring are in :mod:`railval.app.services.diagnosis_ranking`.

The Panel app calls :func:`diagnose` from a background thread with a ``progress(stage,
fraction, info)`` callback; the CLI prints the same callbacks on stderr. The simulations of
the campaign for many candidate effect values run through
:class:`railval.app.services.batch.BatchExecutor` (local process pool, or Dask with
``scheduler="tcp://…"``). Calibration is in :mod:`railval.app.services.calibration`, the
modal identification of [ref 3] in :mod:`railval.app.services.modal`.
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from typing import Any

from railval.app.services.campaign_context import Progress, session_of
from railval.app.services.diagnosis_measurement import MEASUREMENT_PREFIXES
from railval.app.services.diagnosis_ranking import rank_causes, scan_points
from railval.app.services.stored_runs import data_inputs, digests, run_info
from railval.core.diagnosis import PARAMETER_CANDIDATES, DiagnosisResult
from railval.core.diagnosis.lineage import ancestor_entry, lineage_statement
from railval.core.en14363 import PROCESSING_VERSION
from railval.core.sim.effects import EFFECTS, is_neutral
from railval.db import repo, runs

#: version of the diagnosis procedure in the stored runs' digest (with the EN processing
#: version): a change of the procedure computes afresh instead of reusing an older run
DIAGNOSIS_VERSION = f"diagnosis/11+{PROCESSING_VERSION}"  # 3: skipped, causes, families; 4: configuration effects that cannot apply left out, offsets; 5: sign/swap/shift; 6: interface and mass rules; 7: passed-over causes, force gains, track input, contact statement; 8: group offsets, redundancy rule on offsets; 9: a conicity on top never the cause, conicity skipped with measured profiles; 10: runs end at the evaluated range + EN filter run-out, band powers over that span on both sides; 11: the simulator's kernel compiled with floating-point freedoms (values move by rounding)

__all__ = ["DIAGNOSIS_VERSION", "diagnose", "diagnose_and_list", "diagnosis_fit_record", "diagnosis_lineage", "diagnosis_runs", "diagnosis_simulations",
           "latest_diagnosis", "scan_points"]


def diagnosis_simulations(effects: Sequence[str], values_per_parameter: int = 3,
                          template: str | None = None, parameters: bool | int = True, refine: int = 3) -> int:
    """How many campaign simulations :func:`diagnose` runs for ``effects`` (the configuration
    itself once, plus every distinct scan point of the effects that apply to the vehicle
    ``template``, plus one per template parameter candidate (``parameters``: all of the
    template's, or that many) and at most ``refine`` refinements): shown before a user starts it."""
    n_par = len(PARAMETER_CANDIDATES.get(template or "coach", {})) if parameters is True else int(parameters)
    n = 1 + (n_par + min(refine, n_par) if n_par else 0)
    for e in effects:
        if template and template not in EFFECTS[e].templates:
            continue
        n += len({json.dumps(point, sort_keys=True)
                  for _, _, point, _ in scan_points(EFFECTS[e], values_per_parameter)
                  if not is_neutral(EFFECTS[e], point)})  # neutral points reuse the configuration's run
    return n


def diagnose(database_or_session: Any, campaign: repo.CampaignArg, config: repo.ConfigArg, *,
             progress: Progress | None = None, scheduler: Any = None, values_per_parameter: int = 3,
             effects: Sequence[str] | None = None, workers: int | None = None, refresh: bool = False,
             store: bool = True, actor: str = "", **options: Any) -> DiagnosisResult:
    """Rank the causes of the residual of configuration ``config``: the effects it lacks and
    the vehicle-template parameters that may be mis-set, by the share of the residual they
    explain on held-out sections, with noise floor, plausibility, identifiability and a
    verdict (:func:`railval.app.services.diagnosis_ranking.rank_causes`). ``effects``: candidate
    names — effect ids and ``model.NAME`` parameters; given without any ``model.`` name, only
    those effects are tried. ``campaign``/``config``: names (resolved here once, the entrance)
    or the references of :func:`railval.db.repo.resolve`.

    A stored run with the same inputs (signal content hashes of both sides, section records,
    configuration, candidates, ``values_per_parameter``, options, :data:`DIAGNOSIS_VERSION`)
    is returned without simulating unless ``refresh``; every computed run is stored
    (``store``). ``result.run`` describes the stored run
    (:func:`railval.app.services.stored_runs.run_info`)."""
    return _diagnose(database_or_session, campaign, config, progress=progress, scheduler=scheduler,
                     values_per_parameter=values_per_parameter, effects=effects, workers=workers,
                     refresh=refresh, store=store, actor=actor, options=options)[0]


def diagnose_and_list(database_or_session: Any, campaign: repo.CampaignArg, config: repo.ConfigArg,
                      **kw: Any) -> tuple[DiagnosisResult, list[dict[str, Any]]]:
    """:func:`diagnose` and then the stored diagnoses of ``config`` (:func:`diagnosis_runs`),
    the names resolved once for both: what the Diagnose page's "Run diagnosis" shows."""
    known = ("progress", "scheduler", "values_per_parameter", "effects", "workers", "refresh", "store", "actor")
    args = {k: kw.pop(k) for k in known if k in kw}
    args.setdefault("values_per_parameter", 3)
    res, listed = _diagnose(database_or_session, campaign, config, **{
        "progress": None, "scheduler": None, "effects": None, "workers": None, "refresh": False, "store": True,
        "actor": "", **args}, options=kw, listed=True)
    return res, listed or []


def _diagnose(database_or_session: Any, campaign: repo.CampaignArg, config: repo.ConfigArg, *,
              progress: Progress | None, scheduler: Any, values_per_parameter: int,
              effects: Sequence[str] | None, workers: int | None, refresh: bool, store: bool, actor: str,
              options: dict[str, Any], listed: bool = False) -> tuple[DiagnosisResult, list | None]:
    """:func:`diagnose` from the entrance on: the names resolved once into references, the
    digest inputs hashed once; with ``listed`` also the stored runs (:func:`diagnosis_runs`)."""
    settings = {"values_per_parameter": int(values_per_parameter),
                "effects": sorted(effects) if effects is not None else None,
                "options": {k: options[k] for k in sorted(options)}}
    with session_of(database_or_session) as s:
        camp, ref = repo.resolve(s, campaign, config)  # the entrance: the one lookup of each name
        data_sha, inputs_sha = digests(data_inputs(s, camp, ref), settings, DIAGNOSIS_VERSION)
        stored = None if refresh else runs.latest_run(s, ref.id, "diagnosis", inputs_sha)
        if stored is not None:
            res = DiagnosisResult.from_dict(stored.result)
            res.run = run_info(stored, reused=True, current_data_sha256=data_sha)
            res.lineage = diagnosis_lineage(s, camp, ref, res.to_dict(with_signatures=True))
            if progress is not None:
                progress("done", 1.0, {"stored_run": stored.id})
            return res, diagnosis_runs(s, camp, ref, data_sha=data_sha) if listed else None
    started = time.perf_counter()
    if effects is not None:
        names = list(effects)
        params = [n for n in names if n.startswith("model.")]
        options.setdefault("parameters", params or None)
        options.setdefault("include_parameters", bool(params))
        options.setdefault("measurement", [n for n in names if n.startswith(MEASUREMENT_PREFIXES)] or False)
        effects = [n for n in names if not n.startswith(("model.", *MEASUREMENT_PREFIXES))]
    res = rank_causes(database_or_session, camp, ref, progress=progress, scheduler=scheduler,
                                    values_per_parameter=values_per_parameter, effects=effects, workers=workers,
                                    **options)
    if store:
        with session_of(database_or_session, write=True) as s:  # the write door
            row = runs.store_run(s, campaign_id=camp.id, configuration_id=ref.id, kind="diagnosis",
                                 inputs_sha256=inputs_sha,
                                 settings={**settings, "data_sha256": data_sha, "version": DIAGNOSIS_VERSION},
                                 result=res.to_dict(with_signatures=True),
                                 seconds=time.perf_counter() - started, actor=actor)
            res.run = run_info(row, reused=False, current_data_sha256=data_sha)
    with session_of(database_or_session) as s:
        res.lineage = diagnosis_lineage(s, camp, ref, res.to_dict(with_signatures=True))
        return res, diagnosis_runs(s, camp, ref, data_sha=data_sha) if listed else None


def _diagnosis_before(session: Any, conf: Any, before: Any = None) -> Any:
    """The newest stored diagnosis of ``conf`` made before ``before`` (the child's creation:
    the diagnosis the calibration started from), else the newest one; None when never diagnosed."""
    rows = runs.list_runs(session, conf.id, "diagnosis")
    if before is not None:
        for r in rows:
            if r.created_at is not None and r.created_at <= before:
                return r
    return rows[0] if rows else None


def diagnosis_lineage(session: Any, campaign: repo.CampaignArg, config: repo.ConfigArg, result: dict[str, Any]) -> dict[str, Any] | None:
    """The lineage of diagnoses of ``config`` (None for a configuration without a parent):
    ``ancestors`` — every configuration from the root to ``config``'s parent with its diagnosis
    (run id, verdict, top cause) — and, for a configuration fitted by a calibration or a
    diagnosis (``Configuration.calibration``), ``statement``: what is left of the parent's
    residual and whether the library explains it (:func:`lineage_statement`); ``result`` is
    ``config``'s diagnosis as a dict."""
    chain = repo.lineage(session, campaign, config)
    if len(chain) < 2:
        return None
    conf, parent = chain[-1], chain[-2]
    ancestors = []
    for i, c in enumerate(chain[:-1]):
        row = _diagnosis_before(session, c, chain[i + 1].created_at)
        ancestors.append(ancestor_entry(c.name, row.id if row is not None else None,
                                        row.result if row is not None else None,
                                        row.created_at.isoformat(timespec="seconds") if row is not None
                                        and row.created_at else ""))
    out: dict[str, Any] = {"configuration": conf.name, "parent": parent.name, "ancestors": ancestors,
                           "statement": None}
    rec = conf.calibration or {}
    if rec.get("parameters"):
        names = list(rec["parameters"])
        values = {}
        for n in names:
            owner, _, par = n.partition(".")
            src = (conf.parameters or {}) if owner == "model" else ((conf.effects or {}).get(owner) or {})
            if par in src:
                values[n] = src[par]
        prow = _diagnosis_before(session, parent, conf.created_at)
        out["statement"] = lineage_statement(result, prow.result if prow is not None else None,
                                             parent_configuration=parent.name,
                                             parent_run=prow.id if prow is not None else None,
                                             fitted=names, fitted_values=values)
    return out


def diagnosis_runs(session: Any, campaign: repo.CampaignArg, config: repo.ConfigArg, *,
                   data_sha: str | None = None) -> list[dict[str, Any]]:
    """Stored diagnoses of ``config``, newest first: :func:`run_info` plus the top candidate,
    the share it explains, whether the two best are told apart and the run's verdict
    (``cause`` / ``uncertain`` / ``none``); ``current`` is false
    when the signals or sections changed since the run (``data_sha``: the digest of the
    current data when the caller has it, else computed here)."""
    camp, ref = repo.resolve(session, campaign, config)
    if data_sha is None:
        data_sha, _ = digests(data_inputs(session, camp, ref), {}, DIAGNOSIS_VERSION)
    out = []
    for r in runs.list_runs(session, ref.id, "diagnosis"):
        cands = (r.result or {}).get("candidates") or []
        out.append({**run_info(r, reused=True, current_data_sha256=data_sha),
                    "top": cands[0]["effect"] if cands else "",
                    "explained": cands[0]["explained"] if cands else None,
                    "separable": bool((r.result or {}).get("separable", True)),
                    "verdict": (r.result or {}).get("verdict")})
    return out


def latest_diagnosis(session: Any, campaign: repo.CampaignArg, config: repo.ConfigArg) -> DiagnosisResult | None:
    """The newest stored diagnosis of ``config`` (any settings), ``run`` saying
    whether its data are still current; None when never diagnosed."""
    camp, ref = repo.resolve(session, campaign, config)
    row = runs.latest_run(session, ref.id, "diagnosis")
    if row is None:
        return None
    data_sha, _ = digests(data_inputs(session, camp, ref), {}, DIAGNOSIS_VERSION)
    res = DiagnosisResult.from_dict(row.result)
    res.run = run_info(row, reused=True, current_data_sha256=data_sha)
    res.lineage = diagnosis_lineage(session, camp, ref, row.result)
    return res



def diagnosis_fit_record(database_or_session: Any, campaign: str, config: str, effect: str,
                         parameters: dict[str, float]) -> dict[str, Any] | None:
    """The provenance to store with a configuration made by adding ``effect`` to ``config``
    with ``parameters`` (``Configuration.calibration``), when any of those values is one the
    newest stored diagnosis of ``config`` fitted (on every section of the campaign): then the
    new configuration's verdict is in-sample like a calibration's on all sections
    (:func:`railval.app.services.validation.calibration_provenance`). ``model.NAME``
    candidates: ``parameters`` holds ``NAME``. None when no value came from the diagnosis
    (set by hand, or no diagnosis)."""
    with session_of(database_or_session) as s:
        camp, conf = repo.resolve(s, campaign, config)
        row = runs.latest_run(s, conf.id, "diagnosis")
        cands = ((row.result or {}).get("candidates") or []) if row is not None else []
        cand = next((c for c in cands if effect in (c.get("effect"), c.get("name"))), None)
        if cand is None:
            return None
        fitted = ({effect[6:]: cand.get("fitted")} if effect.startswith("model.")
                  else dict(cand.get("parameters") or {}))
        same = sorted(k for k, v in parameters.items()
                      if fitted.get(k) is not None and abs(float(v) - float(fitted[k]))
                      <= 1e-9 * max(1.0, abs(float(fitted[k]))))
        if not same:
            return None
        sections = [sec.id for sec in repo.section_infos(s, camp)]
        owner = "model" if effect.startswith("model.") else effect
        return {"fit_sections": sections, "held_out_sections": [], "fitted_by": "diagnosis",
                "diagnosis_run": row.id, "parameters": [f"{owner}.{k}" for k in same]}
