"""The diagnosis simulates only what its evaluation reads (docs/diagnosis.md "Only the evaluated
span (issue 41, round 5)"): its runs stop at the evaluated range's end plus the EN filters'
run-out, the EN values in the range stay those of the whole run, and the measured band powers
are taken over the same span of track as the simulated ones; validation and calibration
still simulate whole sections."""

from __future__ import annotations

import numpy as np
import pytest

from railval.app.services import campaign_context as cc
from railval.app.services import simulation as simulation_service
from railval.app.services.campaign_context import (
    ACC_CHANNELS,
    cut_to,
    evaluate_effects,
    evaluated_span_end,
    load_context_and_measurement,
    section_values,
    simulate_context,
)
from railval.app.services.diagnosis_ranking import _evaluate_sections, measured_section_bands
from railval.app.services.synth import synth
from railval.core.diagnosis import section_band_powers
from railval.core.errors import InvalidParameter
from railval.core.filters import FILTER_KINDS, design, run_out_s
from railval.core.sim import TrackSection
from railval.db import repo
from railval.db.engine import connect

#: largest relative change of an EN value in the range against the whole run (measured on the
#: bench campaign: 5.7·10⁻³ at the chosen run-out, docs/diagnosis.md)
TOLERANCE = 1e-2


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    db = connect(f"sqlite:///{tmp_path_factory.mktemp('span') / 'span.db'}")
    db.init()
    synth(db, name="span", hidden=["friction_damping"], seed=7)
    with db.session() as s:
        ctx, measured = load_context_and_measurement(s, "span")
        effects = dict(repo.get_configuration(s, "span", "baseline").effects or {})
    ctx.sections = ctx.sections[::3]  # one section per zone is enough here
    yield db, ctx, measured, effects
    db.dispose()


def _spy(monkeypatch, module) -> list[dict]:
    """Record the signal sets every ``simulate_campaign`` call of ``module`` returns."""
    seen: list[dict] = []
    real = module.simulate_campaign

    def spy(*a, **kw):
        out = real(*a, **kw)
        seen.append(out)
        return out

    monkeypatch.setattr(module, "simulate_campaign", spy)
    return seen


def _full_samples(ctx, sid: str) -> int:
    sec = next(s for s in ctx.sections if s.id == sid)
    track = TrackSection.from_info(sec, ctx.layouts.get(sid))
    return int(track.length_m / track.speed_ms * ctx.fs[sid])


def test_run_out_is_the_slowest_filter_settling_times_the_factor():
    fs = 200.0
    slowest = max(design(fs, k).settling_s + design(fs, k).edge / fs for k in FILTER_KINDS)
    assert slowest == pytest.approx(design(fs, "bandpass").settling_s + design(fs, "bandpass").edge / fs)
    assert run_out_s(fs, factor=1.0) == pytest.approx(slowest + 1 / fs)
    assert run_out_s(fs) >= run_out_s(fs, factor=1.0)
    with pytest.raises(InvalidParameter, match="factor"):
        run_out_s(fs, factor=0.5)  # shorter than the settling time: settling warnings


def test_diagnosis_runs_stop_at_range_end_plus_run_out_validation_and_calibration_do_not(campaign, monkeypatch):
    db, ctx, _, effects = campaign
    seen = _spy(monkeypatch, cc)
    _evaluate_sections(ctx, (effects, {}))
    end = evaluated_span_end(ctx)
    (diag,) = seen
    for sec in ctx.sections:
        ss = diag[sec.id]
        step = sec.speed_kmh / 3.6 / ss.fs
        # the run stops at the range's end plus the run-out (its last sample within two samples'
        # travel of it: whole output samples, each at the mid-time of its integration steps)
        assert end[sec.id] - 2 * step <= ss.distance_m[-1] <= end[sec.id]
        assert end[sec.id] == pytest.approx(sec.eval_end_m + run_out_s(ss.fs) * sec.speed_kmh / 3.6)
        assert len(ss) < _full_samples(ctx, sec.id)
    seen.clear()
    evaluate_effects((ctx, effects, {}))  # calibration's worker task
    simulate_context(ctx, effects, {})
    for sets in seen:
        assert {sid: len(ss) for sid, ss in sets.items()} == {s.id: _full_samples(ctx, s.id) for s in ctx.sections}
    val = _spy(monkeypatch, simulation_service)
    simulation_service.simulate_configuration(db, "span", "whole", parent="baseline", workers=1)
    assert {sid: len(val[0][sid]) for sid in end} == {s.id: _full_samples(ctx, s.id) for s in ctx.sections}


def test_values_in_the_range_equal_the_whole_runs(campaign):
    _, ctx, _, effects = campaign
    whole = simulate_context(ctx, effects, {})
    short = simulate_context(ctx, effects, {}, evaluated_only=True)
    for sid, ss in short.items():  # the kernel integrates forward: the samples kept are the same
        for ch, x in ss.channels.items():
            assert np.array_equal(x, whole[sid].channels[ch][:len(x)]), (sid, ch)
    a, b = section_values(whole, ctx.sections), section_values(short, ctx.sections)
    worst = 0.0
    for sid, vals in a.items():
        for key, v in vals.items():
            worst = max(worst, abs(b[sid][key] - v) / max(abs(v), 1e-12))
    assert 0.0 < worst <= TOLERANCE, worst


def test_measured_band_powers_cover_the_simulated_span(campaign, monkeypatch):
    _, ctx, measured, effects = campaign
    seen = _spy(monkeypatch, cc)
    _evaluate_sections(ctx, (effects, {}))
    got = measured_section_bands(ctx, measured)
    for sid, sim in seen[0].items():
        meas = measured[sid]
        cut = cut_to(meas, evaluated_span_end(ctx)[sid])
        assert len(cut) < len(meas)
        # the same stretch of track: both sides end within one sample's travel of each other
        assert abs(cut.distance_m[-1] - sim.distance_m[-1]) <= 1.5 * np.max(np.diff(meas.distance_m))
        want = section_band_powers({ch: cut.channels[ch] for ch in ACC_CHANNELS if ch in cut.channels},
                                   cut.fs, ctx.bands, 10.0)
        whole = section_band_powers({ch: meas.channels[ch] for ch in ACC_CHANNELS if ch in meas.channels},
                                    meas.fs, ctx.bands, 10.0)
        assert set(got[sid]) == set(want) and want
        for ch in want:
            np.testing.assert_array_equal(got[sid][ch], want[ch])
            assert not np.allclose(got[sid][ch], whole[ch], rtol=1e-6, atol=0), (sid, ch)
