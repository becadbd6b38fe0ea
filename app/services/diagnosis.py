"""Services joining the database, the simulator and the diagnosis/calibration core
(docs/design.md §7): ``diagnose``, ``calibrate`` and the modal identification/calibration of [ref 3].

The Panel app calls these from a background thread with a ``progress(stage, fraction, info)``
callback; the CLI prints the same callbacks on stderr. Simulation and evaluation of the
campaign for many candidate effect values run through :class:`railval.app.services.batch.BatchExecutor`
(local process pool, or Dask with ``scheduler="tcp://…"``).

Simulator adapter
-----------------
:func:`_simulate_campaign` is the one place that calls the built-in simulator
(:mod:`railval.core.sim`); the task functions sent to the workers (:func:`_evaluate_effects`) are
top-level so they pickle by reference.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from railval.app.services.batch import BatchExecutor
from railval.core.calibration import (
    COACH_MODAL_DEFAULTS,
    COACH_MODAL_PARAMETERS,
    CalibrationResult,
    ParameterSpec,
    calibrate_modal,
    validation_objective,
)
from railval.core.diagnosis import (
    DEFAULT_BANDS_HZ,
    DiagnosisResult,
    Pattern,
    band_powers,
    band_ratio_pattern,
    pattern_from_pairs,
)
from railval.core.errors import InvalidParameter, NotFound
from railval.core.modal import ssi_cov
from railval.core.types import SectionInfo, SignalSet

Progress = Callable[[str, float, dict[str, Any]], None]

ACC_CHANNELS = ("ay_cb_b1", "ay_cb_b2", "az_cb_b1", "az_cb_b2")


# --------------------------------------------------------------------------- db helpers
@contextmanager
def _session(database_or_session: Any) -> Iterator[Any]:
    """Yield a session from a :class:`railval.db.engine.Database`, a URL string or a Session."""
    from sqlalchemy.orm import Session

    if isinstance(database_or_session, Session):
        yield database_or_session
        return
    if database_or_session is None or isinstance(database_or_session, str):
        from railval.db.engine import connect

        database_or_session = connect(database_or_session)
    with database_or_session.session() as s:
        yield s


def _report(progress: Progress | None, stage: str, fraction: float, **info: Any) -> None:
    if progress is not None:
        progress(stage, float(min(max(fraction, 0.0), 1.0)), info)


# --------------------------------------------------------------------------- campaign context
@dataclass
class CampaignContext:
    """Everything a worker needs to simulate and evaluate the campaign (picklable)."""

    campaign: str
    vehicle: dict[str, Any]
    sections: list[SectionInfo]
    layouts: dict[str, Any]
    measured_values: dict[str, dict[tuple[str, str], float]]
    measured_bands: dict[str, np.ndarray]
    channels: list[str]
    fs: dict[str, float]
    sim_inputs: dict[str, Any] = field(default_factory=dict)
    bands: tuple[tuple[float, float], ...] = DEFAULT_BANDS_HZ


def _band_sum(signalsets: Mapping[str, SignalSet], bands) -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    for ss in signalsets.values():
        for ch in ACC_CHANNELS:
            if ch in ss.channels:
                out[ch] = out.get(ch, 0.0) + band_powers(ss.channels[ch], ss.fs, bands, 10.0)
    return out


def _values(signalsets: Mapping[str, SignalSet], sections: Sequence[SectionInfo]) -> dict[str, dict]:
    from railval.core.en14363 import evaluate_batch

    secs = [s for s in sections if s.id in signalsets]
    vals = evaluate_batch([signalsets[s.id] for s in secs], secs)
    return {s.id: dict(v) for s, v in zip(secs, vals, strict=True)}


def load_context(session: Any, campaign: str) -> CampaignContext:
    """Read the campaign's vehicle, sections and measurement; evaluate the measurement once."""
    from railval.db import repo

    camp = repo.get_campaign(session, campaign)
    sections = repo.section_infos(session, camp)
    vehicle = repo.vehicle_info(session, camp)
    layouts = repo.section_layouts(session, camp)
    measured = repo.load_signalsets(session, camp, None)
    if not measured:
        raise NotFound(f"campaign {camp.name!r} has no measurement recordings")
    ctx = CampaignContext(camp.name, vehicle, sections, layouts, _values(measured, sections),
                          _band_sum(measured, DEFAULT_BANDS_HZ),
                          sorted({c for ss in measured.values() for c in ss.channels}),
                          {sid: ss.fs for sid, ss in measured.items()})
    ctx.sim_inputs = _simulation_inputs(session, camp, ctx, measured)
    return ctx


