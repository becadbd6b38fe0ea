"""Supplementary quantities (core.supplementary): bogie-frame accelerations through the EN
acceleration chain, PSD band rms against scipy's Welch estimate and Parseval, D_v statistics
and the diagnosis pattern by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.signal

from railval.core.en14363 import evaluate_section
from railval.core.supplementary import (
    SUPPLEMENTARY,
    psd_band_values,
    supplementary_pattern,
    supplementary_results,
)
from railval.core.types import SectionInfo, SignalSet

FS = 100.0


def _set(n_s=60.0):
    rng = np.random.default_rng(3)
    t = np.arange(int(n_s * FS)) / FS
    d = 20.0 * t
    acc = np.convolve(rng.normal(size=t.size), np.hanning(15), "same") * 0.05
    ch = {"ay_cb_b1": acc.copy(), "ay_bg_b1": acc.copy(),
          "az_bg_b2": 0.4 * np.sin(2 * np.pi * 3.0 * t) + 0.1 * rng.normal(size=t.size)}
    return SignalSet(FS, t, d, ch), SectionInfo("B1", 0.0, 0.0, 72.0, 1, 200.0, 1000.0)


def test_registry():
    ids = list(SUPPLEMENTARY)
    assert ids[:4] == ["ay_bg_rms", "ay_bg_max", "az_bg_rms", "az_bg_max"]
    assert len(ids) == 4 + 16 and "psd_az_bg_5-10Hz" in ids and "psd_ay_cb_0.4-1Hz" in ids
    assert all(q.source for q in SUPPLEMENTARY.values())
    assert SUPPLEMENTARY["psd_ay_bg_2-5Hz"].band_hz == (2.0, 5.0)


def test_bogie_frame_values_follow_the_car_body_chain():
    ss, sec = _set()
    vals = evaluate_section(ss, sec)
    # identical samples on a car body and a bogie channel → identical rms and maximum
    assert vals.supplementary[("ay_bg_rms", "b1")] == vals[("ay_rms", "b1")]
    assert vals.supplementary[("ay_bg_max", "b1")] == vals[("ay_max", "b1")]
    # and independently: band-pass 0.4–10 Hz (scipy), cut, rms and inverted-CDF maxima
    from railval.core.filters import design

    f = scipy.signal.sosfiltfilt(design(FS, "bandpass", 4).sos, ss.channels["az_bg_b2"])
    x = f[(ss.distance_m >= 200.0) & (ss.distance_m <= 1000.0)]
    assert vals.supplementary[("az_bg_rms", "b2")] == pytest.approx(np.sqrt(np.mean(x * x)),
                                                                    rel=1e-9)
    lo, hi = np.quantile(x, [0.0015, 0.9985], method="inverted_cdf")
    assert vals.supplementary[("az_bg_max", "b2")] == pytest.approx(max(abs(lo), abs(hi)),
                                                                    rel=1e-9)
    # bogie channels never enter the 12 verdict quantities
    assert not any(q.startswith(("ay_bg", "az_bg")) for q, _ in vals)


def test_psd_band_rms_against_scipy_and_parseval():
    t = np.arange(int(40 * FS)) / FS
    a = 0.4
    x = a * np.sin(2 * np.pi * 3.0 * t)
    out = psd_band_values({"az_bg_b2": x}, FS)
    f, g = scipy.signal.welch(x, fs=FS, nperseg=1000, detrend="linear")
    for lo, hi in ((0.4, 1.0), (1.0, 2.0), (2.0, 5.0), (5.0, 10.0)):
        want = math.sqrt(np.sum(g[(f >= lo) & (f < hi)]) * (f[1] - f[0]))
        assert out[(f"psd_az_bg_{lo:g}-{hi:g}Hz", "b2")] == pytest.approx(want, rel=1e-12)
    # Parseval: the 3 Hz sine's rms a/√2 lies in the 2–5 Hz band (per-segment linear
    # detrend of 10 s segments removes < 0.2 % of it), nothing in the other bands
    assert out[("psd_az_bg_2-5Hz", "b2")] == pytest.approx(a / math.sqrt(2), rel=2e-3)
    assert out[("psd_az_bg_5-10Hz", "b2")] < 1e-3 * a
    # a record too short to resolve 0.4–1 Hz (1 s → 1 Hz bins) gives no value there
    short = psd_band_values({"ay_cb_b1": x[:100]}, FS)
    assert ("psd_ay_cb_0.4-1Hz", "b1") not in short and ("psd_ay_cb_1-2Hz", "b1") in short


def test_section_carries_psd_values_of_the_unfiltered_evaluated_part():
    ss, sec = _set()
    vals = evaluate_section(ss, sec)
    cut = (ss.distance_m >= 200.0) & (ss.distance_m <= 1000.0)
    want = psd_band_values({"az_bg_b2": ss.channels["az_bg_b2"][cut]}, FS)
    for k, v in want.items():
        assert vals.supplementary[k] == pytest.approx(v, rel=1e-12)
    assert ("psd_ay_cb_1-2Hz", "b1") in vals.supplementary


def test_statistics_by_hand():
    meas = {"S1": {("ay_bg_rms", "b1"): 1.0, ("ay_bg_rms", "b2"): 2.0},
            "S2": {("ay_bg_rms", "b1"): 4.0}}
    sim = {"S1": {("ay_bg_rms", "b1"): 1.5, ("ay_bg_rms", "b2"): 1.0},
           "S2": {("ay_bg_rms", "b1"): 4.0}}
    res = supplementary_results(meas, sim, {"S1": 1, "S2": 2})
    (row,) = res["quantities"]
    # D = (S − M)·sign(M) = 0.5, −1, 0
    assert row["n"] == 3 and row["n_positions"] == 2 and row["n_sections"] == 2
    assert row["mean"] == pytest.approx(-1 / 6)
    assert row["std"] == pytest.approx(math.sqrt(((0.5 + 1 / 6) ** 2 + (-1 + 1 / 6) ** 2
                                                  + (1 / 6) ** 2) / 2))
    assert row["mean_abs_measured"] == pytest.approx(7 / 3)
    assert row["mean_rel"] == pytest.approx(-1 / 6 / (7 / 3))
    assert row["log2_ratio_mean"] == pytest.approx((math.log2(1.5) - 1.0 + 0.0) / 3)
    assert "do not change" in res["note"]
    # diagnosis pattern: mean over sections of 2·log2(S/M) per (quantity, position)
    pat = supplementary_pattern(res["pairs"])
    assert pat.labels == ["supp ay_bg_rms b1", "supp ay_bg_rms b2"]
    assert pat.groups == ["bogie ay", "bogie ay"]
    np.testing.assert_allclose(pat.values, [(2 * math.log2(1.5) + 0.0) / 2, -2.0])


def test_pattern_leaves_out_car_body_psd():
    pairs = [{"quantity": "psd_ay_cb_1-2Hz", "position": "b1", "log2_ratio": 1.0},
             {"quantity": "psd_az_bg_1-2Hz", "position": "b2", "log2_ratio": -0.5}]
    pat = supplementary_pattern(pairs)
    assert pat.labels == ["supp psd_az_bg_1-2Hz b2"] and pat.groups == ["bogie az"]
    assert pat.values.tolist() == [-1.0]


def test_diagnosis_residual_pattern_holds_the_bogie_frame_components():
    from railval.app.services.campaign_context import CampaignContext, residual_pattern
    from railval.core.en14363 import SectionValues

    sections = [SectionInfo(f"S{i}", 500.0, 100.0, 80.0, 1 + i % 4, 0.0, 100.0) for i in range(4)]
    meas, sim = {}, {}
    for s in sections:
        meas[s.id] = SectionValues(s.id, {("Y_qst", "w1L"): 10.0},
                                   supplementary={("az_bg_rms", "b1"): 1.0,
                                                  ("psd_ay_cb_1-2Hz", "b1"): 0.1})
        sim[s.id] = SectionValues(s.id, {("Y_qst", "w1L"): 12.0},
                                  supplementary={("az_bg_rms", "b1"): 2.0,
                                                 ("psd_ay_cb_1-2Hz", "b1"): 0.2})
    ctx = CampaignContext("c", {"kind": "passenger", "Q0_kN": 80.0}, sections, {}, meas, {}, [], {})
    pat, vr = residual_pattern(ctx, sim, {})
    # D_v/std limit of Y_qst: 2/5 per zone; bogie rms doubled → 2·log2(2) = 2; car body PSD
    # bands stay with the existing PSD components (not repeated)
    assert pat.labels == [f"Y_qst zone {z} w1L" for z in (1, 2, 3, 4)] + ["supp az_bg_rms b1"]
    np.testing.assert_allclose(pat.values, [0.4] * 4 + [2.0])
    assert pat.groups[-1] == "bogie az"
    assert {r["quantity"] for r in vr.supplementary["quantities"]} == {"az_bg_rms", "psd_ay_cb_1-2Hz"}


def test_fast_linear_detrend_equals_scipy():
    from railval.core.psd import detrend_linear, welch_psd

    x = np.random.default_rng(5).normal(size=(3, 1001)) + np.linspace(0, 4, 1001)
    np.testing.assert_allclose(detrend_linear(x), scipy.signal.detrend(x, type="linear"),
                               atol=1e-12)
    f, g = scipy.signal.welch(x[0], fs=FS, nperseg=500, detrend="linear")
    p = welch_psd(x[0], FS, segment_s=5.0)
    np.testing.assert_allclose(p.density, g, rtol=1e-10, atol=1e-15)
    np.testing.assert_array_equal(p.frequency_hz, f)
