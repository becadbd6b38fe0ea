"""The diagnosis ranking service (issue 16): effects AND vehicle-template parameters as
candidate causes, each simulated once per value over the whole campaign, scored with
:func:`railval.core.diagnosis.diagnose_evidence` (held-out share over zone-stratified folds,
bootstrap noise floor, plausibility, identifiability, verdict).

Simulations
-----------
* the configuration itself (its residual and every candidate come from the same simulator);
* every effect not in the configuration: each parameter at ``values_per_parameter`` values
  over its bounds plus its default (as before);
* every template parameter of :data:`railval.core.diagnosis.PARAMETER_CANDIDATES`: ONE
  simulation at ``step`` × the model's value — a linearised sensitivity in log(value),
  extrapolated over the search box (docs/diagnosis.md);
* refinement: the parameter candidates that explain most (``refine``, default 3) whose fitted
  value lies more than 10 % away from a simulated value are simulated once more at that value
  (the response of a damper or stiffness is smooth but not linear over a factor of 3).

Workers return per-section validation pairs and band powers only (no signals).

Length: one diagnosis from loading the campaign to the cause set, in steps of ≤ 80 lines
(load, simulation tasks, candidate evidence, refinement, scoring) that share one request
record; splitting the steps over modules would pass that record across module boundaries.
"""

from __future__ import annotations

import dataclasses
import json
import math
import pickle
import threading
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from railval.app.services.batch import BatchExecutor
from railval.app.services.campaign_context import (
    acceleration_band_powers,
    band_sums,
    configuration_of,
    cut_to,
    effect_parameters,
    evaluated_span_end,
    load_context_and_measurement,
    residual_pattern,
    runnable_effects,
    section_values,
    session_of,
    simulate_context,
    validate_values,
)
from railval.app.services.campaign_context import report as _report
from railval.app.services.diagnosis_measurement import (
    DISCRETE_DEFAULTS,
    apply_redundancy_rule,
    discrete_families,
    offset_families,
    relative_gains,
    shared_gain,
)
from railval.app.services.diagnosis_next import next_step
from railval.core.diagnosis import (
    PARAMETER_CANDIDATES,
    QUANTITY_FAMILIES,
    CandidateFamily,
    DiagnosisResult,
    SectionEvidence,
    diagnose_evidence,
    diagnose_families,
    scan_values,
    section_evidence,
)
from railval.core.diagnosis.causes import cause_set
from railval.core.diagnosis.engine import STRONG
from railval.core.diagnosis.fit import INTERFACE_PARAMETERS, MASS_PARAMETERS
from railval.core.diagnosis.inputs import (
    CONTACT_CANDIDATES,
    contact_statement,
    scatter_level,
    track_first_pool,
    track_statement,
)
from railval.core.diagnosis.measurement import (
    force_gain_groups,
    gain_channels,
    gain_family,
    group_gain_families,
    group_gain_reevaluations,
)
from railval.core.diagnosis.screen import (
    SCREEN_SECTIONS,
    check_keep,
    floor_stand_ins,
    screen_order,
    screen_sections,
)
from railval.core.diagnosis.support import apply_interface_rule, cause_pool, outside_support
from railval.core.errors import InvalidParameter
from railval.core.sim.effects import EFFECTS, Effect, is_neutral, unmet_requirement
from railval.core.sim.vehicles import CONTACT_PARAMETER, template_parameters
from railval.db import repo
from railval.db.repo import config_name

Progress = Any


def scan_points(effect: Effect, values_per_parameter: int) -> Iterator[tuple[str, float, dict[str, float], dict]]:
    """The one-parameter scan of an effect: for each parameter and each of its
    :func:`railval.core.diagnosis.scan_values`, ``(parameter, value, all parameters at default
    but this one, its bounds record)``."""
    params = effect_parameters(effect)
    defaults = {k: float(v["default"]) for k, v in params.items()}
    for pname, p in params.items():
        for v in scan_values(p["lower"], p["upper"], p["default"], values_per_parameter, p["log"]):
            yield pname, v, {**defaults, pname: v}, p


# --------------------------------------------------------------------------- registry accessors
def plausible_range(param: Any) -> tuple[tuple[float, float] | None, str]:
    """The physically plausible range of a simulator parameter and its source, from the
    parameter registry (:class:`railval.core.sim.params.Param` ``plausible``/``plausible_source``);
    ``(None, "")`` where the registry gives none."""
    rng = getattr(param, "plausible", None)
    if rng is None:
        return None, ""
    return (float(rng[0]), float(rng[1])), str(getattr(param, "plausible_source", "") or "")


def template_param(template: str, name: str) -> Any:
    for p in template_parameters(template):
        if p.name == name:
            return p
    raise InvalidParameter(f"model parameter {name!r} is not a parameter of vehicle template {template!r}")


def model_value(ctx: Any, conf_params: Mapping[str, float], name: str) -> float:
    """The configuration's value of a template parameter (configuration override, else the
    campaign's vehicle record, else the template default)."""
    template = str(ctx.vehicle.get("template") or "coach")
    for src in (conf_params, {k.removeprefix("model."): v for k, v in conf_params.items()},
                ctx.vehicle.get("parameters") or {}):
        if name in src:
            return float(src[name])
    return float(template_param(template, name).default)


