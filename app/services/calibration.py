"""Service: add effects to a configuration, fit their parameters to the validation objective
and store the result as a new configuration (docs/design.md §7, :mod:`railval.core.calibration`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from railval.app.services.batch import BatchExecutor
from railval.app.services.campaign_context import (
    CampaignContext,
    Progress,
    configuration_of,
    effect_parameters,
    evaluate_effects,
    load_context,
    report,
    section_values,
    session_of,
    simulate_context,
    validate_values,
)
from railval.core.calibration import (
    COACH_MODAL_DEFAULTS,
    COACH_MODAL_PARAMETERS,
    CalibrationResult,
    ParameterSpec,
    validation_objective,
)
from railval.core.calibration import calibrate as fit_parameters
from railval.core.errors import InvalidParameter
from railval.core.sim.effects import EFFECTS
from railval.core.validation import normalised_errors
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

    def __call__(self, params: Mapping[str, float]) -> float:
        effects, model = self.split(params)
        vals, _ = evaluate_effects((self.ctx, effects, model))
        vr = validate_values(self.ctx, vals)
        return validation_objective({q: r.mean_norm for q, r in vr.quantities.items()},
                                    {q: r.std_norm for q, r in vr.quantities.items()})


def calibrate(database: Any, campaign: str, config: str, effects: list[str], new_name: str, *,
              params: list[str] | None = None, progress: Progress | None = None, scheduler: Any = None,
              seed: int = 0, popsize: int = 5, maxiter: int = 5, polish_maxfev: int = 20,
              workers: int | None = None,
              start: Mapping[str, Mapping[str, float]] | None = None, replace: bool = False) -> CalibrationResult:
    """Add ``effects`` to configuration ``config``, fit their parameters (all of them, or only
    ``params`` — names ``"effect.param"``/``"param"`` of the effects, or ``"model.NAME"`` for
    a vehicle-template parameter) to the validation objective
    (:func:`railval.core.calibration.validation_objective`) with differential evolution and a local
    polish (``start``: the start point of the fitted parameters and the value of those not
    fitted), store the result as configuration ``new_name`` (parent ``config``) with its
    simulated signals, and return the :class:`CalibrationResult` whose ``to_dict()`` holds the
    new configuration's ``validation`` and the ``lineage`` (root → new, normalised error of
    every quantity)."""
    report(progress, "load", 0.0, campaign=campaign, config=config)
    with session_of(database) as s:
        ctx = load_context(s, campaign)
        conf_effects, conf_params, _ = configuration_of(s, campaign, config)
    registry = EFFECTS
    for e in effects:
        if e not in registry:
            raise InvalidParameter(f"unknown effect {e!r}; known: {sorted(registry)}")
    base_effects = {k: dict(v) for k, v in conf_effects.items()}
    specs: list[ParameterSpec] = []
    targets: list[tuple[str, str]] = []
    wanted = set(params or [])
    for e in effects:
        eparams = effect_parameters(registry[e])
        # a parameter left out of ``params`` keeps its ``start`` value (else its default)
        base_effects.setdefault(e, {k: float((start or {}).get(e, {}).get(k, p["default"]))
                                    for k, p in eparams.items()})
        for pname, p in eparams.items():
            if params and not ({pname, f"{e}.{pname}"} & wanted):
                continue
            st = (start or {}).get(e, {}).get(pname, base_effects[e].get(pname, p["default"]))
            specs.append(ParameterSpec(f"{e}.{pname}", p["lower"], p["upper"], p["unit"],
                                       min(max(float(st), p["lower"]), p["upper"]), log=p["log"]))
            targets.append((e, pname))
    for name in sorted(w for w in wanted if w.startswith("model.")):
        specs.append(_model_spec(name[6:], ctx, conf_params))
        targets.append(("model", name[6:]))
    if params:
        matched = {s.name for s in specs} | {s.name.split(".", 1)[1] for s in specs}
        missing = [p for p in params if p not in matched]
        if missing:
            raise InvalidParameter(f"--params {missing} are not parameters of effects {effects} "
                                   f"(use effect.param or model.NAME)")
    if not specs:
        raise InvalidParameter(f"nothing to calibrate for effects {effects} and params {params}")
    objective = _Objective(ctx, base_effects, conf_params, targets)
    with BatchExecutor(scheduler, workers) as ex:
        res = fit_parameters(objective, specs, seed=seed, popsize=popsize, maxiter=maxiter,
                            polish_maxfev=polish_maxfev,
                            workers=ex if ex.backend != "serial" else None,
                            progress=lambda st, f, i: report(progress, f"calibrate:{st}", 0.05 + 0.85 * f, **i))
    eff, model = objective.split(res.parameters)
    report(progress, "store", 0.92)
    sets = simulate_context(ctx, eff, model)
    vals = section_values(sets, ctx.sections)
    vr_full = validate_values(ctx, vals, n_boot=1000)
    with session_of(database) as s:
        repo.store_configuration(
            s, campaign, new_name, parent=config, effects=eff, parameters=model,
            description=f"calibrated {', '.join(effects)} from {config} (objective {res.objective:.3g})",
            signalsets=sets, replace=replace)
        s.flush()
        res.extra["lineage"] = lineage_errors(s, ctx, new_name, {new_name: vr_full})
    res.extra.update({"configuration": new_name, "parent": config, "effects": eff,
                      "model_parameters": model, "validation": vr_full.to_dict()})
    report(progress, "done", 1.0)
    return res


def _model_spec(name: str, ctx: CampaignContext, conf_params: Mapping[str, float]) -> ParameterSpec:
    value = conf_params.get(name, ctx.vehicle.get("parameters", {}).get(name, COACH_MODAL_DEFAULTS.get(name)))
    if value is None:
        raise InvalidParameter(f"model parameter {name!r} has no value in the vehicle template or configuration")
    lo, hi = (COACH_MODAL_PARAMETERS[name][:2] if name in COACH_MODAL_PARAMETERS
              else (0.7 * float(value), 1.3 * float(value)))
    return ParameterSpec(f"model.{name}", lo, hi, "", float(value))


def lineage_errors(session: Any, ctx: CampaignContext, name: str, known: Mapping[str, Any] | None = None) -> list[dict]:
    """Root → ``name``: per configuration its effects and every quantity's normalised error
    (:func:`railval.core.validation.normalised_errors`), so the UI can draw the error falling.
    ``known``: validation results already at hand, by configuration name."""
    out = []
    for conf in repo.lineage(session, ctx.campaign, name):
        vr = (known or {}).get(conf.name)
        if vr is None:
            sets = repo.load_signalsets(session, ctx.campaign, conf.name)
            vr = validate_values(ctx, section_values(sets, ctx.sections))
        out.append({"configuration": conf.name, "effects": dict(conf.effects or {}), **normalised_errors(vr)})
    return out