def residual_pattern(ctx: CampaignContext, sim_values: Mapping[str, Mapping], sim_bands: Mapping[str, np.ndarray]) -> tuple[Pattern, Any]:
    """Pattern (normalised D_v per quantity × zone × position + log₂ band-power ratios) and the
    :class:`railval.core.validation.ValidationResult` (no bootstrap) of simulated values."""
    from railval.core.validation import validate

    vr = validate(ctx.measured_values, sim_values, ctx.sections, ctx.vehicle, n_boot=0)
    pairs = vr.pairs.to_dict("records")
    pat = pattern_from_pairs(pairs, value_key="D_norm")
    return Pattern.concat(pat, band_ratio_pattern(sim_bands, ctx.measured_bands, ctx.bands)), vr


# --------------------------------------------------------------------------- simulator adapter
def _simulation_inputs(session: Any, camp: Any, ctx: CampaignContext, measured: Mapping[str, SignalSet]) -> dict[str, Any]:
    """What the simulator needs beyond vehicle and sections (track irregularities …)."""
    from railval.app.services import simulation as sim_service

    hook = getattr(sim_service, "simulation_inputs", None)
    if hook is not None:
        return dict(hook(session, camp))
    return {}


def _simulate_campaign(ctx: CampaignContext, effects: Mapping[str, Mapping[str, float]],
                       parameters: Mapping[str, float] | None = None) -> dict[str, SignalSet]:
    """Simulate every section of the campaign with the built-in simulator."""
    from railval.core.sim import simulate_campaign

    return simulate_campaign(ctx.vehicle, ctx.sections, layouts=ctx.layouts, effects=dict(effects),
                             parameters=dict(parameters or {}), channels=ctx.channels,
                             fs=ctx.fs, **ctx.sim_inputs)


def _effect_registry() -> dict[str, Any]:
    from railval.core.sim.effects import EFFECTS

    return dict(EFFECTS)


def _evaluate_effects(task: tuple[CampaignContext, dict, dict]) -> tuple[dict, dict]:
    """Worker task: simulate with ``effects`` (and model ``parameters``) and return the section
    values and the summed acceleration band powers (small; no signals travel back)."""
    ctx, effects, parameters = task
    sets = _simulate_campaign(ctx, effects, parameters)
    return _values(sets, ctx.sections), _band_sum(sets, ctx.bands)


def _config(session: Any, campaign: str, name: str) -> tuple[dict, dict, Any]:
    from railval.db import repo

    conf = repo.get_configuration(session, campaign, name)
    return dict(conf.effects or {}), dict(conf.parameters or {}), conf


# --------------------------------------------------------------------------- diagnose
def scan_values(lower: float, upper: float, default: float, n: int, log: bool = False) -> list[float]:
    """``n`` values spanning [lower, upper] (equally spaced, or geometrically with ``log``) plus
    the default, sorted, unique."""
    grid = np.geomspace(lower, upper, n) if log else np.linspace(lower, upper, n)
    return sorted(set(grid.tolist()) | {float(default)})


def scan_points(spec: Any, values_per_parameter: int) -> Iterator[tuple[str, float, dict[str, float], dict]]:
    """The one-parameter scan of an effect: for each parameter and each of its
    :func:`scan_values`, ``(parameter, value, all parameters at default but this one, its
    bounds record)``."""
    params = _effect_parameters(spec)
    defaults = {k: float(v["default"]) for k, v in params.items()}
    for pname, p in params.items():
        for v in scan_values(p["lower"], p["upper"], p["default"], values_per_parameter, p["log"]):
            yield pname, v, {**defaults, pname: v}, p