def parameter_plan(ctx: Any, conf_params: Mapping[str, float]) -> list[dict[str, Any]]:
    """The template parameters tried as candidates: name, model value, perturbed value,
    search bounds (log scale, inside the template bounds), unit, plain-language title,
    plausible range and source."""
    template = str(ctx.vehicle.get("template") or "coach")
    out = []
    for name, (step, lo_f, hi_f) in PARAMETER_CANDIDATES.get(template, {}).items():
        p = template_param(template, name)
        ref = model_value(ctx, conf_params, name)
        if not ref > 0:
            continue
        lo = max(float(p.lower), lo_f * ref, 1e-12)
        hi = min(float(p.upper), hi_f * ref)
        pert = float(min(max(step * ref, lo), hi))
        if not (lo < ref <= hi or lo <= ref < hi) or math.isclose(pert, ref):
            continue
        plaus, source = plausible_range(p)
        out.append({"name": f"model.{name}", "parameter": name, "reference": ref, "perturbed": pert,
                    "bounds": (lo, hi), "unit": p.unit, "title": str(p.description).split(" per ")[0],
                    "plausible": plaus, "source": source})
    return out


# --------------------------------------------------------------------------- workers
def _evaluate_sections(ctx: Any, job: tuple[dict, dict]) -> tuple[list[dict], dict[str, dict[str, np.ndarray]]]:
    """Worker task: simulate the campaign ``ctx`` (shared once per worker,
    :meth:`railval.app.services.batch.BatchExecutor.map`) with the job's ``effects`` and model
    ``parameters`` (a third item: the ids of the only sections to simulate, a screen's);
    return the validation pairs (section, zone, quantity, position, D_norm) and
    the band powers per section and acceleration channel (one Welch call for all sections). Each run
    stops at the evaluated range's end plus the EN filters' run-out
    (:func:`railval.app.services.campaign_context.evaluated_span_end`): the band powers cover
    that span, as :func:`measured_section_bands` does on the measured side."""
    effects, parameters, *only = job
    if only and only[0] is not None:  # a screen's or the rest's sections (each section is its own run)
        keep = set(only[0])
        ctx = dataclasses.replace(ctx, sections=[s for s in ctx.sections if s.id in keep])
    sets = simulate_context(ctx, effects, parameters, evaluated_only=True)
    vr = validate_values(ctx, section_values(sets, ctx.sections))
    pairs = _records(vr.pairs, ("section", "zone", "quantity", "position", "D_norm", "M", "S"))
    return pairs, acceleration_band_powers(sets, ctx.bands)


def _records(frame: Any, columns: Sequence[str]) -> list[dict[str, Any]]:
    """``frame[columns].to_dict("records")`` — the same Python scalars (``tolist`` per column)
    at a sixth of the cost: a diagnosis converts one validation table per campaign run."""
    return [dict(zip(columns, row, strict=True)) for row in zip(*(frame[c].tolist() for c in columns), strict=True)]


def measured_section_bands(ctx: Any, measured: Mapping[str, Any]) -> dict[str, dict[str, np.ndarray]]:
    """Band powers of the measurement (``measured``: section id → SignalSet, decoded once per
    diagnosis) per section and acceleration channel, over the span the diagnosis simulates: each
    section cut at :func:`railval.app.services.campaign_context.evaluated_span_end`, where the
    simulated runs of :func:`_evaluate_sections` stop (like compared with like)."""
    end = evaluated_span_end(ctx)
    return acceleration_band_powers({sid: cut_to(ss, end[sid]) if sid in end else ss
                                     for sid, ss in measured.items()}, ctx.bands)


# --------------------------------------------------------------------------- rank_causes
@dataclass
class _Request:
    """What one diagnosis simulates: the campaign context, the configuration (effects that can
    run, parameters), the measured band powers, the candidate effects and parameter plan."""

    ctx: Any
    config: str
    conf_effects: dict
    conf_params: dict
    config_sets: dict
    meas_bands: dict
    measured_sets: dict
    template: str
    skipped: list[dict]
    in_config: dict
    conf_skipped: list[dict]
    todo: list[str]
    plan: list[dict[str, Any]]


