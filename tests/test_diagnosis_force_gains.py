"""Gains of the wheel-force channels as measurement candidates (docs/diagnosis.md "Model or
measurement?"): the groups (wheel, wheelset, side, bogie), the power law of each EN statistic
checked against the statistic re-evaluated from the signals, and the redundancy rule that keeps
a gain absorbing a common model error from being called a sensor fault."""

from __future__ import annotations

import numpy as np
import pytest

from railval.app.services.diagnosis_measurement import apply_redundancy_rule, not_sensor_faults
from railval.core.diagnosis import DiagnosisResult, TrustedCandidate
from railval.core.diagnosis.measurement import force_gain_groups, gain_degree, remapped_measurement
from railval.core.diagnosis.patterns import Component, Pattern
from railval.core.types import SectionInfo, SignalSet

WHEELS = [f"{k}_w{n}{s}" for k in "YQ" for n in range(1, 5) for s in "LR"]


def test_groups_per_wheel_wheelset_side_and_bogie():
    g = force_gain_groups(WHEELS + ["ay_cb_b1"])
    assert g["Y_w1L"] == ("Y_w1L",) and g["Y_w1"] == ("Y_w1L", "Y_w1R")
    assert g["Q_L"] == ("Q_w1L", "Q_w2L", "Q_w3L", "Q_w4L")
    assert g["Y_bogie2"] == ("Y_w3L", "Y_w3R", "Y_w4L", "Y_w4R")
    assert len(g) == 2 * (8 + 4 + 2 + 2) and not any("ay" in k for k in g)
    # a two-axle wagon: no bogie groups
    two = force_gain_groups([c for c in WHEELS if c[3] in "12"])
    assert "Y_bogie1" not in two and two["Q_w2"] == ("Q_w2L", "Q_w2R")


def test_power_law_of_each_statistic_equals_the_statistics_of_the_scaled_signals():
    """Independent check: the EN values re-evaluated from signals whose group channels are
    divided by g equal M / g^d with d from :func:`gain_degree`; ΣY with one wheel in the group
    has no power law (None) and indeed differs from every g^d."""
    fs, n = 200.0, 6000
    t = np.arange(n) / fs
    rng = np.random.default_rng(3)
    ch = {c: (40.0 if c[0] == "Q" else 5.0) * (1.5 + 0.2 * np.sin(0.7 * t + k)) + rng.normal(0, 1.0, n)
          for k, c in enumerate(WHEELS)}
    ss = {"S1": SignalSet(fs, t, 25.0 * t, ch)}
    sec = [SectionInfo("S1", 600.0, 100.0, 90.0, 3, 100.0, 600.0)]
    comps = [(q, p) for q, p in (("Y_qst", "w1L"), ("Y_max", "w1R"), ("YQ_qst", "w1L"), ("YQ_max", "w1R"),
                                 ("SumY_qst", "ws1"), ("SumY_max", "ws1"), ("Q_qst", "w1L"), ("Q_max", "w1R"))]
    g = 1.3
    base = remapped_measurement(ss, sec, lambda _s, c, _ss: c, comps)
    for group in (("Y_w1L", "Y_w1R"), ("Q_w1L", "Q_w1R"), ("Y_w1L",)):
        scaled = remapped_measurement(ss, sec, lambda _s, c, _ss: {k: (x / g if k in group else x)
                                                                   for k, x in c.items()}, comps)
        for q, p in comps:
            d = gain_degree(q, p, group)
            if d is None:
                assert q.startswith("SumY") and group == ("Y_w1L",)
                assert all(abs(scaled[("S1", q, p)] - base[("S1", q, p)] / g ** e) > 1e-3 for e in (0, 1))
            else:
                assert scaled[("S1", q, p)] == pytest.approx(base[("S1", q, p)] / g ** d, rel=1e-9), (group, q, p, d)
    assert gain_degree("YQ_qst", "w1L", ("Q_w1L",)) == -1 and gain_degree("YQ_qst", "w1L", ("Y_w1L", "Q_w1L")) == 0


