"""Definition sensitivity: the alternative readings of the open EN 14363 choices
(core.definitions), their values from the processing chain against an independent
computation, and a constructed campaign whose verdict flips with the percentile method."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import scipy.signal

from railval.core.definitions import (
    CHOSEN,
    READINGS,
    Reading,
    alternatives_for,
    sample_window_means,
    sorted_percentiles,
    window_centres,
)
from railval.core.en14363 import PERCENTILES, SectionValues, evaluate_section, maxabs
from railval.core.errors import InvalidParameter
from railval.core.filters import design
from railval.core.quantities import QUANTITIES
from railval.core.types import SectionInfo, SignalSet
from railval.core.validation import validate


# ------------------------------------------------------------------ building blocks
@pytest.mark.parametrize("n", [1, 2, 4, 7, 667, 2000, 2001])
@pytest.mark.parametrize("method", ["inverted_cdf", "linear"])
def test_sorted_percentiles_equal_numpy(n, method):
    rng = np.random.default_rng(n)
    x = rng.normal(size=(3, n))
    got = sorted_percentiles(np.sort(x, axis=1), PERCENTILES, method)
    want = np.quantile(x, PERCENTILES, axis=1, method=method).T
    np.testing.assert_array_equal(got, want)


def test_percentiles_by_hand():
    srt = np.array([[1.0, 2.0, 3.0, 4.0]])
    # inverted CDF: rank ceil(4p) → 0.15 %: rank 1 → 1; 50 %: rank 2 → 2; 99.85 %: rank 4 → 4
    assert sorted_percentiles(srt, PERCENTILES, "inverted_cdf").tolist() == [[1.0, 2.0, 4.0]]
    # linear at h = 3p: 0.0045 → 1.0045; 1.5 → 2.5; 2.9955 → 3.9955
    np.testing.assert_allclose(sorted_percentiles(srt, PERCENTILES, "linear"),
                               [[1.0045, 2.5, 3.9955]], rtol=1e-15)
    with pytest.raises(InvalidParameter, match="percentile method"):
        sorted_percentiles(srt, PERCENTILES, "nearest")


def test_sample_windows_by_hand():
    d = np.arange(7) * 0.5            # 0, 0.5, …, 3.0 m
    v = np.arange(7, dtype=float)     # v = 2·d
    c = np.array([1.0, 2.0])
    # window [0, 2] holds samples 0…4 (mean 2); [0, 2) holds 0…3 (mean 1.5);
    # [1, 3] holds 2…6 (mean 4); [1, 3) holds 2…5 (mean 3.5)
    np.testing.assert_allclose(sample_window_means(v, d, c, 2.0, closed=True), [[2.0, 4.0]])
    np.testing.assert_allclose(sample_window_means(v, d, c, 2.0, closed=False), [[1.5, 3.5]])
    # a window without samples is undefined
    out = sample_window_means(v, np.array([0.0, 0.1, 0.2, 5.0, 5.1, 5.2, 5.3]), np.array([2.6]),
                              2.0, closed=True)
    assert np.isnan(out[0, 0])


def test_window_centres_by_hand():
    # grid from 0.3 m inside 0–5 m: centres 1.3, 1.8, …, 3.8 (the last window ends at 4.8 ≤ 5)
    np.testing.assert_allclose(window_centres(0.0, 5.0, 0.3, 2.0, 0.5),
                               [1.3, 1.8, 2.3, 2.8, 3.3, 3.8])
    np.testing.assert_allclose(window_centres(0.0, 5.0, 0.0, 2.0, 0.5),
                               [1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0])


def test_readings_registry():
    assert len(READINGS) == 12 and READINGS[0] == CHOSEN and len(set(READINGS)) == 12
    assert [len(alternatives_for(QUANTITIES[q])) for q in ("YQ_max", "SumY_max")] == [11, 11]
    assert [r.percentile for r in alternatives_for(QUANTITIES["Y_qst"])] == ["linear"]
    assert alternatives_for(QUANTITIES["ay_rms"]) == []
    with pytest.raises(InvalidParameter, match="grid"):
        Reading("linear", "middle", "interpolant")


# ------------------------------------------------------------------ processing chain
FS = 100.0


def _section() -> tuple[SignalSet, SectionInfo]:
    """60 s at 100 Hz at a varying speed (18 ± 3 m/s) so the samples do not fall on the
    0.5 m grid; evaluated range 300.013–700.013 m."""
    rng = np.random.default_rng(7)
    t = np.arange(int(60 * FS)) / FS
    v = 18.0 + 3.0 * np.sin(2 * np.pi * t / 60.0)
    d = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) / FS)])
    ch = {
        "Y_w1L": 8.0 + 3.0 * np.sin(2 * np.pi * 1.3 * t) + rng.normal(0, 2.0, t.size),
        "Y_w1R": -5.0 + 2.0 * np.sin(2 * np.pi * 0.7 * t) + rng.normal(0, 2.0, t.size),
        "Q_w1L": 80.0 + rng.normal(0, 5.0, t.size),
        "Q_w1R": 75.0 + rng.normal(0, 5.0, t.size),
    }
    return SignalSet(FS, t, d, ch), SectionInfo("A1", 500.0, 100.0, 65.0, 3, 300.013, 700.013)


def _interpolant_mean(v, d, a, b):
    """Exact mean of the linear interpolant over [a, b] (trapezoid over the samples inside
    plus the interpolated end points)."""
    inside = (d > a) & (d < b)
    xs = np.concatenate([[a], d[inside], [b]])
    ys = np.concatenate([[np.interp(a, d, v)], v[inside], [np.interp(b, d, v)]])
    return np.sum(0.5 * (ys[1:] + ys[:-1]) * np.diff(xs)) / (b - a)


def test_section_alternatives_equal_an_independent_computation():
    ss, sec = _section()
    vals = evaluate_section(ss, sec)
    sos = design(FS, "lowpass", 4).sos
    f = {k: scipy.signal.sosfiltfilt(sos, x) for k, x in ss.channels.items()}
    d = ss.distance_m
    mask = (d >= sec.eval_start_m) & (d <= sec.eval_end_m)
    first = d[mask][0]
    assert first != sec.eval_start_m  # the two grid alignments differ
    sumy = f["Y_w1L"] + f["Y_w1R"]
    yq = f["Y_w1L"] / f["Q_w1L"]
    lin = Reading("linear", CHOSEN.grid, CHOSEN.window)
    # percentile-only quantities: numpy's linear method on the evaluated samples
    y = f["Y_w1L"][mask]
    lo, hi = np.quantile(y, [0.0015, 0.9985], method="linear")
    assert vals.value_under(lin.id, ("Y_max", "w1L")) == pytest.approx(maxabs(lo, hi), rel=1e-12)
    assert vals.value_under(lin.id, ("Y_qst", "w1L")) == pytest.approx(
        np.quantile(y, 0.5, method="linear"), rel=1e-12)
    assert vals.value_under(lin.id, ("Y_max", "w1L")) != vals[("Y_max", "w1L")]
    # sliding quantities under every reading: windows by explicit loops
    for reading in READINGS:
        origin = sec.eval_start_m if reading.grid == "section_start" else first
        n_c = int(np.floor((sec.eval_end_m - origin - 2.0) / 0.5 + 1e-9)) + 1
        centres = origin + 1.0 + 0.5 * np.arange(n_c)
        for key, sig in ((("SumY_max", "ws1"), sumy), (("YQ_max", "w1L"), yq)):
            means = []
            for x in centres:
                if reading.window == "interpolant":
                    means.append(_interpolant_mean(sig, d, x - 1.0, x + 1.0))
                else:
                    upper = d <= x + 1.0 if reading.window == "samples_closed" else d < x + 1.0
                    means.append(np.mean(sig[(d >= x - 1.0) & upper]))
            lo, hi = np.quantile(means, [0.0015, 0.9985], method=reading.percentile)
            got = vals.value_under(reading.id, key)
            assert got == pytest.approx(maxabs(lo, hi), rel=1e-9), (reading.id, key)
    # the readings do change the sliding values (else the test would prove nothing)
    sliding = {vals.value_under(r.id, ("SumY_max", "ws1")) for r in READINGS}
    assert len(sliding) >= 6
    # only differing values are stored
    assert all(v != vals[k] for alt in vals.alternatives.values() for k, v in alt.items())


# ------------------------------------------------------------------ constructed flip
def _flip_campaign():
    """12 sections (3 per zone), SumY_max on two wheelsets; chosen-reading values give
    D_v = −6.018 kN on every pair (mean −6.018, beyond the mean limit 6.0 kN); the linear
    percentile gives D_v = −5.976 kN (passes). Every other quantity agrees exactly."""
    sections = [SectionInfo(f"S{i:02d}", 500.0, 100.0, 80.0, 1 + i % 4, 0.0, 100.0)
                for i in range(12)]
    lin = Reading("linear", CHOSEN.grid, CHOSEN.window).id
    lin_sliding = Reading("linear", "first_sample", "samples_half_open").id
    meas, sim = {}, {}
    for s in sections:
        base = {(q, p): 10.0 for q in QUANTITIES for p in QUANTITIES[q].positions()[:2]}
        mv, sv = dict(base), dict(base)
        for ws in ("ws1", "ws2"):
            mv[("SumY_max", ws)] = 40.0
            sv[("SumY_max", ws)] = 40.0 - 6.018
        m_alt = {lin: {("SumY_max", ws): 40.0 for ws in ("ws1", "ws2")},
                 lin_sliding: {("SumY_max", ws): 40.1 for ws in ("ws1", "ws2")}}
        s_alt = {lin: {("SumY_max", ws): 40.0 - 5.976 for ws in ("ws1", "ws2")},
                 lin_sliding: {("SumY_max", ws): 40.1 - 6.5 for ws in ("ws1", "ws2")}}
        meas[s.id] = SectionValues(s.id, mv, alternatives=m_alt)
        sim[s.id] = SectionValues(s.id, sv, alternatives=s_alt)
    return sections, meas, sim, lin


def test_percentile_method_flips_sumy_max_and_the_verdict():
    sections, meas, sim, lin = _flip_campaign()
    res = validate(meas, sim, sections, {"kind": "passenger", "Q0_kN": 80.0}, n_boot=0)
    q = res.quantities["SumY_max"]
    assert q.mean == pytest.approx(-6.018, abs=1e-12) and q.mean_limit == 6.0
    assert not q.passed and q.definition_sensitive
    by_id = {a["reading"]["id"]: a for a in q.alternatives}
    flip = by_id[lin]
    assert flip["pass"] is True and flip["flips"] and flip["differs_in"] == ["percentile"]
    assert flip["mean"] == pytest.approx(-5.976, abs=1e-12)
    assert flip["std"] == pytest.approx(0.0, abs=1e-12)
    assert flip["values_changed"] == 24  # 12 sections × 2 wheelsets, simulated side
    # a reading that changes values but not the verdict: mean −6.5 still fails
    other = by_id[Reading("linear", "first_sample", "samples_half_open").id]
    assert other["mean"] == pytest.approx(-6.5) and other["pass"] is False and not other["flips"]
    # unchanged readings reproduce the chosen statistics
    same = by_id[Reading("inverted_cdf", "first_sample", "interpolant").id]
    assert same["mean"] == pytest.approx(-6.018) and same["values_changed"] == 0
    # every other quantity is insensitive; the verdict flips with the linear percentile
    assert [k for k, r in res.quantities.items() if r.definition_sensitive] == ["SumY_max"]
    assert res.coverage.ok and not res.validated
    assert res.validated_under[lin] is True and res.definition_sensitive is True
    doc = res.to_dict()
    json.dumps(doc, allow_nan=False)
    qd = next(x for x in doc["quantities"] if x["quantity"] == "SumY_max")
    assert qd["definition_sensitive"] is True and qd["definition_flips"] == [lin]
    assert doc["definitions"]["sensitive_quantities"] == ["SumY_max"]
    assert doc["definitions"]["verdict_sensitive"] is True
    assert next(x for x in doc["quantities"]
                if x["quantity"] == "ay_rms")["definition_sensitive"] is False


def test_plain_dictionaries_carry_no_sensitivity():
    sections, meas, sim, _ = _flip_campaign()
    res = validate({k: dict(v) for k, v in meas.items()}, {k: dict(v) for k, v in sim.items()},
                   sections, {"kind": "passenger", "Q0_kN": 80.0}, n_boot=0)
    d = res.to_dict()
    assert all(q["definition_sensitive"] is None for q in d["quantities"])
    assert d["definitions"]["verdict_sensitive"] is None


def test_undefined_reading_is_not_a_flip():
    sections, meas, sim, _ = _flip_campaign()
    rid = Reading("inverted_cdf", "section_start", "samples_closed").id
    meas["S00"].alternatives[rid] = {("SumY_max", "ws1"): math.nan}
    res = validate(meas, sim, sections, {"kind": "passenger", "Q0_kN": 80.0}, n_boot=0)
    alt = next(a for a in res.quantities["SumY_max"].alternatives if a["reading"]["id"] == rid)
    assert alt["pass"] is None and not alt["flips"] and alt["mean"] is None


def test_cli_marks_definition_sensitive_quantities():
    from railval.app.cli.cmd_validate import format_result

    sections, meas, sim, _ = _flip_campaign()
    text = format_result(validate(meas, sim, sections, {"kind": "passenger", "Q0_kN": 80.0}, n_boot=0))
    row = next(line for line in text.splitlines() if line.startswith("SumY_max"))
    assert " FAIL " in row and row.endswith("(definition-sensitive)")
    assert "passes with percentile linearly interpolated" in text
    assert "definition-sensitive (pass/fail changes" in text and text.endswith(
        "NOT VALIDATED (definition-sensitive: another reading gives the opposite verdict)")


def test_result_cache_keeps_alternatives_and_supplementary():
    from railval.core.en14363 import pack_values, unpack_values

    rid = Reading("linear", "first_sample", "samples_closed").id
    v = SectionValues("S1", {("SumY_max", "ws1"): 3.0}, warnings=["w"],
                      alternatives={rid: {("SumY_max", "ws1"): math.nan}},
                      supplementary={("ay_bg_rms", "b1"): 0.25})
    back = unpack_values("S1", pack_values(v))
    assert dict(back) == dict(v) and back.warnings == ["w"]
    assert math.isnan(back.value_under(rid, ("SumY_max", "ws1")))
    assert back.value_under(CHOSEN.id, ("SumY_max", "ws1")) == 3.0
    assert back.supplementary == {("ay_bg_rms", "b1"): 0.25}


# ------------------------------------------------------------------ real signals, stored
def store_definition_sensitive_configuration(database, campaign: str = "demo",
                                             name: str = "scaled") -> float:
    """Store a configuration whose signals are the measurement with every Y channel scaled by
    k, chosen so that SumY_max's mean D_v = (k − 1)·mean|M_v| lies between its values under
    the chosen reading and under the alternative reading with the most different mean|M_v|:
    the verdict of SumY_max then depends on the reading. Returns k."""
    from railval.core.en14363 import evaluate_batch
    from railval.db import repo

    with database.session() as s:
        sections = repo.section_infos(s, campaign)
        measured = repo.load_signalsets(s, campaign, None)
    secs = [x for x in sections if x.id in measured]
    vals = evaluate_batch([measured[x.id] for x in secs], secs)
    keys = [(v, k) for v in vals for k in v if k[0] == "SumY_max"]
    chosen = np.mean([abs(v[k]) for v, k in keys])
    alts = {r.id: np.mean([abs(v.value_under(r.id, k)) for v, k in keys])
            for r in alternatives_for(QUANTITIES["SumY_max"])}
    far = max(alts.values(), key=lambda m: abs(m - chosen))
    assert far != chosen
    k = 1.0 + 6.0 / math.sqrt(chosen * far)  # SumY mean limit 6 kN between the two readings
    scaled = {}
    for sid, ss in measured.items():
        ch = {c: (k * x if c.startswith("Y_") else x) for c, x in ss.channels.items()}
        scaled[sid] = SignalSet(ss.fs, ss.time_s, ss.distance_m, ch)
    with database.session(write=True) as s:
        repo.store_configuration(s, campaign, name, parent=None, effects={}, parameters={},
                                 description=f"measurement with Y scaled by {k:.4f}",
                                 signalsets=scaled)
    return k


def test_stored_configuration_is_definition_sensitive(sqlite_database, tmp_path):
    from railval.app.services.validation import validate_configuration
    from railval.db.importer import import_campaign
    from tests.factories import write_demo_campaign

    manifest = write_demo_campaign(tmp_path / "demo", n_sections=12, n_configs=1)
    import_campaign(sqlite_database, manifest.parent)
    k = store_definition_sensitive_configuration(sqlite_database)
    with sqlite_database.write_session(deferred=True) as s:
        res = validate_configuration(s, "demo", "scaled", n_boot=0)
    q = res.quantities["SumY_max"]
    # S = k·M exactly after the linear chain: D_v = (k − 1)·|M_v|
    pairs = res.pairs[res.pairs["quantity"] == "SumY_max"]
    np.testing.assert_allclose(pairs["D"], (k - 1) * pairs["M"].abs(), rtol=1e-9)
    assert q.definition_sensitive
    flips = [a for a in q.alternatives if a["flips"]]
    assert flips
    assert (abs(q.mean) > 6.0) != (abs(flips[0]["mean"]) > 6.0)
    assert "SumY_max" in res.to_dict()["definitions"]["sensitive_quantities"]


def test_reading_labels():
    r = Reading("linear", "first_sample", "samples_half_open")
    assert r.short() == "linear percentiles + grid from first sample + half-open sample window"
    assert r.short(sliding_mean=False) == "linear percentiles"
    assert CHOSEN.short() == "chosen reading"


def test_report_sections_show_sensitivity_and_supplementary():
    from railval.app.report import definition_html, supplementary_html
    from railval.app.views import view_of

    sections, meas, sim, _ = _flip_campaign()
    for sid in meas:
        meas[sid].supplementary = {("az_bg_rms", "b1"): 1.0}
        sim[sid].supplementary = {("az_bg_rms", "b1"): 1.5}
    doc = view_of(validate(meas, sim, sections, {"kind": "passenger", "Q0_kN": 80.0}, n_boot=0))
    rows = {r["quantity"]: r for r in doc.definition_rows()}
    assert set(rows) == {q for q in QUANTITIES if QUANTITIES[q].processing != "rms"}
    assert rows["SumY_max"]["definition_sensitive"] and rows["SumY_max"]["readings"] == 11
    assert rows["SumY_max"]["flipped by"] == "passes with linear percentiles"
    html = definition_html(doc)
    assert "definition-sensitive: SumY_max; the verdict itself changes" in html
    supp = supplementary_html(doc)
    assert "do not change the verdict" in supp and "az_bg_rms" in supp
    # D_v = 0.5 on 12 pairs: mean 0.5, rel 0.5, log2 ratio log2(1.5) = 0.585
    assert "<td>12</td><td>0.500</td><td>0.000</td><td>0.500</td><td>0.000</td><td>0.585</td>" in supp