def rank_causes(database_or_session: Any, campaign: Any, config: Any, *, progress: Progress | None = None,
             scheduler: Any = None, values_per_parameter: int = 3, effects: Sequence[str] | None = None,
             parameters: Sequence[str] | None = None, include_parameters: bool = True,
             measurement: bool | Sequence[str] = True,
             workers: int | None = None, n_boot: int = 100, folds: int = 3, refine: int = 3,
             seed: int = 0, screen: int | None = None) -> DiagnosisResult:
    """Rank the effects missing from ``config`` and the template parameters that may be mis-set
    by the share of the residual they explain on held-out sections, with noise floor,
    plausibility, identifiability and a verdict (module docstring;
    :func:`railval.core.diagnosis.diagnose_evidence`). ``effects``/``parameters`` restrict the
    candidates (``measurement``: the measurement-side candidates ``gain CHANNEL`` —
    :mod:`railval.core.diagnosis.measurement` — all, none or those named; ``offset CHANNEL``
    only when named;
    ``parameters``: template names or ``model.NAME``; ``include_parameters=False``:
    effects only). ``screen``: simulate every effect and parameter candidate on a few sections
    first and only the ``screen`` best on the whole campaign (:func:`_simulate_screened`; the
    others are listed in ``result.screen``, not ranked). Steps: load, simulate the candidates,
    build their evidence, refine the best parameter candidates, score (:func:`_score`)."""
    keep = None if screen is None else check_keep(screen)  # refused before anything is read
    _report(progress, "load", 0.0, campaign=getattr(campaign, "name", campaign), config=config_name(config))
    req = _load(database_or_session, campaign, config, effects, parameters, include_parameters, measurement)
    ctx, config = req.ctx, req.config
    stored_residual, vr = residual_pattern(ctx, section_values(req.config_sets, ctx.sections),
                                           band_sums(req.config_sets, ctx.bands))
    tasks, index = _tasks(req, values_per_parameter)
    total = len(tasks) + (refine if req.plan else 0)
    _report(progress, "simulate", 0.05, tasks=total)
    screened = keep is not None and _screenable(req, index, keep)
    with BatchExecutor(scheduler, workers) as ex:
        if screened:
            sims, index, screen_info = _simulate_screened(
                ex, req, tasks, index, vr, measurement, _Refinement(refine, folds, seed), keep,
                lambda lo, hi: lambda d, t: _report(progress, "simulate", lo + (hi - lo) * (d + 1) / max(t, 1),
                                                    done=d + 1, total=t))
        else:
            sims = _simulate(ex, req, tasks, index, vr, measurement, _Refinement(refine, folds, seed),
                             lambda d, t: _report(progress, "simulate", 0.05 + 0.8 * (d + 1) / total, done=d + 1,
                                                  total=total))
        base, fams = _candidates(req, sims.results, index, vr, sims.base, sims.measured, sims.made)
        n_sim = len(tasks) + _refine(req, base, fams, sims.redo, sims.refined)
        if screened:
            n_sim = math.ceil(screen_info["section_runs"] / len(ctx.sections))
        _report(progress, "score", 0.9)
        res = _score(base, fams + sims.floor, bool(vr.validated), req.template, n_boot=n_boot, folds=folds,
                     seed=seed, ex=ex)
    res.campaign, res.configuration, res.validated = ctx.campaign, config, bool(vr.validated)
    res.effects_in_configuration = sorted(req.conf_effects)
    res.parameters_in_configuration = dict(req.conf_params)
    res.values_per_parameter, res.simulations = values_per_parameter, n_sim
    res.stored_residual_norm = math.sqrt(stored_residual.norm2())
    res.simulated_residual_norm = math.sqrt(res.residual.norm2())
    res.effects_simulated = sorted(req.in_config)
    if screen is not None:
        res.screen = screen_info if screened else {"applied": False, "kept": screen, "reason": (
            f"{len(ctx.sections)} sections, {len({x[1] for x in index})} simulated candidates: nothing to screen")}
        if screened:
            res.note += (f"; screened: {screen} of {screen_info['candidates']} simulated candidates kept after "
                         f"{len(screen_info['sections'])} sections ({', '.join(screen_info['sections'])}), the "
                         "others not ranked; noise floor over every candidate, the screened-out ones' on the "
                         "other sections estimated from the screen section of the same test zone")
    res.skipped = req.conf_skipped + req.skipped
    if req.skipped and not fams:
        res.note += "; left out: " + "; ".join(f"{s['name']} ({s['reason']})" for s in req.skipped)
    if req.conf_skipped:
        res.note += "; " + "; ".join(f"effect {s['name']} {s['reason']}" for s in req.conf_skipped)
    res.next_step = next_step(res, ctx.campaign, config)
    _report(progress, "done", 1.0)
    return res


def _load(database_or_session: Any, campaign: Any, config: Any, effects: Sequence[str] | None,
          parameters: Sequence[str] | None, include_parameters: bool,
          measurement: bool | Sequence[str]) -> _Request:
    """Read the campaign and configuration (names resolved once, unless given as the references
    of :func:`railval.db.repo.resolve`; the measurement decoded once); the candidate effects
    that can apply and the parameter plan (``parameter_plan`` once)."""
    with session_of(database_or_session) as s:
        campaign, ref = repo.resolve(s, campaign, config)
        config = ref.name
        ctx, measured = load_context_and_measurement(s, campaign)
        conf_effects, conf_params, _ = configuration_of(s, campaign, ref, simulated_in=ctx)
        config_sets = repo.load_signalsets(s, campaign, ref)
    meas_bands = measured_section_bands(ctx, measured)
    named = bool(measurement) and (measurement is not True or bool(DISCRETE_DEFAULTS))
    # named offsets and gains of shared channels re-evaluate the measurement from its signals
    measured_sets = measured if named else {}
    registry = EFFECTS
    unknown = [e for e in (effects or ()) if e not in registry]
    if unknown:
        raise InvalidParameter(f"unknown effect(s) {unknown}; known: {sorted(registry)}")
    template = str(ctx.vehicle.get("template") or "coach")
    skipped = inapplicable_effects(ctx, conf_effects, effects) + profile_skipped(conf_params, effects)
    # an effect of the configuration itself that cannot apply: simulated without it, said so
    in_config, conf_skipped = runnable_effects(ctx, conf_effects, config)
    todo = [e for e in (effects if effects is not None else registry) if e not in conf_effects
            and template in registry[e].templates and e not in {x["name"] for x in skipped}]
    every = parameter_plan(ctx, conf_params)
    plan = every if include_parameters else []
    if parameters:
        wanted = {p.removeprefix("model.") for p in parameters}
        bad = sorted(wanted - {p["parameter"] for p in every})
        if bad:
            raise InvalidParameter(f"parameter candidate(s) {bad} unknown; known: "
                                   f"{sorted(p['parameter'] for p in every)}")
        plan = [p for p in every if p["parameter"] in wanted]
    return _Request(ctx, config, dict(conf_effects), dict(conf_params), config_sets, meas_bands, measured_sets,
                    template, skipped, in_config, conf_skipped, todo, plan)


