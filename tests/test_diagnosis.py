"""Tests of core.diagnosis on patterns whose effects are known by construction."""

from __future__ import annotations

import math

import numpy as np
import pytest

from railval.core.diagnosis import (
    ParameterScan,
    Pattern,
    diagnose_patterns,
    fit_scan,
    pattern_from_pairs,
    psd_band_pattern,
)
from railval.core.errors import InvalidSignal

LABELS = [f"{q} zone {z} p" for q in ("Y_qst", "Q_max", "az_rms") for z in (1, 4)]
GROUPS = [lab.split()[0] for lab in LABELS]


def _toy(truth_v=0.6):
    """A linear toy model: the residual r = truth_v·a (the hidden effect A at value truth_v,
    seen from a model without it); adding A at v leaves r − v·a; adding B leaves r − v·b with
    b orthogonal to a in the weighted metric."""
    a = np.array([1.0, 2.0, 0.0, 0.0, 0.5, 0.5])
    b = np.array([0.0, 0.0, 1.0, -1.0, 0.0, 0.0])
    r = truth_v * a
    vals = [0.0, 0.25, 0.5, 0.75, 1.0]
    pat = lambda x: Pattern(LABELS, GROUPS, x)
    scans = {"A": [ParameterScan("A", "k", vals, [pat(r - v * a) for v in vals], {"k": 0.0, "c": 3.0})],
             "B": [ParameterScan("B", "mu", vals, [pat(r - v * b) for v in vals])]}
    return pat(r), scans


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


def test_fit_scan_interpolates_between_scanned_values():
    r, scans = _toy(0.6)
    v, cost, _ = fit_scan(r, scans["A"][0])
    assert v == pytest.approx(0.6, abs=0.005)  # exact linear model → exact within the grid step
    assert cost == pytest.approx(0.0, abs=1e-4)


def test_diagnosis_ranks_the_true_effect_first():
    r, scans = _toy(0.6)
    res = diagnose_patterns(r, scans, explanations={"A": "friction in the suspension"})
    first, second = res.candidates
    assert first.effect == "A" and first.explained == pytest.approx(1.0, abs=1e-3)
    assert first.parameters == {"k": pytest.approx(0.6, abs=0.005), "c": 3.0}
    assert second.explained == pytest.approx(0.0, abs=1e-12)  # b ⟂ a: fitted at v = 0
    assert set(first.fixes) == {"Y_qst", "az_rms"} and first.worsens == []
    assert res.separable
    d = res.to_dict()
    assert d["candidates"][0]["effect"] == "A" and d["candidates"][0]["explanation"]
    assert len(res.to_pandas()) == 2


def test_worsens_is_reported():
    r, scans = _toy(0.6)
    # an effect that fixes Y_qst but introduces a Q_max error
    c = np.array([1.0, 2.0, 1.5, 1.5, 0.0, 0.0])
    vals = [0.0, 0.5, 1.0]
    scans["C"] = [ParameterScan("C", "x", vals, [Pattern(LABELS, GROUPS, r.values - v * c) for v in vals])]
    res = diagnose_patterns(r, scans)
    cand = next(c for c in res.candidates if c.effect == "C")
    assert "Q_max" in cand.worsens and "Y_qst" in cand.fixes


def test_indistinguishable_effects_are_flagged_with_evidence():
    r, scans = _toy(0.6)
    a = np.array([1.0, 2.0, 0.0, 0.0, 0.5, 0.5])
    a2 = a + np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.3])  # differs only in "az_rms zone 4 p"
    vals = [0.0, 0.5, 1.0]
    scans["A2"] = [ParameterScan("A2", "k", vals, [Pattern(LABELS, GROUPS, r.values - v * a2) for v in vals])]
    res = diagnose_patterns(r, scans)
    assert [c.effect for c in res.candidates[:2]] == ["A", "A2"]
    assert not res.separable
    assert res.evidence[0]["component"] == "az_rms zone 4 p"
    assert "A2" in res.note


def test_zero_residual_is_rejected():
    with pytest.raises(InvalidSignal):
        diagnose_patterns(Pattern(["a"], ["g"], [0.0]), {})


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


def test_fit_scan_log_interpolation_recovers_power_law_minimum():
    # pattern linear in log(v): P(v) = ln(v / 0.3)·a, zero at v = 0.3, scanned on a log grid
    a = np.ones(len(LABELS))
    vals = [0.2, 1.0, 5.0, 50.0]
    pats = [Pattern(LABELS, GROUPS, math.log(v / 0.3) * a) for v in vals]
    r = Pattern(LABELS, GROUPS, math.log(1 / 0.3) * a)
    v, cost, _ = fit_scan(r, ParameterScan("E", "k", vals, pats, log=True))
    assert v == pytest.approx(0.3, rel=0.02) and cost == pytest.approx(0.0, abs=1e-3)
    lin, _, _ = fit_scan(r, ParameterScan("E", "k", vals, pats, log=False))
    assert abs(lin - 0.3) > abs(v - 0.3)  # linear interpolation misplaces it
