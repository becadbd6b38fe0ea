"""The campaign as the diagnosis and calibration services see it (docs/design.md §7): one
:class:`CampaignContext` (vehicle, sections, layouts, the measurement evaluated once), the
simulator adapter and the worker task that simulates and evaluates the campaign.

:func:`simulate_context` is the one place these services call the built-in simulator
(:mod:`railval.core.sim`); the task sent to the workers (:func:`evaluate_effects`) is
top-level so it pickles by reference.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from sqlalchemy.orm import Session

from railval.app.services.simulation import simulation_inputs
from railval.core.diagnosis import (
    DEFAULT_BANDS_HZ,
    Pattern,
    band_ratio_pattern,
    pattern_from_pairs,
    sections_band_powers,
)
from railval.core.en14363 import evaluate_present
from railval.core.errors import InvalidParameter, NotFound
from railval.core.filters import run_out_s
from railval.core.sim import simulate_campaign
from railval.core.sim.effects import EFFECTS, Effect, unmet_requirement
from railval.core.sim.vehicles import template_for, unknown_parameters
from railval.core.supplementary import supplementary_pattern
from railval.core.types import SectionInfo, SignalSet
from railval.core.validation import ValidationResult, validate
from railval.db import repo
from railval.db.engine import connect

Progress = Callable[[str, float, dict[str, Any]], None]

ACC_CHANNELS = ("ay_cb_b1", "ay_cb_b2", "az_cb_b1", "az_cb_b2")


@contextmanager
def session_of(database_or_session: Any, *, write: bool = False) -> Iterator[Any]:
    """Yield a session from a :class:`railval.db.engine.Database`, a URL string or a Session
    (used as it is: its owner commits). ``write=True`` for a unit of work that writes
    (:meth:`railval.db.engine.Database.session`)."""
    if isinstance(database_or_session, Session):
        yield database_or_session
        return
    if database_or_session is None or isinstance(database_or_session, str):
        database_or_session = connect(database_or_session)
    with database_or_session.session(write=write) as s:
        yield s


def report(progress: Progress | None, stage: str, fraction: float, **info: Any) -> None:
    """Call ``progress(stage, fraction clipped to [0, 1], info)`` when a callback is given."""
    if progress is not None:
        progress(stage, float(min(max(fraction, 0.0), 1.0)), info)


@dataclass
class CampaignContext:
    """Everything a worker needs to simulate and evaluate the campaign (picklable).
    ``campaign`` is its name (for messages), ``ref`` the campaign resolved once
    (:func:`railval.db.repo.resolve`) that repository calls take."""

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
    ref: repo.CampaignRef | None = None


def band_sums(signalsets: Mapping[str, SignalSet], bands) -> dict[str, np.ndarray]:
    """Car body acceleration channel → band powers summed over the sections (10 s Welch
    segments): :func:`railval.core.diagnosis.band_powers` of every channel of every section,
    each estimated alone (one-row blocks of one
    :func:`railval.core.diagnosis.sections_band_powers` call: the same float bits), summed in
    section order."""
    keys = [(sid, ch) for sid, ss in signalsets.items() for ch in ACC_CHANNELS if ch in ss.channels]
    powers = sections_band_powers({k: {k[1]: signalsets[k[0]].channels[k[1]]} for k in keys},
                                  {k: signalsets[k[0]].fs for k in keys}, bands, 10.0)
    out: dict[str, np.ndarray] = {}
    for k in keys:
        out[k[1]] = out.get(k[1], 0.0) + powers[k][k[1]]
    return out


def acceleration_band_powers(signalsets: Mapping[str, SignalSet], bands) -> dict[str, dict[str, np.ndarray]]:
    """Section id → car body acceleration channel → band powers (10 s Welch segments), each
    section's channels in one block (:func:`railval.core.diagnosis.section_band_powers` of
    every section, one :func:`railval.core.diagnosis.sections_band_powers` call)."""
    return sections_band_powers({sid: {ch: ss.channels[ch] for ch in ACC_CHANNELS if ch in ss.channels}
                                 for sid, ss in signalsets.items()},
                                {sid: ss.fs for sid, ss in signalsets.items()}, bands, 10.0)


def section_values(signalsets: Mapping[str, SignalSet], sections: Sequence[SectionInfo]) -> dict[str, dict]:
    """EN 14363 values (:func:`railval.core.en14363.evaluate_present`) of the sections present;
    the SectionValues (a dict) keep the supplementary values the residual pattern uses."""
    return evaluate_present(signalsets, sections)


def load_context(session: Any, campaign: repo.CampaignArg) -> CampaignContext:
    """Read the campaign's vehicle, sections and measurement; evaluate the measurement once.
    ``campaign``: a :class:`railval.db.repo.CampaignRef` resolved at the service's entrance
    (or, for callers that have not resolved it, its name)."""
    return load_context_and_measurement(session, campaign)[0]


def load_context_and_measurement(session: Any, campaign: repo.CampaignArg
                                 ) -> tuple[CampaignContext, dict[str, SignalSet]]:
    """:func:`load_context` and the measured signal sets it decoded (section id → SignalSet),
    for a service that needs the signals too (the diagnosis: decoded once per diagnosis)."""
    camp = repo.get_campaign(session, campaign)
    sections = repo.section_infos(session, camp)
    vehicle = repo.vehicle_info(session, camp)
    layouts = repo.section_layouts(session, camp)
    measured = repo.load_signalsets(session, camp, None)
    if not measured:
        raise NotFound(f"campaign {camp.name!r} has no measurement recordings")
    ctx = CampaignContext(camp.name, vehicle, sections, layouts, section_values(measured, sections),
                          band_sums(measured, DEFAULT_BANDS_HZ),
                          sorted({c for ss in measured.values() for c in ss.channels}),
                          {sid: ss.fs for sid, ss in measured.items()},
                          ref=repo.CampaignRef(camp.id, camp.name))
    ctx.sim_inputs = dict(simulation_inputs(session, camp))
    return ctx, measured


def validate_values(ctx: CampaignContext, sim_values: Mapping[str, Mapping], n_boot: int = 0) -> ValidationResult:
    """The validation (:func:`railval.core.validation.validate`) of simulated section values
    against the context's measurement."""
    return validate(ctx.measured_values, sim_values, ctx.sections, ctx.vehicle, n_boot=n_boot)