def diagnosis_simulations(effects: Sequence[str], values_per_parameter: int = 3,
                          template: str | None = None, parameters: bool | int = True, refine: int = 3) -> int:
    """How many campaign simulations :func:`diagnose` runs for ``effects`` (the configuration
    itself once, plus every distinct scan point of the effects that apply to the vehicle
    ``template``, plus one per template parameter candidate (``parameters``: all of the
    template's, or that many) and at most ``refine`` refinements): shown before a user starts it."""
    from railval.core.diagnosis import PARAMETER_CANDIDATES

    registry = _effect_registry()
    n_par = len(PARAMETER_CANDIDATES.get(template or "coach", {})) if parameters is True else int(parameters)
    n = 1 + (n_par + min(refine, n_par) if n_par else 0)
    for e in effects:
        if template and template not in getattr(registry[e], "templates", (template,)):
            continue
        n += len({json.dumps(point, sort_keys=True)
                  for _, _, point, _ in scan_points(registry[e], values_per_parameter)})
    return n


def diagnose(database_or_session: Any, campaign: str, config: str, *, progress: Progress | None = None,
             scheduler: Any = None, values_per_parameter: int = 3, effects: Sequence[str] | None = None,
             workers: int | None = None, **options: Any) -> DiagnosisResult:
    """Rank the causes of the residual of configuration ``config``: the effects it lacks and
    the vehicle-template parameters that may be mis-set, by the share of the residual they
    explain on held-out sections, with noise floor, plausibility, identifiability and a
    verdict (:func:`railval.app.services.diagnosis_evidence.diagnose`). ``effects``: candidate
    names — effect ids and ``model.NAME`` parameters; given without any ``model.`` name, only
    those effects are tried."""
    from railval.app.services.diagnosis_evidence import diagnose as diagnose_evidence_service

    if effects is not None:
        names = list(effects)
        params = [n for n in names if n.startswith("model.")]
        options.setdefault("parameters", params or None)
        options.setdefault("include_parameters", bool(params))
        effects = [n for n in names if not n.startswith("model.")]
    return diagnose_evidence_service(database_or_session, campaign, config, progress=progress, scheduler=scheduler,
                                     values_per_parameter=values_per_parameter, effects=effects, workers=workers,
                                     **options)


def _effect_parameters(spec: Any) -> dict[str, dict[str, float]]:
    """``{name: {lower, upper, default, unit}}`` of an effect registry entry (adapter)."""
    params = spec["parameters"] if isinstance(spec, Mapping) else spec.parameters
    out = {}
    for name, p in (params.items() if isinstance(params, Mapping) else ((q.name, q) for q in params)):
        get = p.get if isinstance(p, Mapping) else (lambda k, _p=p: getattr(_p, k))
        scale = p.get("scale", "linear") if isinstance(p, Mapping) else getattr(p, "scale", "linear")
        lower = float(get("lower"))
        out[name] = {"lower": lower, "upper": float(get("upper")),
                     "default": float(get("default")), "unit": str(get("unit") or ""),
                     "log": scale == "log" and lower > 0}
    return out


def _effect_explanation(spec: Any) -> str:
    return str(spec.get("explanation", "") if isinstance(spec, Mapping) else getattr(spec, "explanation", ""))


# --------------------------------------------------------------------------- calibrate
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
        from railval.core.validation import validate

        effects, model = self.split(params)
        vals, _ = _evaluate_effects((self.ctx, effects, model))
        vr = validate(self.ctx.measured_values, vals, self.ctx.sections, self.ctx.vehicle, n_boot=0)
        return validation_objective({q: r.mean_norm for q, r in vr.quantities.items()},
                                    {q: r.std_norm for q, r in vr.quantities.items()})