def _tasks(req: _Request, values_per_parameter: int) -> tuple[list[tuple], list[tuple]]:
    """The simulations (the configuration first, then every effect scan point once, then one
    perturbed value per parameter candidate) and, per candidate value, which one it uses; a scan
    point at which the effect is neutral (:func:`railval.core.sim.effects.is_neutral`: the
    simulator computes exactly what it computes without it) uses the configuration's own run."""
    tasks: list[tuple] = [(req.in_config, req.conf_params)]
    index: list[tuple] = []
    unique: dict[str, int] = {}
    for e in req.todo:
        spec = EFFECTS[e]
        defaults = {k: float(q["default"]) for k, q in effect_parameters(spec).items()}
        for pname, v, point, _p in scan_points(spec, values_per_parameter):
            if is_neutral(spec, point):  # simulates exactly as the configuration itself: its run
                index.append(("effect", e, pname, v, defaults, 0))
                continue
            key = json.dumps({**req.in_config, e: point}, sort_keys=True)
            if key not in unique:
                unique[key] = len(tasks)
                tasks.append(({**req.in_config, e: point}, req.conf_params))
            index.append(("effect", e, pname, v, defaults, unique[key]))
    for p in req.plan:
        index.append(("parameter", p["name"], p["parameter"], p["perturbed"], {}, len(tasks)))
        tasks.append((req.in_config, {**req.conf_params, p["parameter"]: p["perturbed"]}))
    return tasks, index


@dataclass
class _Refinement:
    """How many parameter candidates are simulated again at their fitted value, and the folds
    and seed of the first ranking that picks them (:func:`_refinement`)."""

    count: int
    folds: int
    seed: int


@dataclass
class _Simulated:
    """What :func:`_simulate` hands on: the campaign runs in task order, the configuration's
    evidence, the measurement families, the parameter candidates' evidence (task index →
    evidence), the refinement picked from them and its runs (and a screen's ``floor``)."""

    results: list
    base: SectionEvidence
    measured: dict[str, CandidateFamily]
    made: dict[int, SectionEvidence]
    redo: list[tuple[str, float]]
    refined: list
    #: a screened diagnosis's screened-out candidates as floor-only stand-ins (:func:`_screen`)
    floor: list[CandidateFamily] = field(default_factory=list)


def _simulate(ex: Any, req: _Request, tasks: list[tuple], index: Sequence[tuple], vr: Any,
              measurement: bool | Sequence[str], refine: _Refinement, progress: Any) -> _Simulated:
    """The campaign simulations, the measurement-side candidates and the refinement. The
    workers take ``tasks[1:]``, the parameter candidates' runs first; meanwhile this thread
    simulates the configuration (``tasks[0]``), its per-section evidence and, from it, the
    measurement candidates (the measured signals re-evaluated at their gain and offset nodes),
    then, once the parameter runs are in, picks the refinement from the parameter candidates
    alone (:func:`_refinement`) and hands its runs to the workers behind the effects' runs — the
    pool never waits for the first ranking. The same results as one map of every task followed
    by the refinement (candidates are ranked each on its own)."""
    sections = [(s.id, int(s.zone)) for s in req.ctx.sections]
    params = [k for kind, *_, k in index if kind == "parameter"]
    order = params + sorted(set(range(1, len(tasks))) - set(params))
    ex.start(shared=req.ctx)  # in this thread: a pool started from the main thread forks
    handles = dict(zip(order, ex.submit(_evaluate_sections, [tasks[k] for k in order], shared=req.ctx),
                       strict=True))
    rest: list = []
    failed: list[BaseException] = []

    def run() -> None:
        try:
            rest.extend(ex.gather([handles[k] for k in range(1, len(tasks))], progress=progress))
        except BaseException as exc:  # noqa: BLE001 - raised again in the calling thread
            failed.append(exc)

    waiter = threading.Thread(target=run, name="railval-diagnosis-map", daemon=True)
    if ex.backend != "serial":  # serial: every run in this thread, in task order
        waiter.start()
    try:
        first = _evaluate_sections(req.ctx, tasks[0])
        base = section_evidence(first[0], first[1], req.meas_bands, sections, value_key="D_norm")
        if ex.backend == "serial":
            run()
        measured = _measurement_families(req, first, base, sections, vr, measurement) if measurement else {}
        made = {k: section_evidence(*res, req.meas_bands, sections, value_key="D_norm", like=base)
                for k, res in zip(params, ex.gather([handles[k] for k in params]), strict=True)}
        redo = _refinement(req, base, index, made, bool(vr.validated), refine)
        more = ex.submit(_evaluate_sections, [(req.in_config, {**req.conf_params, p: v}) for p, v in redo],
                         shared=req.ctx)
    finally:
        if waiter.is_alive():
            waiter.join()
    if failed:
        raise failed[0]
    refined = ex.gather(more, progress=lambda d, t: progress(len(tasks) - 1 + d, t))
    return _Simulated([first, *rest], base, measured, made, redo, refined)