def _cand(name, fitted, ci):
    pat = Pattern(["x"], ["x"], np.zeros(1), [Component("pair", "az_rms", 1, "b1")])
    wide = (ci[0] - 0.2, ci[1] + 0.2)  # the widened interval holds 1 in every case: the rule reads the bootstrap one
    return TrustedCandidate(name, 0.8, {}, [], [], "", pat, 0.0, kind="measurement", parameter="gain",
                            fitted=fitted, fitted_ci=wide, fitted_ci_bootstrap=ci, significant=True,
                            held_out_explained=0.8)


def _res(cands, verdict="cause"):
    return DiagnosisResult(Pattern(["x"], ["x"], np.ones(1), [Component("pair", "az_rms", 1, "b1")]), cands, True, [],
                           verdict=verdict)


def test_redundancy_rule_a_gain_interval_containing_one_is_no_sensor_fault():
    res = _res([_cand("gain Y_w1", 1.12, (0.95, 1.3)), _cand("gain Q_w2L", 0.8, (0.74, 0.86))])
    out = apply_redundancy_rule(res)
    assert set(out) == {"gain Y_w1"} and "contains 1" in out["gain Y_w1"]
    assert res.verdict == "uncertain" and any(f.startswith("not a sensor fault") for f in res.candidates[0].flags)
    res = _res([_cand("gain Q_w2L", 0.8, (0.74, 0.86))])
    assert apply_redundancy_rule(res) == {} and res.verdict == "cause"


def test_redundancy_rule_the_same_gain_on_every_channel_of_a_kind_is_a_model_error():
    """Every car body vertical accelerometer (or every Y transducer) wants ≈ 1.2: a model error
    common to them; one wheel alone at 1.3 with the others at 1 is a sensor fault."""
    same = [_cand("gain az_cb_b1", 1.21, (1.15, 1.27)), _cand("gain az_cb_b2", 1.19, (1.13, 1.25))]
    out = not_sensor_faults(_res(same))
    assert set(out) == {"gain az_cb_b1", "gain az_cb_b2"} and "same gain" in out["gain az_cb_b1"]
    wheels = [_cand(f"gain Y_w{n}L", 1.2 + 0.01 * n, (1.1, 1.35)) for n in (1, 2, 3, 4)] + \
        [_cand("gain Y_L", 1.22, (1.15, 1.3))]
    assert set(not_sensor_faults(_res(wheels))) == {c.name for c in wheels}
    one = [_cand("gain Y_w1L", 1.3, (1.22, 1.38)), _cand("gain Y_w2L", 1.02, (0.97, 1.08)),
           _cand("gain Y_w3L", 1.03, (0.98, 1.1))]
    assert "gain Y_w1L" not in not_sensor_faults(_res(one))


def test_redundancy_rule_most_channels_of_a_kind_below_one_is_a_model_error():
    """Seven of eight Y wheels want a gain below 1 (another creep law in the truth lowers every
    guiding force): no Y gain is a sensor fault, the side group neither; a bogie's four at 0.75
    with the other four at 1 stays a sensor fault."""
    low = [_cand(f"gain Y_w{n}{s}", 0.8, (0.76, 0.85)) for n in (1, 2, 3, 4) for s in "LR"][:7]
    wheels = low + [_cand("gain Y_w4R", 0.98, (0.95, 1.02)), _cand("gain Y_L", 0.78, (0.76, 0.82))]
    wheels[0] = _cand("gain Y_w1L", 0.7, (0.66, 0.74))  # not all alike: the strict rule does not apply
    out = not_sensor_faults(_res(wheels))
    assert "gain Y_L" in out and "7 of the 8 Y channels want a gain below 1" in out["gain Y_L"]
    bogie = [_cand(f"gain Y_w{n}{s}", 0.75 if n > 2 else 1.0, (0.72, 0.78) if n > 2 else (0.97, 1.03))
             for n in (1, 2, 3, 4) for s in "LR"] + [_cand("gain Y_bogie2", 0.75, (0.73, 0.77))]
    assert "gain Y_bogie2" not in not_sensor_faults(_res(bogie))