def residual_pattern(ctx: CampaignContext, sim_values: Mapping[str, Mapping],
                     sim_bands: Mapping[str, np.ndarray]) -> tuple[Pattern, ValidationResult]:
    """Pattern (normalised D_v per quantity × zone × position + log₂ band-power ratios + the
    bogie-frame supplementary quantities, :func:`railval.core.supplementary.supplementary_pattern`)
    and the :class:`railval.core.validation.ValidationResult` (no bootstrap) of simulated values."""
    vr = validate_values(ctx, sim_values)
    pairs = vr.pairs.to_dict("records")
    pat = pattern_from_pairs(pairs, value_key="D_norm")
    return Pattern.concat(pat, band_ratio_pattern(sim_bands, ctx.measured_bands, ctx.bands),
                          supplementary_pattern(vr.supplementary.get("pairs", ()))), vr


def evaluated_span_end(ctx: CampaignContext) -> dict[str, float]:
    """Section id → distance (m) where the diagnosis's runs stop: the evaluated range's end plus
    the EN filters' run-out (:func:`railval.core.filters.run_out_s` at the section's rate)
    travelled at the section's speed."""
    return {s.id: float(s.eval_end_m) + run_out_s(ctx.fs.get(s.id, 200.0)) * float(s.speed_kmh) / 3.6
            for s in ctx.sections}


def cut_to(ss: SignalSet, end_m: float) -> SignalSet:
    """The samples of ``ss`` up to distance ``end_m`` (m), inclusive: a measured section cut where a
    run stopped at ``end_m`` ends (the same track span on both sides); ``ss`` itself when it ends
    before."""
    n = int(np.searchsorted(ss.distance_m, end_m, side="right"))
    if n >= len(ss):
        return ss
    return SignalSet(fs=ss.fs, time_s=ss.time_s[:n], distance_m=ss.distance_m[:n],
                     channels={k: x[:n] for k, x in ss.channels.items()})