def _simulate_screened(ex: Any, req: _Request, tasks: list[tuple], index: Sequence[tuple], vr: Any,
                       measurement: bool | Sequence[str], refine: _Refinement, keep: int,
                       stage: Any) -> tuple[_Simulated, list[tuple], dict[str, Any]]:
    """The screened diagnosis's simulations (docs/diagnosis.md "Screened diagnosis",
    :mod:`railval.core.diagnosis.screen`): every candidate run on the screen sections while this
    thread simulates the configuration on every section and builds the measurement candidates;
    then the ``keep`` candidates that explain most on the screen on the other sections (each
    section is its own run, so a kept candidate's runs are those of the whole diagnosis), then
    the refinement among the kept parameter candidates. Returns what :func:`_simulate` returns,
    the index of the kept candidates' values and the screen's record. ``stage(lo, hi)``: a
    progress callback ``(done, total)`` over that part of the progress bar."""
    sections = [(s.id, int(s.zone)) for s in req.ctx.sections]
    on = screen_sections(sections)
    rest = [sid for sid, _ in sections if sid not in set(on)]
    ex.start(shared=req.ctx)
    handles = ex.submit(_evaluate_sections, [(*tasks[k], on) for k in range(1, len(tasks))], shared=req.ctx)
    first = _evaluate_sections(req.ctx, tasks[0])
    base = section_evidence(first[0], first[1], req.meas_bands, sections, value_key="D_norm")
    measured = _measurement_families(req, first, base, sections, vr, measurement) if measurement else {}
    part = [first, *ex.gather(handles, progress=stage(0.05, 0.4))]
    kept, out, floor = _screen(req, index, part, base, on, bool(vr.validated), refine, keep)
    index = [x for x in index if x[1] in kept]
    params = [k for kind, *_, k in index if kind == "parameter"]
    later = params + sorted({k for *_, k in index if k} - set(params))  # parameters first, as _simulate
    handles = ex.submit(_evaluate_sections, [(*tasks[k], rest) for k in later], shared=req.ctx)
    merged = {k: _joined(part[k], w) for k, w in zip(params, ex.gather(handles[:len(params)]), strict=True)}
    made = {k: section_evidence(*merged[k], req.meas_bands, sections, value_key="D_norm", like=base) for k in params}
    redo = _refinement(req, base, index, made, bool(vr.validated), refine)  # while the effects' runs go on
    halves = [[sid for sid, _ in sections[h::2]] for h in (0, 1)]  # 2 tasks a run: both workers to the end
    more = ex.submit(_evaluate_sections, [(req.in_config, {**req.conf_params, p: v}, half) for p, v in redo
                                          for half in halves], shared=req.ctx)
    merged.update({k: _joined(part[k], w) for k, w in zip(
        later[len(params):], ex.gather(handles[len(params):], progress=stage(0.4, 0.75)), strict=True)})
    results = [first] + [merged.get(k) for k in range(1, len(tasks))]
    got = ex.gather(more, progress=stage(0.75, 0.85))
    refined = [_joined(a, b) for a, b in zip(got[::2], got[1::2], strict=True)]
    info = {"applied": True, "kept": keep, "sections": on, "candidates": len(kept) + len(out),
            "screened_out": out, "floor_stand_ins": len(floor),
            "section_runs": (len(tasks) - 1) * len(on) + len(later) * len(rest) + (1 + len(redo)) * len(sections),
            "section_runs_whole": (len(tasks) + len(redo)) * len(sections)}
    return _Simulated(results, base, measured, made, redo, refined, floor), index, info


def _joined(a: tuple, b: tuple) -> tuple:
    """One campaign run from two runs of :func:`_evaluate_sections` on disjoint sections: their
    validation pairs one after the other, their band powers together (each section is its own
    run, so a section's records and powers are those of the whole run)."""
    return a[0] + b[0], {**a[1], **b[1]}


def _screen(req: _Request, index: Sequence[tuple], part: Sequence[tuple], base: SectionEvidence,
            on: Sequence[str], validated: bool, refine: _Refinement,
            keep: int) -> tuple[set[str], list[dict], list[CandidateFamily]]:
    """(names kept, the screened-out candidates with their shares on the screen, their
    floor-only stand-ins over every section): the candidates' families on the screen sections
    ``on`` (``part[k]``: task ``k``'s runs there, the configuration's ``part[0]`` on every
    section; ``base`` the configuration's evidence on every section), ordered by
    :func:`railval.core.diagnosis.screen.screen_order`; a candidate that moves nothing on the
    screen is screened out with share 0 (and has no stand-in: it moves no pattern)."""
    sections = [(s.id, int(s.zone)) for s in req.ctx.sections if s.id in set(on)]
    made: dict[int, SectionEvidence] = {}

    def evidence(k: int) -> SectionEvidence:
        if k not in made:
            made[k] = section_evidence(part[k][0], part[k][1], req.meas_bands, sections, value_key="D_norm", like=base)
        return made[k]

    fams = list(_families(req, index, evidence, evidence(0)).values())
    blind = _without_effect(evidence(0), fams)
    fams = _best_per_effect(evidence(0), [f for f in fams if f not in blind], validated)
    kept, out = screen_order(evidence(0), fams, keep, validated=validated, folds=refine.folds, seed=refine.seed)
    ranked = set(kept) | {x["name"] for x in out}
    floor = floor_stand_ins(base, evidence(0), [f for f in fams if f.name not in kept])
    out += [{"name": name, "kind": kind, "explained_on_screen": 0.0, "held_out_on_screen": 0.0}
            for name, kind in dict.fromkeys((f.name, f.kind) for f in blind if f.name not in ranked)]
    return set(kept), out, floor


def _screenable(req: _Request, index: Sequence[tuple], keep: int) -> bool:
    """Whether a screen keeping ``keep`` candidates leaves anything out: more sections than a
    screen simulates and more simulated candidates than it keeps."""
    return len(req.ctx.sections) > SCREEN_SECTIONS and len({x[1] for x in index}) > keep