def test_redundancy_rule_the_same_wheelset_of_the_other_bogie_alike_is_a_model_error():
    """Both leading wheelsets (1 and 3) want Y × ≈ 0.91 (a softer flange contact in the truth):
    no sensor fault; wheelset 1 at 1.25 with wheelset 3 at 1.02 is one."""
    lead = [_cand("gain Y_w1", 0.908, (0.89, 0.93)), _cand("gain Y_w3", 0.93, (0.91, 0.95)),
            _cand("gain Y_w2", 1.06, (1.03, 1.09))]
    out = not_sensor_faults(_res(lead))
    assert "gain Y_w1" in out and "other bogie" in out["gain Y_w1"] and "gain Y_w2" not in out
    fault = [_cand("gain Y_w1", 1.25, (1.2, 1.3)), _cand("gain Y_w3", 1.02, (1.01, 1.03))]
    assert "gain Y_w1" not in not_sensor_faults(_res(fault))
    from railval.app.services.diagnosis_measurement import _counterpart

    assert [_counterpart(x) for x in ("Y_w1L", "Q_w4", "Y_bogie2", "Y_L", "az_cb_b1")] == \
        ["Y_w3L", "Q_w2", "Y_bogie1", None, None]


def test_batched_group_reevaluation_equals_each_groups_own_evaluation(sqlite_database):
    """On a synthetic campaign's recorded signals: the re-evaluations of every force group
    done in one batch (:func:`group_gain_reevaluations`, shared between a wheel and the side
    holding it) equal the group's own :func:`remapped_measurement` with its channels divided
    by g, for every group, component and node (to 1e-12, relative); ΣY with one wheel scaled
    differs from the unscaled value, so the comparison sees the gain."""
    from railval.app.services.campaign_context import load_context_and_measurement
    from railval.app.services.synth import synth
    from railval.core.diagnosis.measurement import FORCE_GAIN_NODES, group_gain_reevaluations

    synth(sqlite_database, name="fg", hidden=["friction_damping"], seed=3)
    with sqlite_database.session() as s:
        ctx, sets = load_context_and_measurement(s, "fg")
    sections = ctx.sections[:4]  # four sections keep the test short
    groups = force_gain_groups(ctx.channels)
    comps = sorted({(q, f"ws{n}") for q in ("SumY_qst", "SumY_max") for n in (1, 2)}
                   | {("YQ_max", "w1L"), ("Y_qst", "w2R")})
    redo = group_gain_reevaluations(sets, sections, groups, comps)
    base = remapped_measurement(sets, sections, lambda _s, c, _ss: c, comps)
    checked = 0
    for name, group in groups.items():
        other = [c for c in comps if gain_degree(*c, group) is None]
        for g in FORCE_GAIN_NODES:
            got = redo[name](g, other)
            want = remapped_measurement(sets, sections, lambda _s, c, _ss, g=g, group=group: {
                k: (x / g if k in group else x) for k, x in c.items()}, other)
            assert got.keys() == want.keys()
            for k, v in want.items():
                assert got[k] == pytest.approx(v, rel=1e-12, abs=1e-12), (name, g, k)
                if g != 1.0:
                    assert abs(v - base[k]) > 1e-9 * abs(base[k]), (name, g, k)
                checked += 1
    assert checked >= 2 * 4 * len(FORCE_GAIN_NODES)  # the wheel and side groups of Y, two ΣY statistics