def simulate_context(ctx: CampaignContext, effects: Mapping[str, Mapping[str, float]],
                     parameters: Mapping[str, float] | None = None, *,
                     evaluated_only: bool = False) -> dict[str, SignalSet]:
    """Simulate every section of the campaign with the built-in simulator; ``evaluated_only``:
    each run stops at :func:`evaluated_span_end` (the diagnosis: its EN values equal the whole
    run's — docs/diagnosis.md "Only the evaluated span" — and its band powers are taken over the
    same span of the measurement)."""
    return simulate_campaign(ctx.vehicle, ctx.sections, layouts=ctx.layouts, effects=dict(effects),
                             parameters=dict(parameters or {}), channels=ctx.channels,
                             fs=ctx.fs, end_m=evaluated_span_end(ctx) if evaluated_only else None,
                             **ctx.sim_inputs)


def evaluate_effects(task: tuple[CampaignContext, dict, dict]) -> tuple[dict, dict]:
    """Worker task: simulate with ``effects`` (and model ``parameters``) and return the section
    values and the summed acceleration band powers (small; no signals travel back)."""
    ctx, effects, parameters = task
    sets = simulate_context(ctx, effects, parameters)
    return section_values(sets, ctx.sections), band_sums(sets, ctx.bands)


def configuration_of(session: Any, campaign: repo.CampaignArg, config: repo.ConfigArg,
                     simulated_in: CampaignContext | None = None) -> tuple[dict, dict, Any]:
    """(effects, model parameters, row) of stored configuration ``config`` (a
    :class:`railval.db.repo.ConfigRef` or its name). ``simulated_in``: the context the
    configuration will be simulated in; its model parameters are then checked against the
    vehicle's template first (:func:`check_model_parameters`)."""
    conf = repo.get_configuration(session, campaign, config)
    if simulated_in is not None:
        check_model_parameters(simulated_in, conf.name, dict(conf.parameters or {}))
    return dict(conf.effects or {}), dict(conf.parameters or {}), conf


def check_model_parameters(ctx: CampaignContext, config: str, conf_params: Mapping[str, Any]) -> None:
    """Refuse, before any simulation, a vehicle or configuration ``config`` whose model
    parameters the built-in simulator's template does not know (e.g. an external model's own
    names), naming which record holds which names: the diagnosis and calibration simulate
    with that template (docs/simulator.md)."""
    template = template_for(ctx.vehicle)
    for owner, names in (("the campaign's vehicle", ctx.vehicle.get("parameters") or {}),
                         (f"configuration {config!r}", conf_params)):
        unknown = unknown_parameters(template, names)
        if unknown:
            raise InvalidParameter(
                f"{owner} has parameters the built-in simulator's vehicle template {template!r} "
                f"does not know: {', '.join(map(repr, unknown))}; the diagnosis and calibration "
                "simulate with that template (docs/simulator.md lists its parameters)")


def runnable_effects(ctx: CampaignContext, effects: Mapping[str, Any], config: str) -> tuple[dict, list[dict]]:
    """The effects switched on in configuration ``config`` that can apply to the campaign, and
    for each that cannot (track data its sections do not carry:
    :func:`railval.core.sim.effects.unmet_requirement`) ``{"name", "kind": "configuration",
    "reason"}`` with a one-line reason naming the sections and the missing field. The
    configuration is then simulated without it — the simulator would refuse every section —
    and the result says so (docs/diagnosis.md "Candidates that cannot apply")."""
    keep, out = {}, []
    for e, params in effects.items():
        why = unmet_requirement(EFFECTS[e], ctx.layouts) if e in EFFECTS else None
        if why:
            out.append({"name": e, "kind": "configuration",
                        "reason": f"switched on in configuration {config!r} but cannot apply: {why}; "
                                  f"simulated without it"})
        else:
            keep[e] = params
    return keep, out


def effect_parameters(effect: Effect) -> dict[str, dict[str, Any]]:
    """``{name: {lower, upper, default, unit, log}}`` of an effect of :mod:`railval.core.sim.effects`
    (``log``: scanned and fitted on a logarithmic scale)."""
    return {name: {"lower": float(p.lower), "upper": float(p.upper), "default": float(p.default),
                   "unit": str(p.unit or ""), "log": p.scale == "log" and p.lower > 0}
            for name, p in effect.parameters.items()}