def calibrate(database: Any, campaign: str, config: str, effects: list[str], new_name: str, *,
              params: list[str] | None = None, progress: Progress | None = None, scheduler: Any = None,
              seed: int = 0, popsize: int = 5, maxiter: int = 5, polish_maxfev: int = 20,
              workers: int | None = None,
              start: Mapping[str, Mapping[str, float]] | None = None, replace: bool = False,
              fit_sections: Sequence[str] | None = None, holdout: Sequence[str] | None = None,
              split: bool = False) -> CalibrationResult:
    """Add ``effects`` to configuration ``config`` (effect ids, or ``"model.NAME"`` for a
    vehicle-template parameter candidate as :func:`diagnose` names it), fit their parameters
    (all of them, or only ``params`` — names ``"effect.param"``/``"param"`` of the effects, or
    ``"model.NAME"``) to the validation objective
    (:func:`railval.core.calibration.validation_objective`) with differential evolution and a local
    polish (``start``: the start point of the fitted parameters and the value of those not
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
    ``plausible`` (fitted values inside their plausible ranges and off the search bounds)."""
    from railval.core import calibration as cal

    _report(progress, "load", 0.0, campaign=campaign, config=config)
    with _session(database) as s:
        ctx = load_context(s, campaign)
        conf_effects, conf_params, _ = _config(s, campaign, config)
    model_candidates = [e for e in effects if e.startswith("model.")]
    effects = [e for e in effects if not e.startswith("model.")]
    start = {k: dict(v) for k, v in (start or {}).items()}
    for key in [k for k in start if k.startswith("model.")]:  # {"model.P": {"P": v}} as the app sends it
        value = start.pop(key)
        if value:
            start.setdefault("model", {})[key[6:]] = float(value.get(key[6:], next(iter(value.values()))))
    fit_ids, held_ids = _calibration_split(ctx, fit_sections, holdout, split)
    registry = _effect_registry()
    for e in effects:
        if e not in registry:
            raise InvalidParameter(f"unknown effect {e!r}; known: {sorted(registry)}")
    base_effects = {k: dict(v) for k, v in conf_effects.items()}
    specs: list[ParameterSpec] = []
    targets: list[tuple[str, str]] = []
    wanted = set(params or []) | set(model_candidates)
    for e in effects:
        eparams = _effect_parameters(registry[e])
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
        spec = _model_spec(name[6:], ctx, conf_params)
        st = (start.get("model") or {}).get(name[6:])
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
    ctx_fit = _restrict(ctx, fit_ids) if held_ids else ctx
    objective = _Objective(ctx_fit, base_effects, conf_params, targets)
    with BatchExecutor(scheduler, workers) as ex:
        res = cal.calibrate(objective, specs, seed=seed, popsize=popsize, maxiter=maxiter,
                            polish_maxfev=polish_maxfev,
                            workers=ex if ex.backend != "serial" else None,
                            progress=lambda st, f, i: _report(progress, f"calibrate:{st}", 0.05 + 0.85 * f, **i))
    eff, model = objective.split(res.parameters)
    _report(progress, "store", 0.92)
    sets = _simulate_campaign(ctx, eff, model)
    vals = _values(sets, ctx.sections)
    from railval.core.validation import validate

    vr_full = validate(ctx.measured_values, vals, ctx.sections, ctx.vehicle)
    record = {"fit_sections": fit_ids, "held_out_sections": held_ids, "parameters": [s.name for s in specs]}
    vr_held = None
    if held_ids:
        held = _restrict(ctx, held_ids)
        vr_held = validate(held.measured_values, {k: v for k, v in vals.items() if k in held_ids}, held.sections,
                           ctx.vehicle)
    plausible, flags = _calibration_flags(ctx, specs, res.parameters, vr_full, vr_held)
    with _session(database) as s:
        from railval.db import repo

        repo.store_configuration(
            s, campaign, new_name, parent=config, effects=eff, parameters=model,
            description=f"calibrated {', '.join(effects + model_candidates)} from {config} "
                        f"(objective {res.objective:.3g})",
            signalsets=sets, replace=replace, calibration=record)
        s.flush()
        res.extra["lineage"] = lineage_errors(s, ctx, new_name, {new_name: vr_full})
    res.extra.update({"configuration": new_name, "parent": config, "effects": eff,
                      "model_parameters": model, "validation": vr_full.to_dict(),
                      "validation_held_out": vr_held.to_dict() if vr_held is not None else None,
                      "fit_sections": fit_ids, "held_out_sections": held_ids, "in_sample": not held_ids,
                      "plausible": plausible, "flags": flags,
                      "next": {"action": "diagnose", "command": f"railval diagnose {campaign} --config {new_name}",
                               "text": f"diagnose the child next: railval diagnose {campaign} --config {new_name}"}})
    _report(progress, "done", 1.0)
    return res


def _restrict(ctx: CampaignContext, ids: Sequence[str]) -> CampaignContext:
    """The campaign context on a subset of its sections."""
    from dataclasses import replace

    keep = set(ids)
    return replace(ctx, sections=[s for s in ctx.sections if s.id in keep],
                   measured_values={k: v for k, v in ctx.measured_values.items() if k in keep})


