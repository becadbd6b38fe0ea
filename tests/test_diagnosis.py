"""Tests of core.diagnosis (patterns, the fit along one parameter, the ranking) on patterns
whose effects are known by construction."""

from __future__ import annotations

import math

import numpy as np
import pytest

from railval.core.diagnosis import (
    CandidateFamily,
    Pattern,
    SectionEvidence,
    diagnose_evidence,
    pattern_from_pairs,
    psd_band_pattern,
)
from railval.core.diagnosis.fit import _Curve, _fit
from railval.core.errors import InvalidSignal

LABELS = [f"{q} zone {z} p" for q in ("Y_qst", "Q_max", "az_rms") for z in (1, 4)]
GROUPS = [lab.split()[0] for lab in LABELS]
ZONES = [1, 1, 2, 2, 4, 4]  # six sections, two per zone


def _constant(values) -> SectionEvidence:
    """Evidence of a model whose every section shows the same pattern ``values`` (no scatter)."""
    S = len(ZONES)
    return SectionEvidence([f"S{i}" for i in range(S)], ZONES, LABELS, GROUPS, len(LABELS),
                           np.tile(np.asarray(values, float), (S, 1)), np.ones((S, len(LABELS))),
                           np.zeros((S, 0)), np.zeros((S, 0)))


def _family(name, parameter, values, residual, direction, defaults=None, log=False):
    """Candidate ``name``: at value v the model leaves ``residual − v·direction``."""
    return CandidateFamily("effect", name, parameter, list(values),
                           [_constant(residual - v * np.asarray(direction)) for v in values],
                           (min(values), max(values)), log=log, defaults=dict(defaults or {}))


def _toy(truth_v=0.6):
    """A linear toy model: the residual r = truth_v·a (the hidden effect A at value truth_v,
    seen from a model without it); adding A at v leaves r − v·a; adding B leaves r − v·b with
    b orthogonal to a in the weighted metric."""
    a = np.array([1.0, 2.0, 0.0, 0.0, 0.5, 0.5])
    b = np.array([0.0, 0.0, 1.0, -1.0, 0.0, 0.0])
    r = truth_v * a
    vals = [0.0, 0.25, 0.5, 0.75, 1.0]
    return _constant(r), [_family("A", "k", vals, r, a, {"k": 0.0, "c": 3.0}), _family("B", "mu", vals, r, b)]


def _fit_family(fam, residual):
    """(v*, remaining ‖·‖²_W) of a family fitted to the whole campaign (as diagnose_evidence does)."""
    curve = _Curve(fam)
    w = residual.pattern().weights()
    k, cost, _ = _fit(curve, np.stack([e.values() for e in fam.evidence]), w)
    return curve.value(k), cost


def test_weights_give_each_group_unit_total():
    p = Pattern(["a", "b", "c"], ["g1", "g1", "g2"], [1.0, 1.0, 1.0])
    w = p.weights()
    np.testing.assert_allclose(w, [1 / math.sqrt(2), 1 / math.sqrt(2), 1.0])
    assert p.norm2() == pytest.approx(2.0)  # g1: 0.5 + 0.5, g2: 1
    assert p.group_norms() == {"g1": pytest.approx(1.0), "g2": pytest.approx(1.0)}
    with pytest.raises(InvalidSignal):
        Pattern(["a"], ["g"], [1.0, 2.0])


def test_pattern_from_pairs_means_per_quantity_zone_position():
    pairs = [{"quantity": "Y_qst", "zone": 4, "position": "w1L", "norm": 0.2},
             {"quantity": "Y_qst", "zone": 4, "position": "w1L", "norm": 0.6},
             {"quantity": "Y_qst", "zone": 1, "position": "w1L", "norm": -1.0},
             {"quantity": "az_rms", "zone": 1, "position": "b1", "norm": float("nan")}]
    p = pattern_from_pairs(pairs)
    assert p.labels == ["Y_qst zone 1 w1L", "Y_qst zone 4 w1L"]
    np.testing.assert_allclose(p.values, [-1.0, 0.4])
    with pytest.raises(InvalidSignal):
        pattern_from_pairs([])


def test_psd_band_pattern_log2_power_ratio():
    rng = np.random.default_rng(0)
    fs = 100.0
    x = rng.standard_normal(6000)
    p = psd_band_pattern({"az_cb_b1": [2.0 * x]}, {"az_cb_b1": [x]}, fs)
    # amplitude ×2 → power ×4 → log2 ratio 2 in every band (independent of the estimate)
    np.testing.assert_allclose(p.values, 2.0, atol=1e-9)
    assert p.labels[0] == "psd az_cb_b1 0.4-1 Hz" and set(p.groups) == {"psd az"}