def _refinement(req: _Request, base: SectionEvidence, index: Sequence[tuple], made: Mapping[int, SectionEvidence],
                validated: bool, refine: _Refinement) -> list[tuple[str, float]]:
    """(template parameter, value) of the ``refine.count`` best parameter candidates whose
    fitted value lies > 10 % from a simulated one, best first. Ranked among the parameter
    candidates alone: every candidate is scored on its own and the ranking is a stable sort, so
    their order is the one they have among all candidates (the choice the full first ranking
    made)."""
    if not (req.plan and refine.count):
        return []
    fams = [_parameter_family(req, name, v, base, made[k]) for kind, name, _p, v, _d, k in index
            if kind == "parameter"]
    blind = _without_effect(base, fams)
    fams = [f for f in fams if f not in blind]
    first = diagnose_evidence(base, fams, validated=validated, n_boot=0, folds=refine.folds, seed=refine.seed)
    redo: list[tuple[str, float]] = []
    for c in first.candidates:
        if len(redo) >= refine.count:
            break
        fam = next(f for f in fams if f.name == c.name)
        v = c.fitted  # inside the bounds: core.diagnosis.fit._Curve.value clamps it
        if min(abs(math.log(v / x)) for x in fam.values) > math.log(1.1):
            redo.append((fam.parameter, v))
    return redo


def _parameter_family(req: _Request, name: str, value: float, base: SectionEvidence,
                      evidence: SectionEvidence) -> CandidateFamily:
    """The candidate family of template parameter ``name``: the model's value (the
    configuration's run) and the perturbed ``value`` (its sensitivity run)."""
    pp = next(x for x in req.plan if x["name"] == name)
    return CandidateFamily(
        "parameter", name, pp["parameter"], [pp["reference"], value], [base, evidence], pp["bounds"], log=True,
        extrapolate=True, reference=pp["reference"], plausible=pp["plausible"], plausible_source=pp["source"],
        unit=pp["unit"], title=pp["title"], interface=pp["parameter"] in INTERFACE_PARAMETERS)


def _candidates(req: _Request, results: Sequence, index: Sequence[tuple], vr: Any, base: SectionEvidence,
                measured: Mapping[str, CandidateFamily],
                made: dict[int, SectionEvidence]) -> tuple[SectionEvidence, list[CandidateFamily]]:
    """Per-section evidence of the candidate values and the candidate families (effects,
    parameters, then the ``measured`` candidates of :func:`_simulate`); candidates that move
    nothing the campaign measures go to ``req.skipped``; of an effect's one-parameter families
    the one that explains most."""
    ctx = req.ctx
    sections = [(s.id, int(s.zone)) for s in ctx.sections]

    made: dict[int, SectionEvidence] = {}

    def evidence(k: int) -> SectionEvidence:  # once per simulation (a shared one: the same object)
        if k not in made:
            made[k] = section_evidence(results[k][0], results[k][1], req.meas_bands, sections, value_key="D_norm",
                                       like=base)
        return made[k]

    families = _families(req, index, evidence, base)
    families.update(measured)
    blind = _without_effect(base, list(families.values()))
    req.skipped += [{"name": f.name, "kind": f.kind, "reason": "changes none of the quantities the campaign "
                     "measures at any simulated value"} for f in blind
                    if not any(s["name"] == f.name for s in req.skipped)]
    # an effect with several parameters is one candidate: the parameter that explains most
    return base, _best_per_effect(base, [f for f in families.values() if f not in blind], vr.validated)


def _families(req: _Request, index: Sequence[tuple], evidence: Any, base: SectionEvidence) -> dict[str, CandidateFamily]:
    """The effect families (one per effect parameter) and parameter families of the candidate
    values in ``index``; ``evidence(k)``: the evidence of task ``k``, ``base`` the configuration's."""
    families: dict[str, CandidateFamily] = {}
    for kind, name, pname, v, defaults, k in index:
        if kind == "effect":
            spec = EFFECTS[name]
            p = effect_parameters(spec)[pname]
            key = f"{name}.{pname}"
            if key not in families:
                plaus, source = plausible_range(spec.parameters[pname])
                families[key] = CandidateFamily(
                    "effect", name, pname, [], [], (p["lower"], p["upper"]), log=p["log"], defaults=defaults,
                    plausible=plaus, plausible_source=source, unit=p["unit"],
                    title=spec.title, explanation=spec.explanation, interface=spec.interface)
            families[key].values.append(v)
            families[key].evidence.append(evidence(k))
        else:
            families[name] = _parameter_family(req, name, v, base, evidence(k))
    return families


def _measurement_families(req: _Request, result0: tuple, base: SectionEvidence, sections: list,
                          vr: Any, measurement: bool | Sequence[str]) -> dict[str, CandidateFamily]:
    """The measurement-side candidates (``gain CHANNEL``, named ``offset CHANNEL``, and the
    discrete ``sign``, ``swap`` and ``shift`` candidates)."""
    out: dict[str, CandidateFamily] = {}
    limits = {q: r.std_limit for q, r in vr.quantities.items()}
    chans = gain_channels(result0[0])
    wanted_m = None if measurement is True else {m.removeprefix("gain ") for m in measurement
                                                 if m.startswith("gain ")}
    groups = force_gain_groups(req.ctx.channels) if req.measured_sets else {}
    out.update(force_gain_families(req, result0, base, sections, limits, groups, wanted_m))
    for bad in sorted((wanted_m or set()) - set(chans) - set(groups)):
        fam = shared_gain(req.ctx, req.measured_sets, bad, base, result0, req.meas_bands, sections, limits)
        if fam is not None:
            out[fam.name] = fam
        else:
            req.skipped.append({"name": f"gain {bad}", "kind": "measurement", "reason": "not a channel of this "
                                "campaign whose quantities it forms alone, nor a low-pass channel they use"})
    for ch, comps in chans.items():
        if wanted_m is None or ch in wanted_m:
            out[f"gain {ch}"] = gain_family(base, result0[0], result0[1], req.meas_bands, sections, ch,
                                            comps, limits, bands=req.ctx.bands)
    out.update(offset_families(req.ctx, req.measured_sets, measurement, base, result0, req.meas_bands, sections,
                               limits, req.skipped))
    out.update(discrete_families(req.ctx, req.measured_sets, req.config_sets, measurement, base, result0,
                                 req.meas_bands, sections, limits, req.skipped, defaults=DISCRETE_DEFAULTS))
    return out