def _calibration_split(ctx: CampaignContext, fit_sections: Sequence[str] | None, holdout: Sequence[str] | None,
                       split: bool) -> tuple[list[str], list[str]]:
    """(fit section ids, held-out section ids) from the user's choice; unknown ids name the
    known ones. ``split``: the first zone-stratified fold of :func:`railval.core.diagnosis.zone_folds`
    is held out (one section per zone and fold, every zone on both sides where it has ≥ 2)."""
    from railval.core.diagnosis import zone_folds

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
    from railval.app.services.diagnosis_evidence import plausible_range, template_param
    from railval.core.diagnosis import plausibility_flags

    registry = _effect_registry()
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


def _model_spec(name: str, ctx: CampaignContext, conf_params: Mapping[str, float]) -> ParameterSpec:
    """Search box of a template parameter: the diagnosis's box for its parameter candidates
    (log scale), else the modal box ([ref 3]) or ±30 %."""
    from railval.app.services.diagnosis_evidence import parameter_plan

    plan = {p["parameter"]: p for p in parameter_plan(ctx, conf_params)}
    if name in plan:
        p = plan[name]
        return ParameterSpec(f"model.{name}", p["bounds"][0], p["bounds"][1], p["unit"], p["reference"], log=True)
    value = conf_params.get(name, ctx.vehicle.get("parameters", {}).get(name, COACH_MODAL_DEFAULTS.get(name)))
    if value is None:
        raise InvalidParameter(f"model parameter {name!r} has no value in the vehicle template or configuration")
    lo, hi = (COACH_MODAL_PARAMETERS[name][:2] if name in COACH_MODAL_PARAMETERS
              else (0.7 * float(value), 1.3 * float(value)))
    return ParameterSpec(f"model.{name}", lo, hi, "", float(value))