def test_group_gain_evidence_equals_the_corrected_pairs_evidence_exactly():
    """Independent expectation: at every node the evidence of :func:`corrected_pairs` (M/g^d,
    ΣY from the re-evaluation, a zero and a NaN measurement among the records) through
    :func:`section_evidence` — equal bit for bit to the array path of :func:`group_gain_families`."""
    from railval.core.diagnosis.evidence import section_evidence
    from railval.core.diagnosis.measurement import (
        FORCE_GAIN_NODES,
        corrected_pairs,
        group_gain_families,
    )

    rng = np.random.default_rng(11)
    comps = [("Y_qst", "w1L"), ("YQ_max", "w1L"), ("SumY_max", "ws1"), ("Q_qst", "w1R"), ("az_rms", "b1")]
    limits = {"Y_qst": 4.0, "YQ_max": 0.1, "SumY_max": 6.0, "Q_qst": 9.0, "az_rms": 0.2}
    pairs = []
    for k in range(8):
        for q, p in comps:
            m, s = float(rng.normal(3, 2)), float(rng.normal(3, 2))
            m = 0.0 if (k, q) == (2, "Y_qst") else (float("nan") if (k, q) == (5, "Q_qst") else m)
            d = (s - m) * np.copysign(1.0, m) if m != 0 else s
            pairs.append({"section": f"S{k}", "quantity": q, "zone": 1 + k % 2, "position": p, "M": m, "S": s,
                          "D_norm": d / limits[q]})
    sections = [(f"S{k}", 1 + k % 2) for k in range(8)]
    base = section_evidence(pairs, {}, {}, sections, value_key="D_norm")
    redo_vals = {g: {(f"S{k}", "SumY_max", "ws1"): float(rng.normal(2, 1)) for k in range(8) if k != 3}
                 for g in FORCE_GAIN_NODES}
    group = ("Y_w1L", "Q_w1R")
    fam = group_gain_families(base, pairs, {}, {}, sections, {"x": group}, limits,
                              {"x": lambda g, c: redo_vals[g]})["x"]
    degs = {c: gain_degree(*c, group) for c in comps}
    assert degs[("YQ_max", "w1L")] == 1 and degs[("SumY_max", "ws1")] is None and degs[("az_rms", "b1")] == 0
    for g, ev in zip(FORCE_GAIN_NODES, fam.evidence, strict=True):
        def measured(r, g=g):
            d = degs[(r["quantity"], r["position"])]
            if d == 0:
                return None
            return redo_vals[g].get((r["section"], r["quantity"], r["position"])) if d is None else r["M"] / g ** d
        want = section_evidence(corrected_pairs(pairs, measured, limits), {}, {}, sections, value_key="D_norm",
                                like=base)
        assert np.array_equal(ev.sums, want.sums) and np.array_equal(ev.counts, want.counts), g
        assert ev.labels == want.labels


def test_single_channel_gain_evidence_equals_the_per_node_evidence_exactly():
    """Independent expectation: at every node, :func:`gain_pairs` (M/g) and the channel's band
    powers divided by g² through :func:`section_evidence` — equal bit for bit to the array path
    of :func:`gain_family`; another channel's band powers stay."""
    from railval.core.diagnosis.evidence import section_evidence
    from railval.core.diagnosis.measurement import GAIN_NODES, gain_family, gain_pairs

    rng = np.random.default_rng(12)
    limits = {"az_rms": 0.2, "ay_rms": 0.3}
    pairs = []
    for k in range(6):
        for q, p in (("az_rms", "b1"), ("az_rms", "b2"), ("ay_rms", "b1")):
            m, s = float(rng.normal(1, 0.5)), float(rng.normal(1, 0.5))
            pairs.append({"section": f"S{k}", "quantity": q, "zone": 1 + k % 2, "position": p, "M": m, "S": s,
                          "D_norm": (s - m) * np.copysign(1.0, m) / limits[q]})
    sections = [(f"S{k}", 1 + k % 2) for k in range(6)]
    bands = ((0.5, 2.0), (2.0, 8.0))
    sim = {f"S{k}": {c: rng.uniform(0.1, 2, 2) for c in ("az_cb_b1", "az_cb_b2")} for k in range(6)}
    meas = {f"S{k}": {c: rng.uniform(0.1, 2, 2) for c in ("az_cb_b1", "az_cb_b2")} for k in range(6)}
    base = section_evidence(pairs, sim, meas, sections, bands=bands, value_key="D_norm")
    comps = [("az_rms", "b1")]
    fam = gain_family(base, pairs, sim, meas, sections, "az_cb_b1", comps, limits, bands=bands)
    for g, ev in zip(GAIN_NODES, fam.evidence, strict=True):
        mb = {sid: {ch: (p / g ** 2 if ch == "az_cb_b1" else p) for ch, p in chans.items()} for sid, chans in meas.items()}
        want = section_evidence(gain_pairs(pairs, comps, g, limits), sim, mb, sections, bands=bands,
                                value_key="D_norm", like=base)
        for a in ("sums", "counts", "sim_power", "meas_power"):
            assert np.array_equal(getattr(ev, a), getattr(want, a)), (g, a)
        assert np.array_equal(ev.values(), want.values())
    assert not np.array_equal(fam.evidence[0].meas_power, base.meas_power)