def force_gain_families(req: _Request, result0: tuple, base: SectionEvidence, sections: list,
                        limits: Mapping[str, float], groups: Mapping[str, Sequence[str]],
                        wanted: set[str] | None) -> dict[str, CandidateFamily]:
    """The ``gain GROUP`` candidates of the wheel-force channels (per wheel, wheelset, side and
    bogie, :func:`railval.core.diagnosis.measurement.force_gain_groups`): all of them by default,
    those named otherwise; judged on the measurement corrected by the power law of each
    quantity, ΣY of a group holding one wheel of it re-evaluated from the signals."""
    chosen = {n: g for n, g in groups.items() if wanted is None or n in wanted}
    comps = sorted({(str(r["quantity"]), str(r["position"])) for r in result0[0]})
    redo = group_gain_reevaluations(req.measured_sets, req.ctx.sections, chosen, comps) if chosen else {}
    fams = group_gain_families(base, result0[0], result0[1], req.meas_bands, sections, chosen, limits, redo,
                               bands=req.ctx.bands)
    return {fam.name: fam for fam in fams.values()}


def _refine(req: _Request, base: SectionEvidence, fams: list[CandidateFamily], redo: Sequence[tuple[str, float]],
            refined: Sequence) -> int:
    """Add the refinement's runs (:func:`_simulate`, picked by :func:`_refinement`) to their
    parameter families; returns the number of simulations added."""
    sections = [(s.id, int(s.zone)) for s in req.ctx.sections]
    for (parameter, v), res in zip(redo, refined, strict=True):
        fam = next(f for f in fams if f.kind == "parameter" and f.parameter == parameter)
        fam.values.append(v)
        fam.evidence.append(section_evidence(res[0], res[1], req.meas_bands, sections, value_key="D_norm", like=base))
    return len(redo)


#: the quantity families judged on each pool worker while the calling thread ranks the
#: candidates and their support (:func:`_ranked`; measured 0.3–0.9, 1.2–1.4, 0.6, 0.6–0.9 s of
#: one core for guiding, wheel, car body and supplementary on the bench campaign)
FAMILY_SPLIT = (("guiding", "carbody"), ("wheel", "supplementary"))


def _families_task(job: tuple[bytes, Sequence[str]]) -> list[dict[str, Any]]:
    """Worker task: :func:`railval.core.diagnosis.diagnose_families` of the quantity families
    ``names`` on the evidence pickled in ``blob``."""
    blob, names = job
    base, fams, validated, n_boot, folds, seed = pickle.loads(blob)  # this process's own bytes
    return diagnose_families(base, fams, validated=validated, n_boot=n_boot, folds=folds, seed=seed, names=names)


def _ranked(ex: Any, base: SectionEvidence, fams: list[CandidateFamily], validated: bool, *, n_boot: int,
            folds: int, seed: int) -> tuple[DiagnosisResult, list[dict[str, Any]], dict]:
    """The held-out ranking, the per-family judgements and the support outside the guiding
    forces. With a pool or a Dask cluster the families are judged on the workers
    (:data:`FAMILY_SPLIT`) while this thread makes the ranking and the support: the evidence is
    pickled once, here, before either starts (the ranking fills memos on the evidence), and
    each family is judged on its own components alone, so the result equals the serial one
    (tests/test_diagnosis_scoring_overlap.py compares them whole)."""
    kw = {"n_boot": n_boot, "folds": folds, "seed": seed}
    if ex is None or ex.backend == "serial":
        res = diagnose_evidence(base, fams, validated=validated, **kw)
        families = diagnose_families(base, fams, validated=validated, **kw)
        return res, families, outside_support(base, fams, **kw)
    blob = pickle.dumps((base, fams, validated, n_boot, folds, seed), protocol=pickle.HIGHEST_PROTOCOL)
    parts: list[list[dict[str, Any]]] = []
    failed: list[BaseException] = []

    def run() -> None:
        try:
            # a family missing from FAMILY_SPLIT (one added later) goes with the last part
            rest = tuple(n for n in QUANTITY_FAMILIES if not any(n in part for part in FAMILY_SPLIT))
            split = [*FAMILY_SPLIT[:-1], FAMILY_SPLIT[-1] + rest]
            ref = ex.broadcast(blob)  # Dask: scattered once, not inside each task through the scheduler
            parts.extend(ex.map(_families_task, [(ref, names) for names in split]))
        except BaseException as exc:  # noqa: BLE001 - raised again in the calling thread
            failed.append(exc)

    waiter = threading.Thread(target=run, name="railval-diagnosis-families", daemon=True)
    waiter.start()
    try:
        res = diagnose_evidence(base, fams, validated=validated, **kw)
        support = outside_support(base, fams, **kw)
    finally:
        waiter.join()
    if failed:
        raise failed[0]
    order = list(QUANTITY_FAMILIES)
    return res, sorted((f for part in parts for f in part), key=lambda f: order.index(f["name"])), support