def lineage_errors(session: Any, ctx: CampaignContext, name: str, known: Mapping[str, Any] | None = None) -> list[dict]:
    """Root → ``name``: per configuration its effects and every quantity's normalised error
    max(|mean_norm|, std_norm) (with both parts), so the UI can draw the error falling.

    A calibrated configuration also carries ``fit_sections``, ``held_out_sections``,
    ``in_sample`` (its verdict is on sections the calibration was fitted to) and, when it was
    calibrated with held-out sections, ``held_out`` — the largest normalised error of it and
    of its parent on those sections and the improvement (parent − child): the step's
    held-out evidence."""
    from railval.core.validation import validate
    from railval.db import repo

    out = []
    prev_vals = None
    for conf in repo.lineage(session, ctx.campaign, name):
        vr = (known or {}).get(conf.name)
        sets = None
        if vr is None or (conf.calibration or {}).get("held_out_sections"):
            sets = repo.load_signalsets(session, ctx.campaign, conf.name)
        vals = _values(sets, ctx.sections) if sets is not None else None
        if vr is None:
            vr = validate(ctx.measured_values, vals, ctx.sections, ctx.vehicle, n_boot=0)
        worst = _max_error(vr)
        cal_rec = conf.calibration or {}
        held = list(cal_rec.get("held_out_sections") or [])
        item = {"configuration": conf.name, "effects": dict(conf.effects or {}),
                "parameters": dict(conf.parameters or {}),
                "validated": bool(vr.validated), "max_error": worst, "quantities": _quantity_errors(vr),
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
            vals = _values(repo.load_signalsets(session, ctx.campaign, conf.name), ctx.sections)
        prev_vals = vals
    return out


def _quantity_errors(vr: Any) -> dict[str, dict]:
    return {k: {"mean_norm": _finite(r.mean_norm), "std_norm": _finite(r.std_norm),
                "error": _finite(max(abs(r.mean_norm), r.std_norm))} for k, r in vr.quantities.items()}


def _max_error(vr: Any) -> float | None:
    return max((v["error"] for v in _quantity_errors(vr).values() if v["error"] is not None), default=None)


def _finite(x: float) -> float | None:
    return float(x) if x is not None and math.isfinite(x) else None


# --------------------------------------------------------------------------- modal ([ref 3])
def identify_modes(database_or_session: Any, campaign: str, *, sections: Sequence[str] | None = None,
                   config: str | None = None, channels: Sequence[str] = ("az_cb_b1", "az_cb_b2"),
                   fs_target: float = 20.0, f_min: float = 0.5, f_max: float = 4.0):
    """SSI-COV modes of the car body from the accelerations of the measurement (or of a
    configuration) over the chosen sections (all by default; covariances averaged over the
    sections). Signals are decimated to about ``fs_target`` Hz with an anti-alias FIR
    (``scipy.signal.resample_poly``)."""
    from scipy.signal import resample_poly

    from railval.db import repo

    with _session(database_or_session) as s:
        sets = repo.load_signalsets(s, campaign, config, sections=list(sections) if sections else None,
                                    channels=list(channels))
    records, fs_used = [], None
    for ss in sets.values():
        q = max(round(ss.fs / fs_target), 1)
        fs_new = ss.fs / q
        if fs_used is not None and not math.isclose(fs_new, fs_used):
            continue
        fs_used = fs_new
        records.append(np.column_stack([resample_poly(ss.channels[c], 1, q) for c in channels]))
    if not records:
        raise NotFound(f"campaign {campaign!r}: no recordings with channels {list(channels)}")
    return ssi_cov(records, fs_used, channels=list(channels), f_min=f_min, f_max=f_max)


def modal(database_or_session: Any, campaign: str, *, sections: Sequence[str] | None = None,
          calibrate_params: Sequence[str] | None = None, progress: Progress | None = None,
          n_modes: int = 2) -> dict[str, Any]:
    """Identify the car body modes and, with ``calibrate_params``, fit those coach modal
    parameters (:data:`railval.core.calibration.COACH_MODAL_PARAMETERS`) to the ``n_modes`` best
    supported modes ([ref 3]). Returns a JSON-ready dict with ``modes`` and ``calibration``
    (the before/after frequency error table)."""
    _report(progress, "identify", 0.0)
    ident = identify_modes(database_or_session, campaign, sections=sections)
    out: dict[str, Any] = {"campaign": campaign, "identification": ident.to_dict(),
                           "stabilisation": ident.stabilisation_diagram()}
    if calibrate_params:
        unknown = [p for p in calibrate_params if p not in COACH_MODAL_PARAMETERS]
        if unknown:
            raise InvalidParameter(f"unknown modal parameter(s) {unknown}; known: {sorted(COACH_MODAL_PARAMETERS)}")
        with _session(database_or_session) as s:
            from railval.db import repo

            vinfo = repo.vehicle_info(s, campaign)
        if (vinfo.get("template") or "coach") != "coach":
            raise InvalidParameter(
                f"modal calibration models the coach template; campaign {campaign!r} uses "
                f"template {vinfo.get('template')!r} (identification alone works for any vehicle)")
        vparams = vinfo["parameters"]
        base = _coach_modal_base(vparams)
        best = sorted(ident.modes, key=lambda m: -m.n_stable)[:n_modes]
        best.sort(key=lambda m: m.freq_hz)
        if len(best) < 1:
            raise NotFound(f"campaign {campaign!r}: no stable mode identified between 0.5 and 4 Hz")
        specs = [ParameterSpec(p, *COACH_MODAL_PARAMETERS[p]) for p in calibrate_params]
        res = calibrate_modal([m.freq_hz for m in best], np.column_stack([m.shape for m in best]), specs,
                              base=base, progress=progress)
        out["calibration"] = res.to_dict()
    _report(progress, "done", 1.0)
    return out


def _coach_modal_base(vehicle_parameters: Mapping[str, Any]) -> dict[str, float]:
    """Coach modal model values from the simulator's coach template defaults overlaid by the
    campaign's vehicle parameters (``bogie_centres`` → ``bogie_half_distance``)."""
    merged: dict[str, float] = {}
    try:
        from railval.core.sim.vehicles import template_parameters

        merged.update({p.name: float(p.default) for p in template_parameters("coach")})
    except ImportError:  # pragma: no cover - the simulator ships with railval
        pass
    merged.update({k: float(v) for k, v in vehicle_parameters.items() if isinstance(v, (int, float))})
    base = {k: merged[k] for k in COACH_MODAL_DEFAULTS if k in merged}
    if "bogie_centres" in merged:
        base["bogie_half_distance"] = merged["bogie_centres"] / 2.0
    return base