def test_fit_interpolates_between_simulated_values():
    base, fams = _toy(0.6)
    v, cost = _fit_family(fams[0], base)
    assert v == pytest.approx(0.6, abs=0.005)  # exact linear model → exact within the grid step
    assert cost == pytest.approx(0.0, abs=1e-4)


def test_diagnosis_ranks_the_true_effect_first():
    base, fams = _toy(0.6)
    fams[0].explanation = "friction in the suspension"
    res = diagnose_evidence(base, fams, n_boot=20)
    first, second = res.candidates
    assert first.name == "A" and first.explained == pytest.approx(1.0, abs=1e-3)
    assert first.parameters == {"k": pytest.approx(0.6, abs=0.005), "c": 3.0}
    assert second.explained == pytest.approx(0.0, abs=1e-12)  # b ⟂ a: fitted at v = 0
    assert set(first.fixes) == {"Y_qst", "az_rms"} and first.worsens == []
    assert res.separable
    d = res.to_dict()
    assert d["candidates"][0]["effect"] == "A" and "friction in the suspension" in d["candidates"][0]["explanation"]
    assert len(res.to_pandas()) == 2


def test_worsens_is_reported():
    base, fams = _toy(0.6)
    r = base.values()
    # an effect that fixes Y_qst but introduces a Q_max error
    c = np.array([1.0, 2.0, 1.5, 1.5, 0.0, 0.0])
    fams.append(_family("C", "x", [0.0, 0.5, 1.0], r, c))
    res = diagnose_evidence(base, fams, n_boot=0)
    cand = next(c for c in res.candidates if c.name == "C")
    assert "Q_max" in cand.worsens and "Y_qst" in cand.fixes


def test_indistinguishable_effects_are_flagged_with_evidence():
    base, fams = _toy(0.6)
    r = base.values()
    a = np.array([1.0, 2.0, 0.0, 0.0, 0.5, 0.5])
    a2 = a + np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.3])  # differs only in "az_rms zone 4 p"
    fams.append(_family("A2", "k", [0.0, 0.5, 1.0], r, a2))
    res = diagnose_evidence(base, fams, n_boot=0)
    assert [c.name for c in res.candidates[:2]] == ["A", "A2"]
    assert not res.separable and res.verdict == "uncertain"
    assert res.evidence[0]["component"] == "az_rms zone 4 p"
    assert "A2" in res.note


def test_zero_residual_is_rejected():
    base, fams = _toy(0.0)
    with pytest.raises(InvalidSignal):
        diagnose_evidence(base, fams)


def test_difference_pairs_sign_convention_and_normalisation():
    from railval.core.diagnosis import difference_pairs

    meas = {"S1": {("Y_qst", "w1L"): -10.0, ("az_rms", "b1"): 0.0}}
    sim = {"S1": {("Y_qst", "w1L"): -12.5, ("az_rms", "b1"): 0.3}}
    pairs = difference_pairs(meas, sim, {"S1": 4}, {"Y_qst": 5.0, "az_rms": 0.15})
    by_q = {p["quantity"]: p for p in pairs}
    # (S − M)·M/|M| = (−12.5 + 10)·(−1) = 2.5 → simulation overestimates the magnitude; /5 kN
    assert by_q["Y_qst"]["D_v"] == pytest.approx(2.5) and by_q["Y_qst"]["norm"] == pytest.approx(0.5)
    # M = 0 → D_v = S
    assert by_q["az_rms"]["D_v"] == pytest.approx(0.3) and by_q["az_rms"]["norm"] == pytest.approx(2.0)
    assert by_q["Y_qst"]["zone"] == 4


def test_fit_log_interpolation_recovers_power_law_minimum():
    # pattern linear in log(v): P(v) = ln(v / 0.3)·a, zero at v = 0.3, simulated on a log grid
    a = np.ones(len(LABELS))
    vals = [0.2, 1.0, 5.0, 50.0]
    base = _constant(math.log(1 / 0.3) * a)
    ev = [_constant(math.log(v / 0.3) * a) for v in vals]
    fit = lambda log: _fit_family(CandidateFamily("effect", "E", "k", vals, ev, (0.2, 50.0), log=log), base)
    v, cost = fit(True)
    assert v == pytest.approx(0.3, rel=0.02) and cost == pytest.approx(0.0, abs=1e-3)
    lin, _ = fit(False)
    assert abs(lin - 0.3) > abs(v - 0.3)  # linear interpolation misplaces it