def _score(base: SectionEvidence, fams: list[CandidateFamily], validated: bool, template: str, *, n_boot: int,
           folds: int, seed: int, ex: Any = None) -> DiagnosisResult:
    """Held-out ranking and verdict, per family, the interface rule (support outside the guiding
    forces, core/diagnosis/support.py) and the cause set (``ex``: the diagnosis's executor,
    :func:`_ranked`)."""
    res, res.families, support = _ranked(ex, base, fams, validated, n_boot=n_boot, folds=folds, seed=seed)
    # interface candidates need support outside the guiding forces (core/diagnosis/support.py)
    apply_interface_rule(res, res.families, support, base, strong=STRONG)
    res.interface_support = [x.to_dict() for x in support.values()]
    relative_gains(res)
    no_fault = apply_redundancy_rule(res)
    # the pool: candidates beyond the noise floor on the whole residual, and the best of every
    # family that has one (a second cause may be small beside the first but lead its family)
    leads = {f["top"][0]["name"] for f in res.families if f["top"] and f["verdict"] in ("cause", "uncertain")}
    pool, left_out = cause_pool([f for f in fams if not f.floor_only and (f.name in leads or any(
        c.name == f.name and c.significant for c in res.candidates))], res, support, MASS_PARAMETERS)
    # input-side statements: the generated track's level, the contact geometry (core/diagnosis/inputs.py)
    track = sorted(e for e, spec in EFFECTS.items() if spec.input_side == "track")
    res.statements = [x for x in [track_statement(res, track)] if x]
    pool, track_out = track_first_pool(pool, res, track)
    left_out += track_out + [{"name": f.name, "reason": "not a sensor fault: " + no_fault[f.name]}
                             for f in pool if f.name in no_fault]
    pool = [f for f in pool if f.name not in no_fault]
    if res.verdict == "none" or not pool:
        cs = {"causes": [], "held_out_explained": 0.0, "remaining_within_noise": bool(res.residual_within_noise),
              "stopped": "verdict none: " + res.note if res.verdict == "none" else
              "every candidate beyond the section scatter is left out (left_out)" if left_out else
              "no candidate explains more than the section scatter"}
    else:
        later = {f["top"][0]["name"] for f in res.families if f["top"]}
        cs = cause_set(base, pool, folds=folds, n_boot=n_boot, seed=seed, later=sorted(later))
    rel = {c.name: c.parameters.get("relative_gain") for c in res.candidates}
    for x in cs["causes"]:
        if rel.get(x["name"]) is not None:
            x["relative_gain"] = rel[x["name"]]
    res.causes = cs.pop("causes")
    cs["left_out"] = left_out
    res.cause_set = cs
    covered = any(x["name"] == "conicity" for x in res.causes) and bool(cs["remaining_within_noise"])
    res.statements += [x for x in [contact_statement(res, base, scatter_level(base, n_boot, seed), covered,
                                                     interface=set(support))] if x]
    return res


def profile_skipped(conf_params: Mapping[str, Any], effects: Sequence[str] | None) -> list[dict]:
    """The contact-geometry candidates (``conicity``) left out, with the reason, when the
    configuration carries measured profiles (template parameter ``contact_geometry``, a Δr(y)
    table: docs/diagnosis.md "Contact geometry"): the simulator then uses the table, a conicity
    changes nothing; ``[]`` without a table or when no such candidate is asked for."""
    table = conf_params.get(CONTACT_PARAMETER) or conf_params.get("model." + CONTACT_PARAMETER)
    if not table:
        return []
    src = table.get("source") if isinstance(table, Mapping) else None
    return [{"name": e, "kind": "effect",
             "reason": f"the configuration carries measured profiles (rolling-radius difference table"
                       f"{' ' + repr(src) if src else ''}): the simulator uses the table, not a conicity"}
            for e in sorted(CONTACT_CANDIDATES) if effects is None or e in effects]


def inapplicable_effects(ctx: Any, conf_effects: Mapping[str, Any], effects: Sequence[str] | None) -> list[dict]:
    """The candidate effects that cannot apply to the campaign, each ``{"name", "kind":
    "effect", "reason"}`` with a one-line reason (:func:`railval.core.sim.effects.unmet_requirement`:
    track data the sections do not carry, quantities the campaign does not measure); effects
    of another vehicle template are named only when asked for (``effects``)."""
    template = str(ctx.vehicle.get("template") or "coach")
    measured = {q for values in ctx.measured_values.values() for q, _ in values}
    out = []
    for e in (effects if effects is not None else EFFECTS):
        if e in conf_effects:
            continue
        if template not in EFFECTS[e].templates:
            if effects is not None:
                out.append({"name": e, "kind": "effect",
                            "reason": f"applies to the {', '.join(EFFECTS[e].templates)} template only, "
                                      f"the campaign's vehicle is a {template}"})
            continue
        reason = unmet_requirement(EFFECTS[e], ctx.layouts, measured)
        if reason:
            out.append({"name": e, "kind": "effect", "reason": reason})
    return out


def _without_effect(base: SectionEvidence, fams: Sequence[CandidateFamily]) -> list[CandidateFamily]:
    """The families whose every simulated value leaves the campaign's pattern exactly as it is
    (nothing the campaign measures moves): nothing to fit, nothing to rank."""
    ref = base.values()
    return [f for f in fams if all(np.array_equal(e.values(), ref) for e in f.evidence)]


def _best_per_effect(base: SectionEvidence, fams: list[CandidateFamily], validated: bool) -> list[CandidateFamily]:
    """Keep, of an effect's one-parameter families, the one that explains most (all
    sections; as the former ranking did); parameter candidates pass through."""
    by_effect: dict[str, list[CandidateFamily]] = {}
    out = []
    for f in fams:
        if f.kind == "effect":
            by_effect.setdefault(f.name, []).append(f)
        else:
            out.append(f)
    for group in by_effect.values():
        if len(group) == 1:
            out.append(group[0])
            continue
        res = diagnose_evidence(base, group, validated=validated, n_boot=0, folds=2)
        best = max(res.candidates, key=lambda c: c.explained)
        out.append(next(f for f in group if f.parameter == best.parameter))
    return out
