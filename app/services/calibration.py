"""Service: add effects (or template-parameter candidates ``model.NAME``) to a configuration,
fit their parameters to the validation objective — on all sections or on a split, with the
held-out sections validated apart — and store the result as a new configuration with the
sections the fit used (docs/design.md §7, docs/diagnosis.md, :mod:`railval.core.calibration`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from railval.app.services.batch import BatchExecutor
from railval.app.services.calibration_plan import (
    calibration_simulations,
    diagnosis_flags,
    diagnosis_start,
)
from railval.app.services.campaign_context import (
    CampaignContext,
    Progress,
    configuration_of,
    effect_parameters,
    evaluate_effects,
    load_context,
    report,
    runnable_effects,
    section_values,
    session_of,
    simulate_context,
    validate_values,
)
from railval.app.services.diagnosis_ranking import parameter_plan, plausible_range, template_param
from railval.core.calibration import (
    COACH_MODAL_DEFAULTS,
    COACH_MODAL_PARAMETERS,
    CalibrationResult,
    ParameterSpec,
    validation_objective,
    validation_residuals,
)
from railval.core.calibration import calibrate as fit_parameters
from railval.core.calibration_local import calibrate_local
from railval.core.diagnosis import plausibility_flags, zone_folds
from railval.core.errors import InvalidParameter, InvalidSignal
from railval.core.sim.effects import EFFECTS, unmet_requirement
from railval.core.validation import normalised_errors, validate
from railval.db import repo


class _Objective:
    """Validation objective of a parameter vector (picklable; evaluated in the workers)."""

    def __init__(self, ctx: CampaignContext, base_effects: dict, base_params: dict, targets: list[tuple[str, str]]):
        self.ctx, self.base_effects, self.base_params, self.targets = ctx, base_effects, base_params, targets

    def split(self, params: Mapping[str, float]) -> tuple[dict, dict]:
        effects = {k: dict(v) for k, v in self.base_effects.items()}
        model = dict(self.base_params)
        for (owner, pname), key in zip(self.targets, params, strict=True):
            if owner == "model":
                model[pname] = float(params[key])
            else:
                effects.setdefault(owner, {})[pname] = float(params[key])
        return effects, model

    def residuals(self, params: Mapping[str, float]) -> np.ndarray:
        """Residual vector r_q = max(|mean_norm_q|, std_norm_q) of the DynoTRAIN quantities
        (:func:`railval.core.calibration.validation_residuals`; Σ r² is the objective below);
        ``inf`` entries where the simulation diverges (a channel holds non-finite values),
        which the search treats as its worst point (core.calibration penalty) instead of
        aborting the whole calibration — observed for the coach with track_flexibility at
        k_vertical 300 MN/m and k_lateral ≤ 2 MN/m (docs/diagnosis.md "The hidden-effect test")."""
        effects, model = self.split(params)
        try:
            vals, _ = evaluate_effects((self.ctx, effects, model))
        except InvalidSignal as exc:
            if "non-finite" not in str(exc):
                raise
            return np.full(1, math.inf)
        vr = validate_values(self.ctx, vals)
        return validation_residuals({q: r.mean_norm for q, r in vr.quantities.items()},
                                    {q: r.std_norm for q, r in vr.quantities.items()})

    def __call__(self, params: Mapping[str, float]) -> float:
        """Σ r_q² (:func:`railval.core.calibration.validation_objective`); ``inf`` where diverged."""
        r = self.residuals(params)
        return float(r @ r) if np.all(np.isfinite(r)) else math.inf


class _Residuals:
    """Picklable residual-vector view of an :class:`_Objective` (for the worker processes)."""

    def __init__(self, objective: _Objective):
        self.objective = objective

    def __call__(self, params: Mapping[str, float]) -> np.ndarray:
        return self.objective.residuals(params)


def calibrate(database: Any, campaign: str, config: str, effects: list[str], new_name: str, *,
              params: list[str] | None = None, progress: Progress | None = None, scheduler: Any = None,
              seed: int = 0, popsize: int = 5, maxiter: int = 5, polish_maxfev: int = 20,
              workers: int | None = None,
              start: Mapping[str, Mapping[str, float]] | None = None, replace: bool = False,
              fit_sections: Sequence[str] | None = None, holdout: Sequence[str] | None = None,
              split: bool = False, method: str = "local") -> CalibrationResult:
    """Add ``effects`` to configuration ``config`` (effect ids, or ``"model.NAME"`` for a
    vehicle-template parameter candidate as :func:`diagnose` names it), fit their parameters
    (all of them, or only ``params`` — names ``"effect.param"``/``"param"`` of the effects, or
    ``"model.NAME"``) to the validation objective
    (:func:`railval.core.calibration.validation_objective`) — ``method="local"``: scan/start then
    trust-region least squares (:func:`railval.core.calibration_local.calibrate_local`);
    ``"global"``: differential evolution and a Powell polish for multi-modal cases (``start``: the start point of the fitted parameters and the value of those not
    fitted), store the result as configuration ``new_name`` (parent ``config``) with its
    simulated signals, and return the :class:`CalibrationResult` whose ``to_dict()`` holds the
    new configuration's ``validation`` and the ``lineage`` (root → new, normalised error of
    every quantity).

    Sections: ``fit_sections`` (fit on these, validate on the others), ``holdout`` (fit on all
    but these) or ``split=True`` (hold out one section per zone and fold, every zone on both
    sides where the campaign has ≥ 2 sections per zone: :func:`railval.core.diagnosis.zone_folds`).
    The result and the stored configuration record which sections the fit used
    (``Configuration.calibration``); the result carries ``validation`` (all sections),
    ``validation_held_out`` (held-out sections), ``in_sample`` and plain-language ``flags`` with
    ``plausible`` (fitted values inside their plausible ranges and off the search bounds).

    The campaign and configuration are resolved once here (docs/design.md §2); every step
    below takes the references. Steps: load, plan (:func:`_plan`), fit, judge
    (:func:`_judge`), store (:func:`_store`)."""
    if method not in ("local", "global"):
        raise InvalidParameter(f"calibrate method must be 'local' or 'global', got {method!r}")
    report(progress, "load", 0.0, campaign=campaign, config=config)
    with session_of(database) as s:
        camp, conf = repo.resolve(s, campaign, config)
        repo.check_new_configuration(s, camp, new_name, replace=replace)  # before fitting
        ctx = load_context(s, camp)
        conf_effects, conf_params, _ = configuration_of(s, camp, conf, simulated_in=ctx)
        # the parent's own evidence, to judge what the calibration adds on sections it has not seen
        parent_vals = section_values(repo.load_signalsets(s, camp, conf), ctx.sections)
        support = diagnosis_flags(s, camp, conf, list(effects))
        start_values, start_source = diagnosis_start(s, conf, list(effects), _start_values(start))
    fit_ids, held_ids = _calibration_split(ctx, fit_sections, holdout, split)
    plan = _plan(ctx, conf, effects, params, start_values, conf_effects, conf_params)
    bound = calibration_simulations(len(plan.specs), method, popsize=popsize, maxiter=maxiter, polish_maxfev=polish_maxfev)
    report(progress, f"plan: {len(plan.specs)} parameter(s), at most {bound} campaign simulations", 0.04)
    objective = _Objective(_restrict(ctx, fit_ids) if held_ids else ctx, plan.base_effects, conf_params,
                           plan.targets)
    with BatchExecutor(scheduler, workers) as ex:
        pool = ex if ex.backend != "serial" else None
        def prog(st: str, f: float, i: dict) -> None:
            report(progress, f"calibrate:{st}", 0.05 + 0.85 * f, **i)
        if method == "global":
            res = fit_parameters(objective, plan.specs, seed=seed, popsize=popsize, maxiter=maxiter,
                                 polish_maxfev=polish_maxfev, workers=pool, progress=prog)
        else:
            res = calibrate_local(_Residuals(objective), plan.specs, seed=seed, workers=pool, progress=prog)
    eff, model = objective.split(res.parameters)
    report(progress, "store", 0.92)
    sets = simulate_context(ctx, eff, model)
    vr_full, vr_held, plausible, flags = _judge(ctx, plan, res.parameters, sets, parent_vals, held_ids)
    flags += support + [f"{'configuration effect' if x['kind'] == 'configuration' else 'effect'} {x['name']} "
                        f"left out: {x['reason']}" for x in plan.skipped]
    record = {"fit_sections": fit_ids, "held_out_sections": held_ids,
              "parameters": [s.name for s in plan.specs]}
    res.extra["lineage"] = _store(database, ctx, camp, conf, new_name, plan, res.objective, eff, model, sets,
                                  record, replace, vr_full)
    start_source["started_from"] = res.tolerance.get("start_from", "start")
    res.extra.update({"configuration": new_name, "parent": conf.name, "effects": eff,
                      "simulations": res.n_evaluations + (1 if method == "local" else 2),
                      "simulations_at_most": bound, "start_source": start_source,
                      "model_parameters": model, "validation": vr_full.to_dict(),
                      "validation_held_out": vr_held.to_dict() if vr_held is not None else None,
                      "fit_sections": fit_ids, "held_out_sections": held_ids, "in_sample": not held_ids,
                      "plausible": plausible, "flags": flags, "skipped": plan.skipped,
                      "next": {"action": "diagnose",
                               "command": f"railval diagnose {camp.name} --config {new_name}",
                               "text": f"diagnose the child next: railval diagnose {camp.name} --config {new_name}"}})
    report(progress, "done", 1.0)
    return res


@dataclass
class _Plan:
    """What a calibration fits: the search box of every fitted parameter (``specs``) and where
    each value goes (``targets``: (effect or ``"model"``, parameter)), the effects simulated
    (``base_effects``: the configuration's runnable effects plus the added ones at their start
    values), the added effects and template-parameter candidates, and what was left out
    (``skipped``; ``conf_skipped``: the configuration's own effects that cannot apply)."""

    specs: list[ParameterSpec]
    targets: list[tuple[str, str]]
    base_effects: dict[str, dict[str, float]]
    effects: list[str]
    model_candidates: list[str]
    skipped: list[dict[str, str]]
    conf_skipped: list[dict[str, str]]


def _start_values(start: Mapping[str, Mapping[str, float]] | None) -> dict[str, dict[str, float]]:
    """``start`` with template parameters under ``"model"``: the app sends a parameter candidate
    ``model.P`` as ``{"model.P": {"P": value}}``, the CLI as ``{"model": {"P": value}}``."""
    out = {k: dict(v) for k, v in (start or {}).items()}
    for key in [k for k in out if k.startswith("model.")]:
        value, name = out.pop(key), key[6:]
        if value:
            if name not in value:
                raise InvalidParameter(f"start value of {key!r} must be given as {{{name!r}: value}}, "
                                       f"got keys {sorted(value)}")
            out.setdefault("model", {})[name] = float(value[name])
    return out


def _plan(ctx: CampaignContext, conf: repo.ConfigRef, requested: Sequence[str], params: Sequence[str] | None,
          start: Mapping[str, Mapping[str, float]], conf_effects: Mapping[str, Any],
          conf_params: Mapping[str, float]) -> _Plan:
    """The :class:`_Plan` of adding ``requested`` (effect ids or ``model.NAME``) to configuration
    ``conf``: unknown effects are refused; effects that cannot apply to the campaign
    (:func:`railval.core.sim.effects.unmet_requirement`) are left out with their reason, refused
    (before any simulation, before anything is stored) only when nothing is left to calibrate; a
    parameter left out of ``params`` keeps its ``start`` value (else its default)."""
    model_candidates = [e for e in requested if e.startswith("model.")]
    effects = [e for e in requested if not e.startswith("model.")]
    for e in effects:
        if e not in EFFECTS:
            raise InvalidParameter(f"unknown effect {e!r}; known: {sorted(EFFECTS)}")
    skipped = [{"name": e, "kind": "effect", "reason": f"cannot apply to campaign {ctx.campaign!r}: {why}"}
               for e in effects if (why := unmet_requirement(EFFECTS[e], ctx.layouts))]
    if skipped and len(skipped) == len(effects) and not model_candidates:
        raise InvalidParameter("; ".join(f"effect {x['name']!r} {x['reason']}" for x in skipped))
    effects = [e for e in effects if e not in {x["name"] for x in skipped}]
    in_config, conf_skipped = runnable_effects(ctx, conf_effects, conf.name)
    base_effects = {k: dict(v) for k, v in in_config.items()}
    specs: list[ParameterSpec] = []
    targets: list[tuple[str, str]] = []
    wanted = set(params or []) | set(model_candidates)
    for e in effects:
        eparams = effect_parameters(EFFECTS[e])
        base_effects.setdefault(e, {k: float(start.get(e, {}).get(k, p["default"])) for k, p in eparams.items()})
        for pname, p in eparams.items():
            if params and not ({pname, f"{e}.{pname}"} & wanted):
                continue
            # its start: the given start value, else the configuration's value, else the default
            st = next((src[pname] for src in (start.get(e, {}), base_effects[e]) if pname in src), p["default"])
            specs.append(ParameterSpec(f"{e}.{pname}", p["lower"], p["upper"], p["unit"],
                                       min(max(float(st), p["lower"]), p["upper"]), log=p["log"]))
            targets.append((e, pname))
    for name in sorted(w for w in wanted if w.startswith("model.")):
        spec = _model_spec(name[6:], ctx, conf_params)
        st = start.get("model", {}).get(name[6:])
        if st is not None:
            spec = ParameterSpec(spec.name, spec.lower, spec.upper, spec.unit,
                                 min(max(float(st), spec.lower), spec.upper), log=spec.log)
        specs.append(spec)
        targets.append(("model", name[6:]))
    if params:
        matched = {s.name for s in specs} | {s.name.split(".", 1)[1] for s in specs}
        missing = [p for p in params if p not in matched]
        if missing:
            raise InvalidParameter(f"--params {missing} are not parameters of effects {effects} "
                                   f"(use effect.param or model.NAME)")
    if not specs:
        raise InvalidParameter(f"nothing to calibrate for effects {effects} and params {params}")
    return _Plan(specs, targets, base_effects, effects, model_candidates, conf_skipped + skipped, conf_skipped)


def _judge(ctx: CampaignContext, plan: _Plan, fitted: Mapping[str, float], sets: Mapping[str, Any],
           parent_vals: Mapping[str, Mapping], held_ids: Sequence[str]) -> tuple[Any, Any, bool, list[str]]:
    """(validation on all sections with 1000 bootstrap resamples, validation on the held-out
    sections or ``None``, plausible, flags) of the calibrated simulation ``sets``: plausibility
    of the fitted values, in-sample / held-out caveats (:func:`_calibration_flags`) and what
    the calibration adds over its parent (:func:`_parent_flags`)."""
    vals = section_values(sets, ctx.sections)
    vr_full = validate_values(ctx, vals, n_boot=1000)
    vr_held = vr_parent_held = None
    if held_ids:
        held = _restrict(ctx, held_ids)
        vr_held = validate(held.measured_values, {k: v for k, v in vals.items() if k in held_ids}, held.sections,
                           ctx.vehicle)
        vr_parent_held = validate(held.measured_values, {k: v for k, v in parent_vals.items() if k in held_ids},
                                  held.sections, ctx.vehicle)
    vr_parent = validate_values(ctx, parent_vals)
    plausible, flags = _calibration_flags(ctx, plan.specs, fitted, vr_full, vr_held)
    flags += _parent_flags(vr_parent, vr_parent_held, vr_held)
    return vr_full, vr_held, plausible, flags


def _store(database: Any, ctx: CampaignContext, camp: repo.CampaignRef, conf: repo.ConfigRef, new_name: str,
           plan: _Plan, objective: float, eff: dict, model: dict, sets: Mapping[str, Any],
           record: dict[str, Any], replace: bool, vr_full: Any) -> list[dict]:
    """Store the calibrated configuration ``new_name`` (parent ``conf``) in one writing unit of
    work and return its lineage errors (:func:`lineage_errors`)."""
    description = (f"calibrated {', '.join(plan.effects + plan.model_candidates)} from {conf.name} "
                   f"(objective {objective:.3g})"
                   + "".join(f"; without {x['name']} (cannot apply to this campaign)" for x in plan.conf_skipped))
    with session_of(database, write=True) as s:
        repo.store_configuration(s, camp, new_name, parent=conf, effects=eff, parameters=model,
                                 description=description, signalsets=sets, replace=replace,
                                 calibration=record)
        s.flush()
        return lineage_errors(s, ctx, new_name, {new_name: vr_full})


def _restrict(ctx: CampaignContext, ids: Sequence[str]) -> CampaignContext:
    """The campaign context on a subset of its sections."""
    keep = set(ids)
    return replace(ctx, sections=[s for s in ctx.sections if s.id in keep],
                   measured_values={k: v for k, v in ctx.measured_values.items() if k in keep})


def _calibration_split(ctx: CampaignContext, fit_sections: Sequence[str] | None, holdout: Sequence[str] | None,
                       split: bool) -> tuple[list[str], list[str]]:
    """(fit section ids, held-out section ids) from the user's choice; unknown ids name the
    known ones. ``split``: the first zone-stratified fold of :func:`railval.core.diagnosis.zone_folds`
    is held out (one section per zone and fold, every zone on both sides where it has ≥ 2)."""
    ids = [s.id for s in ctx.sections]
    given = [*(fit_sections or []), *(holdout or [])]
    bad = [x for x in given if x not in ids]
    if bad:
        raise InvalidParameter(f"unknown section(s) {bad} in campaign {ctx.campaign!r}; known: {ids}")
    if sum(bool(x) for x in (fit_sections, holdout, split)) > 1:
        raise InvalidParameter("give only one of --fit-sections, --holdout and --split")
    if fit_sections:
        fit = [i for i in ids if i in set(fit_sections)]
    elif holdout:
        fit = [i for i in ids if i not in set(holdout)]
    elif split:
        masks = zone_folds([int(s.zone) for s in ctx.sections], 3)
        fit = [i for i, m in zip(ids, masks[0], strict=True) if m == 0]
    else:
        return ids, []
    if not fit:
        raise InvalidParameter("the calibration needs at least one section to fit on")
    held = [i for i in ids if i not in set(fit)]
    return fit, held


def _calibration_flags(ctx: CampaignContext, specs: Sequence[ParameterSpec], values: Mapping[str, float],
                       vr_full: Any, vr_held: Any) -> tuple[bool, list[str]]:
    """Plausibility of the fitted values (plausible range from the parameter registry, or at a
    search bound) and the in-sample / held-out caveats of the verdict."""

    registry = EFFECTS
    template = str(ctx.vehicle.get("template") or "coach")
    ok_all, flags = True, []
    for sp in specs:
        owner, pname = sp.name.split(".", 1)
        try:
            pobj = (template_param(template, pname) if owner == "model"
                    else next(p for p in (registry[owner].parameters.values()) if p.name == pname))
            plaus, source = plausible_range(pobj)
        except (InvalidParameter, StopIteration, KeyError, AttributeError):
            plaus, source = None, ""
        ok, fl = plausibility_flags(sp.name, float(values[sp.name]), bounds=(sp.lower, sp.upper),
                                    plausible=plaus, source=source, unit=sp.unit)
        ok_all &= ok
        flags += fl
    if vr_held is None:
        flags.append("in-sample: validated on the sections the calibration was fitted to; calibrate with "
                     "--split (or --holdout) to judge it on sections it has not seen")
    else:
        worst = lambda vr: max((max(abs(r.mean_norm), r.std_norm) for r in vr.quantities.values()
                                if math.isfinite(r.mean_norm) and math.isfinite(r.std_norm)), default=math.nan)
        e_full, e_held = worst(vr_full), worst(vr_held)
        if e_held > 1.0 and bool(vr_full.validated):
            flags.append(f"passes on all sections but the largest normalised error on the held-out sections is "
                         f"{e_held:.2f} (> 1): the fit does not carry over; the model may be compensating for "
                         "something else")
        elif e_held > 1.5 * e_full and e_held > 0.5:
            flags.append(f"held-out sections fit worse (largest normalised error {e_held:.2f} vs {e_full:.2f} on all)")
    return ok_all, flags


#: a calibration must lower the held-out objective by at least this share to count as evidence
HELD_OUT_GAIN = 0.2


def _objective_of(vr: Any) -> float:
    return validation_objective({q: r.mean_norm for q, r in vr.quantities.items()},
                                {q: r.std_norm for q, r in vr.quantities.items()})


def _parent_flags(vr_parent: Any, vr_parent_held: Any, vr_held: Any) -> list[str]:
    """What the calibration adds over its parent (the configuration it started from): a note
    when the parent already passed; on held-out sections the DynoTRAIN objective
    Σ max(|mean_norm|, std_norm)² (:func:`railval.core.calibration.validation_objective`) must
    fall by ``HELD_OUT_GAIN`` or more — otherwise the fitted change is not evidence of a cause
    (held-out check, docs/diagnosis.md "Calibration")."""
    flags = []
    if bool(vr_parent.validated):
        flags.append("note: the parent configuration already passed validation; this calibration changes a "
                     "model that was acceptable — keep it only if it also improves the held-out sections")
    if vr_parent_held is not None and vr_held is not None:
        before, after = _objective_of(vr_parent_held), _objective_of(vr_held)
        if not after <= (1.0 - HELD_OUT_GAIN) * before:
            flags.append(f"on the held-out sections the calibration improves the validation objective by less than "
                         f"{HELD_OUT_GAIN:.0%} ({before:.3g} → {after:.3g}): no held-out evidence that this candidate "
                         "is a cause; the model may be compensating for something else")
    return flags


def _model_spec(name: str, ctx: CampaignContext, conf_params: Mapping[str, float]) -> ParameterSpec:
    """Search box of a template parameter: the diagnosis's box for its parameter candidates
    (log scale), else the modal box ([ref 3]) or ±30 %."""

    plan = {p["parameter"]: p for p in parameter_plan(ctx, conf_params)}
    if name in plan:
        p = plan[name]
        return ParameterSpec(f"model.{name}", p["bounds"][0], p["bounds"][1], p["unit"], p["reference"], log=True)
    # its value: the configuration's, else the vehicle template's, else the modal default
    sources = (conf_params, ctx.vehicle["parameters"], COACH_MODAL_DEFAULTS)
    value = next((src[name] for src in sources if name in src), None)
    if value is None:
        raise InvalidParameter(f"model parameter {name!r} has no value in the vehicle template or configuration")
    lo, hi = (COACH_MODAL_PARAMETERS[name][:2] if name in COACH_MODAL_PARAMETERS
              else (0.7 * float(value), 1.3 * float(value)))
    return ParameterSpec(f"model.{name}", lo, hi, "", float(value))


def lineage_errors(session: Any, ctx: CampaignContext, config: str, known: Mapping[str, Any] | None = None) -> list[dict]:
    """Root → ``config``: per configuration its effects and every quantity's normalised error
    (:func:`railval.core.validation.normalised_errors`), so the UI can draw the error falling.
    ``known``: validation results already at hand, by configuration name.

    A calibrated configuration also carries ``fit_sections``, ``held_out_sections``,
    ``in_sample`` (its verdict is on sections the calibration was fitted to) and, when it was
    calibrated with held-out sections, ``held_out`` — the largest normalised error of it and
    of its parent on those sections and the improvement (parent − child): the step's
    held-out evidence."""
    out = []
    prev_vals = None
    camp = ctx.ref or ctx.campaign
    for conf in repo.lineage(session, camp, config):
        vr = (known or {}).get(conf.name)
        sets = None
        src = repo.ConfigRef(camp, conf.id, conf.name) if isinstance(camp, repo.CampaignRef) else conf.name
        if vr is None or (conf.calibration or {}).get("held_out_sections"):
            sets = repo.load_signalsets(session, camp, src)
        vals = section_values(sets, ctx.sections) if sets is not None else None
        if vr is None:
            vr = validate_values(ctx, vals)
        cal_rec = conf.calibration or {}
        held = list(cal_rec.get("held_out_sections") or [])
        item = {"configuration": conf.name, "effects": dict(conf.effects or {}),
                "parameters": dict(conf.parameters or {}), **normalised_errors(vr),
                "fit_sections": cal_rec.get("fit_sections"), "held_out_sections": held or None,
                "in_sample": bool(cal_rec) and not held}
        if held and vals is not None:
            sub = _restrict(ctx, held)
            child = _max_error(validate(sub.measured_values, {k: v for k, v in vals.items() if k in held},
                                        sub.sections, ctx.vehicle, n_boot=0))
            parent = None
            if prev_vals is not None:
                parent = _max_error(validate(sub.measured_values, {k: v for k, v in prev_vals.items() if k in held},
                                             sub.sections, ctx.vehicle, n_boot=0))
            item["held_out"] = {"max_error": child, "parent_max_error": parent,
                                "improvement": (parent - child) if parent is not None and child is not None else None}
        out.append(item)
        if vals is None:
            vals = section_values(repo.load_signalsets(session, camp, src), ctx.sections)
        prev_vals = vals
    return out


def _max_error(vr: Any) -> float | None:
    return normalised_errors(vr)["max_error"]

