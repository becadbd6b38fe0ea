"""Service: rank the effects missing from a configuration by the share of its residual they
explain (docs/design.md §7, :mod:`railval.core.diagnosis`).

The Panel app calls :func:`diagnose` from a background thread with a ``progress(stage,
fraction, info)`` callback; the CLI prints the same callbacks on stderr. The simulations of
the campaign for many candidate effect values run through
:class:`railval.app.services.batch.BatchExecutor` (local process pool, or Dask with
``scheduler="tcp://…"``). Calibration is in :mod:`railval.app.services.calibration`, the
modal identification of [ref 3] in :mod:`railval.app.services.modal`.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Iterator, Sequence
from typing import Any

from railval.app.services.batch import BatchExecutor
from railval.app.services.campaign_context import (
    Progress,
    band_sums,
    configuration_of,
    effect_parameters,
    evaluate_effects,
    load_context,
    report,
    residual_pattern,
    section_values,
    session_of,
)
from railval.app.services.stored_runs import data_inputs, digests, run_info
from railval.core.diagnosis import DiagnosisResult, ParameterScan, diagnose_patterns, scan_values
from railval.core.en14363 import PROCESSING_VERSION
from railval.core.errors import InvalidParameter
from railval.core.sim.effects import EFFECTS, Effect
from railval.db import repo, runs

#: version of the diagnosis procedure in the stored runs' digest (with the EN processing
#: version): a change of the procedure computes afresh instead of reusing an older run
DIAGNOSIS_VERSION = f"diagnosis/1+{PROCESSING_VERSION}"


def scan_points(effect: Effect, values_per_parameter: int) -> Iterator[tuple[str, float, dict[str, float], dict]]:
    """The one-parameter scan of an effect: for each parameter and each of its
    :func:`railval.core.diagnosis.scan_values`, ``(parameter, value, all parameters at default
    but this one, its bounds record)``."""
    params = effect_parameters(effect)
    defaults = {k: float(v["default"]) for k, v in params.items()}
    for pname, p in params.items():
        for v in scan_values(p["lower"], p["upper"], p["default"], values_per_parameter, p["log"]):
            yield pname, v, {**defaults, pname: v}, p


def diagnosis_simulations(effects: Sequence[str], values_per_parameter: int = 3,
                          template: str | None = None) -> int:
    """How many campaign simulations :func:`diagnose` runs for ``effects`` (the configuration
    itself once, plus every distinct scan point of the effects that apply to the vehicle
    ``template``): shown before a user starts it."""
    n = 1
    for e in effects:
        if template and template not in EFFECTS[e].templates:
            continue
        n += len({json.dumps(point, sort_keys=True)
                  for _, _, point, _ in scan_points(EFFECTS[e], values_per_parameter)})
    return n


def diagnose(database_or_session: Any, campaign: str, config: str, *, progress: Progress | None = None,
             scheduler: Any = None, values_per_parameter: int = 3, effects: Sequence[str] | None = None,
             workers: int | None = None, refresh: bool = False, store: bool = True,
             actor: str = "") -> DiagnosisResult:
    """Rank the effects missing from configuration ``config`` by the share of its residual
    they explain (:mod:`railval.core.diagnosis`). Each candidate effect parameter is simulated at
    ``values_per_parameter`` values over its bounds (plus its default) on the whole campaign.

    A stored run with the same inputs (signal content hashes of both sides, section records,
    configuration, candidate effects, ``values_per_parameter``, :data:`DIAGNOSIS_VERSION`) is
    returned without simulating unless ``refresh``; every computed run is stored (``store``).
    ``result.extra["run"]`` describes the stored run (:func:`railval.app.services.stored_runs.run_info`)."""
    report(progress, "load", 0.0, campaign=campaign, config=config)
    registry = EFFECTS
    unknown = [e for e in (effects or ()) if e not in registry]
    if unknown:
        raise InvalidParameter(f"unknown effect(s) {unknown}; known: {sorted(registry)}")
    with session_of(database_or_session) as s:
        ctx = load_context(s, campaign)
        conf_effects, conf_params, conf_row = configuration_of(s, campaign, config)
        template = str(ctx.vehicle.get("template") or "coach")
        todo = [e for e in (effects or registry) if e not in conf_effects
                and template in registry[e].templates]
        settings = {"values_per_parameter": int(values_per_parameter), "effects": sorted(todo)}
        data_sha, inputs_sha = digests(data_inputs(s, campaign, config), settings, DIAGNOSIS_VERSION)
        stored = None if refresh else runs.latest_run(s, conf_row.id, "diagnosis", inputs_sha)
        if stored is not None:
            res = DiagnosisResult.from_dict(stored.result)
            res.extra["run"] = run_info(stored, reused=True, current_data_sha256=data_sha)
            report(progress, "done", 1.0, stored_run=stored.id)
            return res
        config_sets = repo.load_signalsets(s, campaign, config)
        ids = (conf_row.campaign_id, conf_row.id)
    started = time.perf_counter()
    stored_residual, vr = residual_pattern(ctx, section_values(config_sets, ctx.sections), band_sums(config_sets, ctx.bands))
    # the configuration itself is re-simulated so that its residual and the scanned patterns
    # come from the same simulator run settings (signatures are differences of the two)
    tasks, index, unique = [(ctx, conf_effects, conf_params)], [], {}
    for e in todo:
        defaults = {k: float(q["default"]) for k, q in effect_parameters(registry[e]).items()}
        for pname, v, point, p in scan_points(registry[e], values_per_parameter):
            eff = {**conf_effects, e: point}
            key = json.dumps(eff, sort_keys=True)
            if key not in unique:  # the all-defaults point of a multi-parameter effect once
                unique[key] = len(tasks)
                tasks.append((ctx, eff, conf_params))
            index.append((e, pname, v, defaults, (p["lower"], p["upper"]), p["log"], unique[key]))
    report(progress, "simulate", 0.05, tasks=len(tasks))
    with BatchExecutor(scheduler, workers) as ex:
        results = ex.map(evaluate_effects, tasks,
                         progress=lambda d, t: report(progress, "simulate", 0.05 + 0.9 * d / t, done=d, total=t))
    scans: dict[str, dict[str, ParameterScan]] = {}
    residual, _ = residual_pattern(ctx, *results[0])
    for e, pname, v, defaults, bounds, log, k in index:
        pat, _ = residual_pattern(ctx, *results[k])
        sc = scans.setdefault(e, {}).setdefault(pname, ParameterScan(e, pname, [], [], defaults, bounds, log))
        sc.values.append(v)
        sc.patterns.append(pat)
    explanations = {e: registry[e].explanation for e in todo}
    res = diagnose_patterns(residual, {e: list(d.values()) for e, d in scans.items()}, explanations=explanations)
    res.extra.update({"campaign": ctx.campaign, "configuration": config, "validated": bool(vr.validated),
                      "effects_in_configuration": sorted(conf_effects),
                      "values_per_parameter": values_per_parameter, "simulations": len(tasks),
                      "stored_residual_norm": math.sqrt(stored_residual.norm2()),
                      "simulated_residual_norm": math.sqrt(residual.norm2())})
    if store:
        with session_of(database_or_session) as s:
            row = runs.store_run(s, campaign_id=ids[0], configuration_id=ids[1], kind="diagnosis",
                                 inputs_sha256=inputs_sha,
                                 settings={**settings, "data_sha256": data_sha,
                                           "version": DIAGNOSIS_VERSION},
                                 result=res.to_dict(with_signatures=True),
                                 seconds=time.perf_counter() - started, actor=actor)
            res.extra["run"] = run_info(row, reused=False, current_data_sha256=data_sha)
    report(progress, "done", 1.0)
    return res


def diagnosis_runs(session: Any, campaign: str, config: str) -> list[dict[str, Any]]:
    """Stored diagnoses of ``config``, newest first: :func:`run_info` plus the top candidate,
    the share it explains and whether the two best are told apart; ``current`` is false
    when the signals or sections changed since the run."""
    conf = repo.get_configuration(session, campaign, config)
    data_sha, _ = digests(data_inputs(session, campaign, config), {}, DIAGNOSIS_VERSION)
    out = []
    for r in runs.list_runs(session, conf.id, "diagnosis"):
        cands = (r.result or {}).get("candidates") or []
        out.append({**run_info(r, reused=True, current_data_sha256=data_sha),
                    "top": cands[0]["effect"] if cands else "",
                    "explained": cands[0]["explained"] if cands else None,
                    "separable": bool((r.result or {}).get("separable", True))})
    return out


def latest_diagnosis(session: Any, campaign: str, config: str) -> DiagnosisResult | None:
    """The newest stored diagnosis of ``config`` (any settings), ``extra["run"]`` saying
    whether its data are still current; None when never diagnosed."""
    conf = repo.get_configuration(session, campaign, config)
    row = runs.latest_run(session, conf.id, "diagnosis")
    if row is None:
        return None
    data_sha, _ = digests(data_inputs(session, campaign, config), {}, DIAGNOSIS_VERSION)
    res = DiagnosisResult.from_dict(row.result)
    res.extra["run"] = run_info(row, reused=True, current_data_sha256=data_sha)
    return res

