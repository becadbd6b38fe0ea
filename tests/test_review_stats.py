"""Statistics of expert review workshops (railval.core.review; docs/workshops.md "Statistics").

Every statistic is checked against a well-kept library on the same data (statsmodels,
krippendorff) or against an example computed by hand in the test; the whole analysis is
checked on simulated reviewers of known strictness (recovery test).
"""

from __future__ import annotations

import json
from fractions import Fraction
from math import comb

import krippendorff
import numpy as np
import pandas as pd
import pytest
import scipy.stats
import statsmodels.api as sm
from statsmodels.stats.inter_rater import fleiss_kappa as sm_fleiss_kappa
from statsmodels.stats.proportion import proportion_confint

from railval.core.errors import InvalidParameter
from railval.core.review import (
    analyse,
    fit_rasch,
    fit_threshold,
    monotone_threshold,
    fleiss_kappa,
    gwet_ac1,
    gwet_ac1_two_raters,
    krippendorff_alpha_nominal,
    mcnemar_exact,
    simulate_answers,
    simulate_workshop,
    wilson_interval,
    yes_curve,
)
from railval.core.review.agreement import counts_table


def _answers(rows, *, repeat=False, scaling="fixed"):
    """Rows ``(reviewer, plot, answer[, repeat[, scaling]])`` → an answers frame."""
    full = [(r[0], r[1], r[2], r[3] if len(r) > 3 else repeat, r[4] if len(r) > 4 else scaling, 5.0)
            for r in rows]
    return pd.DataFrame(full, columns=["reviewer", "plot", "answer", "repeat", "scaling", "seconds"])


def _plots(kinds: dict[str, str], deviation=None):
    ids = list(kinds)
    dev = [np.nan] * len(ids) if deviation is None else [deviation[i] for i in ids]
    return pd.DataFrame({"plot": ids, "kind": [kinds[i] for i in ids], "deviation": dev,
                         "sg_c": [np.nan] * len(ids)})


# --------------------------------------------------------------------------- Wilson
@pytest.mark.parametrize("k,n", [(0, 1), (0, 10), (3, 10), (10, 10), (57, 120), (119, 120), (1, 2)])
def test_wilson_interval_equals_statsmodels(k, n):
    lo, hi = wilson_interval(k, n)
    ref = proportion_confint(k, n, alpha=0.05, method="wilson")
    assert lo == pytest.approx(ref[0], abs=1e-12)
    assert hi == pytest.approx(ref[1], abs=1e-12)


def test_wilson_interval_vectorised_and_rejects_bad_counts():
    lo, hi = wilson_interval(np.array([2, 5]), np.array([10, 20]), confidence=0.9)
    for i, (k, n) in enumerate([(2, 10), (5, 20)]):
        ref = proportion_confint(k, n, alpha=0.1, method="wilson")
        assert (lo[i], hi[i]) == pytest.approx(ref, abs=1e-12)
    with pytest.raises(InvalidParameter, match="successes"):
        wilson_interval(11, 10)
    with pytest.raises(InvalidParameter, match="n ≥ 1"):
        wilson_interval(0, 0)


# --------------------------------------------------------------------------- Fleiss κ
def test_fleiss_kappa_equals_statsmodels():
    rng = np.random.default_rng(4)
    for n_raters, n_cat in ((5, 2), (12, 2), (7, 4)):
        p = rng.dirichlet(np.ones(n_cat), size=40)
        table = np.array([rng.multinomial(n_raters, row) for row in p])
        assert fleiss_kappa(table) == pytest.approx(sm_fleiss_kappa(table, method="fleiss"), abs=1e-12)


def test_fleiss_kappa_needs_equal_raters():
    with pytest.raises(InvalidParameter, match="same number"):
        fleiss_kappa([[2, 1], [1, 1]])


# --------------------------------------------------------------------------- Krippendorff α
def test_krippendorff_alpha_equals_package_with_missing_answers():
    rng = np.random.default_rng(7)
    for n_cat in (2, 3):
        truth = rng.integers(0, n_cat, 60)
        data = np.where(rng.random((9, 60)) < 0.7, truth, rng.integers(0, n_cat, (9, 60))).astype(float)
        data[rng.random(data.shape) < 0.25] = np.nan          # a quarter of the answers missing
        ref = krippendorff.alpha(reliability_data=data, level_of_measurement="nominal")
        assert krippendorff_alpha_nominal(data) == pytest.approx(ref, abs=1e-12)


def test_krippendorff_alpha_hand_example():
    # 2 raters, 4 units: (1,1), (0,0), (1,0), (1,1). Pairable values n = 8, n_1 = 5, n_0 = 3;
    # coincidences o_11 = 2+2 = 4, o_00 = 2, so D_o ∝ 8 − 6 = 2 and
    # α = 1 − (n−1)·2 / (n² − n_1² − n_0²) = 1 − 7·2/(64 − 25 − 9) = 1 − 14/30 = 8/15.
    data = np.array([[1, 0, 1, 1], [1, 0, 0, 1]], dtype=float)
    assert krippendorff_alpha_nominal(data) == pytest.approx(8 / 15, abs=1e-12)


# --------------------------------------------------------------------------- Gwet AC1
def test_gwet_ac1_two_raters_worked_example():
    # Two raters, 10 plots (1 = Yes). They disagree on plots 7 and 9, so p_a = 8/10.
    # Each says Yes 8 times: π_yes = (0.8 + 0.8)/2 = 0.8, π_no = 0.2,
    # p_e = Σ π_k(1 − π_k)/(q − 1) = 0.16 + 0.16 = 0.32, AC1 = (0.8 − 0.32)/(1 − 0.32) = 12/17.
    # (Cohen's κ on the same table is (0.8 − 0.68)/0.32 = 0.375 — the high-agreement paradox
    # AC1 was made for, Gwet 2008.)
    a = [1, 1, 1, 1, 1, 1, 1, 0, 0, 1]
    b = [1, 1, 1, 1, 1, 1, 0, 0, 1, 1]
    expected = float(Fraction(12, 17))
    assert gwet_ac1_two_raters(a, b) == pytest.approx(expected, abs=1e-12)
    # the multiple-rater formula reduces to the two-rater one
    assert gwet_ac1(np.array([a, b], dtype=float), categories=(0, 1)) == pytest.approx(expected, abs=1e-12)


def test_gwet_ac1_multiple_raters_with_missing_answers_by_hand():
    # 3 raters, 4 plots (NaN = no answer):
    #   plot 1: Y Y Y   r=3   Σ r_k(r_k−1)/(r(r−1)) = 6/6 = 1
    #   plot 2: Y N –   r=2   0/2 = 0
    #   plot 3: N N N   r=3   1
    #   plot 4: Y – –   r=1   (not pairable: out of p_a, in π)
    # p_a = (1 + 0 + 1)/3 = 2/3; π_yes = (3/3 + 1/2 + 0/3 + 1/1)/4 = 5/8; p_e = 2·5/8·3/8 = 15/32;
    # AC1 = (2/3 − 15/32)/(1 − 15/32) = (19/96)/(17/32) = 19/51.
    nan = np.nan
    data = np.array([[1, 1, 0, 1], [1, 0, 0, nan], [1, nan, 0, nan]], dtype=float)
    assert gwet_ac1(data, categories=(0, 1)) == pytest.approx(19 / 51, abs=1e-12)


def test_gwet_ac1_random_two_raters_both_forms_agree():
    rng = np.random.default_rng(11)
    a = rng.integers(0, 3, 50)
    b = np.where(rng.random(50) < 0.6, a, rng.integers(0, 3, 50))
    assert gwet_ac1(np.array([a, b], dtype=float), categories=(0, 1, 2)) == pytest.approx(
        gwet_ac1_two_raters(a, b, categories=(0, 1, 2)), abs=1e-12)


def test_counts_table_rejects_unknown_category():
    with pytest.raises(InvalidParameter, match="not among the categories"):
        counts_table(np.array([[0, 1, 2]], dtype=float), categories=(0, 1))


# --------------------------------------------------------------------------- McNemar
def test_mcnemar_exact_hand_example():
    # discordant pairs b = 2, c = 8: two-sided exact p = 2·P(X ≤ 2 | n=10, ½)
    #   = 2·(C(10,0) + C(10,1) + C(10,2))/2¹⁰ = 2·56/1024 = 0.109375
    stat, p = mcnemar_exact([[10, 2], [8, 5]])
    assert stat == 2
    assert p == pytest.approx(2 * (comb(10, 0) + comb(10, 1) + comb(10, 2)) / 2**10, abs=1e-12)
    assert mcnemar_exact([[4, 0], [0, 3]])[1] == 1.0      # no discordant pair


# --------------------------------------------------------------------------- Rasch
def test_rasch_fit_equals_statsmodels_glm_at_vanishing_ridge():
    """With a negligible ridge the penalised fit is the maximum-likelihood fit of the logistic
    model with plot dummies and sum-to-zero reviewer effects — statsmodels' GLM on that design
    gives the same estimates and standard errors."""
    rng = np.random.default_rng(5)
    n_r, n_p = 8, 30
    s = rng.normal(0, 0.8, n_r)
    a = rng.normal(0, 1.0, n_p)
    rr, pp = np.meshgrid(np.arange(n_r), np.arange(n_p), indexing="ij")
    rr, pp = rr.ravel(), pp.ravel()
    y = (rng.random(rr.size) < scipy.special.expit(a[pp] - s[rr])).astype(float)
    mixed = [j for j in range(n_p) if 0 < y[pp == j].sum() < n_r]     # no separated plot
    keep = np.isin(pp, mixed)
    rr, pp, y = rr[keep], np.searchsorted(mixed, pp[keep]), y[keep]
    n_p = len(mixed)
    fit = fit_rasch(rr, pp, y, n_reviewers=n_r, n_plots=n_p, ridge=1e-9)
    assert fit.converged
    # design: a_p (plot dummies), θ_k = s_k for k < R with s_R = −Σθ; η = a_p − s_r
    x = np.zeros((y.size, n_p + n_r - 1))
    x[np.arange(y.size), pp] = 1.0
    for k in range(n_r - 1):
        x[rr == k, n_p + k] = -1.0
        x[rr == n_r - 1, n_p + k] = 1.0
    ref = sm.GLM(y, x, family=sm.families.Binomial()).fit(tol=1e-12)
    assert fit.acceptability == pytest.approx(ref.params[:n_p], abs=1e-5)
    assert fit.strictness[:-1] == pytest.approx(ref.params[n_p:], abs=1e-5)
    assert fit.strictness.sum() == pytest.approx(0.0, abs=1e-10)
    assert fit.acceptability_se == pytest.approx(ref.bse[:n_p], rel=1e-4)
    assert fit.strictness_se[:-1] == pytest.approx(ref.bse[n_p:], rel=1e-4)


def test_rasch_keeps_all_yes_reviewer_and_plot_finite():
    rr = np.repeat(np.arange(3), 4)
    pp = np.tile(np.arange(4), 3)
    y = np.array([1, 1, 1, 1,  1, 0, 1, 0,  1, 0, 0, 0], dtype=float)   # reviewer 0: all Yes; plot 0: all Yes
    fit = fit_rasch(rr, pp, y)
    assert fit.converged
    assert np.all(np.isfinite(fit.strictness)) and np.all(np.isfinite(fit.acceptability))
    assert fit.strictness[0] < fit.strictness[1] < fit.strictness[2]    # most Yes = least strict
    assert fit.acceptability[0] == max(fit.acceptability)


# --------------------------------------------------------------------------- threshold
def test_threshold_fit_equals_statsmodels_glm_with_clustered_covariance():
    """ridge = 0: the fit is the GLM ``logit P = β log v − s_r`` (reviewer dummies, no
    intercept); its plot-clustered covariance is statsmodels' ``cov_type="cluster"``, and the
    interval is the delta method for ``log v₅₀ = s̄/β`` computed here from that covariance."""
    w = simulate_workshop(10, 60, seed=3, strictness_sd=0.8, repeat_share=0.0)
    dev = w.plots.set_index("plot")["deviation"]
    v = dev.loc[w.answers["plot"]].to_numpy()
    fit = fit_threshold(v, w.answers["answer"].to_numpy(), w.answers["reviewer"].to_numpy(),
                        w.answers["plot"].to_numpy(), ridge=0.0)
    names, ri = np.unique(w.answers["reviewer"].to_numpy(), return_inverse=True)
    x = np.zeros((v.size, 1 + names.size))
    x[:, 0] = np.log(v)
    x[np.arange(v.size), 1 + ri] = -1.0
    groups = np.unique(w.answers["plot"].to_numpy(), return_inverse=True)[1]
    ref = sm.GLM(w.answers["answer"].to_numpy(dtype=float), x, family=sm.families.Binomial()).fit(
        tol=1e-12, cov_type="cluster", cov_kwds={"groups": groups})
    beta, s = ref.params[0], ref.params[1:]
    assert fit.slope == pytest.approx(beta, rel=1e-6)
    assert fit.intercept == pytest.approx(-s.mean(), rel=1e-6)
    log50 = s.mean() / beta
    grad = np.concatenate([[-s.mean() / beta**2], np.full(names.size, 1.0 / (names.size * beta))])
    se = np.sqrt(grad @ ref.cov_params() @ grad)
    z = scipy.stats.norm.ppf(0.975)
    assert fit.at_50 == pytest.approx(np.exp(log50), rel=1e-6)
    assert fit.ci == pytest.approx((np.exp(log50 - z * se), np.exp(log50 + z * se)), rel=1e-5)
    # the typical reviewer's curve passes ½ at v₅₀
    assert yes_curve(fit.at_50, fit.intercept, fit.slope) == pytest.approx(0.5, abs=1e-12)


def test_linear_link_threshold_equals_statsmodels_glm():
    """power = 1 (logit linear in v): the fit is the GLM ``logit P = β (v − 1) − s_r``;
    v₅₀ = 1 + s̄/β."""
    w = simulate_workshop(10, 60, seed=5, strictness_sd=0.8, repeat_share=0.0, response="linear")
    v = w.plots.set_index("plot")["deviation"].loc[w.answers["plot"]].to_numpy()
    fit = fit_threshold(v, w.answers["answer"].to_numpy(), w.answers["reviewer"].to_numpy(),
                        w.answers["plot"].to_numpy(), ridge=0.0, power=1.0)
    names, ri = np.unique(w.answers["reviewer"].to_numpy(), return_inverse=True)
    x = np.zeros((v.size, 1 + names.size))
    x[:, 0] = v - 1.0
    x[np.arange(v.size), 1 + ri] = -1.0
    ref = sm.GLM(w.answers["answer"].to_numpy(dtype=float), x, family=sm.families.Binomial()).fit(tol=1e-12)
    beta, s = ref.params[0], ref.params[1:]
    assert fit.slope == pytest.approx(beta, rel=1e-6)
    assert fit.at_50 == pytest.approx(1.0 + s.mean() / beta, rel=1e-6)
    assert fit.loglik == pytest.approx(ref.llf, rel=1e-9)
    assert yes_curve(fit.at_50, fit.intercept, fit.slope, power=1.0) == pytest.approx(0.5, abs=1e-12)


def test_threshold_none_without_a_falling_curve():
    rng = np.random.default_rng(0)
    v = np.repeat(np.linspace(0.5, 2.0, 20), 6)
    y = rng.random(v.size) < scipy.special.expit(2.0 * np.log(v))      # more deviation → more Yes
    fit = fit_threshold(v, y, np.tile(np.arange(6), 20), np.repeat(np.arange(20), 6))
    assert fit.slope > 0 and fit.at_50 is None and fit.ci is None


# --------------------------------------------------------------------------- analysis: hand examples
def test_table1_by_hand_only_first_fixed_answers_count():
    kinds = {"y1": "Y", "y2": "Y", "y3": "Y", "q1": "Q", "q2": "Q"}
    rows = [
        # reviewer A: Y 2/3 yes, Q 0/2
        ("A", "y1", True), ("A", "y2", True), ("A", "y3", False), ("A", "q1", False), ("A", "q2", False),
        # reviewer B: Y 1/3, Q 2/2
        ("B", "y1", False), ("B", "y2", True), ("B", "y3", False), ("B", "q1", True), ("B", "q2", True),
        # reviewer C answered only Y so far: 3/3
        ("C", "y1", True), ("C", "y2", True), ("C", "y3", True),
        # a hidden repeat and an automatic-scaling showing must not enter Table 1
        ("C", "y1", False, True, "fixed"), ("B", "q1", False, False, "auto"),
    ]
    res = analyse(_answers(rows), _plots(kinds), n_boot=0).to_dict()
    assert res["table1"] == [
        {"kind": "Y", "plots": 3, "reviewers": 3, "answers": 9, "min_yes": pytest.approx(1 / 3),
         "min_yes_count": 1, "min_yes_answers": 3, "max_yes": 1.0, "max_yes_count": 3, "max_yes_answers": 3},
        {"kind": "Q", "plots": 2, "reviewers": 2, "answers": 4, "min_yes": 0.0, "min_yes_count": 0,
         "min_yes_answers": 2, "max_yes": 1.0, "max_yes_count": 2, "max_yes_answers": 2},
    ]
    by = {r["reviewer"]: r for r in res["reviewers"]}
    assert by["A"]["answers"] == 5 and by["A"]["yes_share"] == pytest.approx(2 / 5)
    assert by["A"]["yes_share_ci"] == pytest.approx(list(proportion_confint(2, 5, method="wilson")))
    assert by["C"]["answers"] == 3 and by["C"]["yes_share"] == 1.0


def test_consistency_on_hidden_repeats_by_hand():
    kinds = {f"p{i}": "Y" for i in range(4)}
    rows = [
        ("A", "p0", True), ("A", "p1", False), ("A", "p2", True), ("A", "p3", True),
        ("B", "p0", True), ("B", "p1", True), ("B", "p2", False), ("B", "p3", True),
        # A repeats p0 (same), p1 (changed), p2 (same): 2 of 3 consistent
        ("A", "p0", True, True), ("A", "p1", True, True), ("A", "p2", True, True),
        # B: no repeat → consistency None
    ]
    res = analyse(_answers(rows), _plots(kinds), n_boot=0).to_dict()
    by = {r["reviewer"]: r for r in res["reviewers"]}
    assert by["A"]["consistency"] == pytest.approx(2 / 3) and by["A"]["repeats"] == 3
    assert by["B"]["consistency"] is None and by["B"]["repeats"] == 0
    assert by["A"]["yes_share"] == pytest.approx(3 / 4)       # repeats do not count as answers


def test_scaling_effect_mcnemar_by_hand():
    kinds = {f"p{i}": "Y" for i in range(6)}
    fixed = [("A", "p0", True), ("A", "p1", True), ("A", "p2", False), ("A", "p3", False),
             ("A", "p4", False), ("A", "p5", True),
             ("B", "p0", False), ("B", "p1", True), ("B", "p2", False), ("B", "p3", True)]
    auto = [("A", "p0", True), ("A", "p1", False), ("A", "p2", True), ("A", "p3", True), ("A", "p4", True),
            ("B", "p0", True), ("B", "p1", True), ("B", "p2", True)]
    # pairs (fixed → auto): A p0 Y→Y, p1 Y→N, p2 N→Y, p3 N→Y, p4 N→Y; B p0 N→Y, p1 Y→Y, p2 N→Y
    # table [[YY, YN], [NY, NN]] = [[2, 1], [5, 0]]; exact p = 2·P(X ≤ 1 | 6, ½) = 2·7/64
    rows = fixed + [(r, p, a, False, "auto") for r, p, a in auto]
    res = analyse(_answers(rows), _plots(kinds), n_boot=0).to_dict()
    eff = res["scaling_effect"]
    assert eff["pairs"] == 8 and eff["changed"] == 6 and eff["changed_share"] == pytest.approx(6 / 8)
    assert eff["fixed_yes_auto_no"] == 1 and eff["fixed_no_auto_yes"] == 5
    assert eff["fixed_yes_share"] == pytest.approx(3 / 8) and eff["auto_yes_share"] == pytest.approx(7 / 8)
    assert eff["p_value"] == pytest.approx(2 * 7 / 64, abs=1e-12)
    assert eff["changed_share_ci"] == pytest.approx(list(proportion_confint(6, 8, method="wilson")))
    # without automatic-scaling answers there is no scaling effect
    assert analyse(_answers(fixed), _plots(kinds), n_boot=0).scaling_effect is None


def test_fleiss_block_rule_with_an_unfinished_reviewer():
    kinds = {f"p{i}": "Y" for i in range(4)}
    rows = [("A", "p0", True), ("A", "p1", False), ("A", "p2", True), ("A", "p3", True),
            ("B", "p0", True), ("B", "p1", True), ("B", "p2", False), ("B", "p3", True),
            ("C", "p0", True), ("C", "p1", False)]
    res = analyse(_answers(rows), _plots(kinds), n_boot=0).to_dict()
    fk = res["agreement"]["fleiss_kappa"]
    # blocks: {A, B} × 4 plots = 8 answers beats {A, B, C} × 2 plots = 6
    assert fk["reviewers"] == 2 and fk["plots"] == 4
    table = np.array([[0, 2], [1, 1], [1, 1], [0, 2]])          # (No, Yes) per plot for A and B
    assert fk["value"] == pytest.approx(sm_fleiss_kappa(table), abs=1e-12)
    # α uses every plot with two answers or more, including C's
    data = np.array([[1, 0, 1, 1], [1, 1, 0, 1], [1, 0, np.nan, np.nan]])
    alpha = res["agreement"]["krippendorff_alpha"]
    assert alpha["value"] == pytest.approx(krippendorff.alpha(reliability_data=data, level_of_measurement="nominal"))
    assert alpha["plots"] == 4 and alpha["reviewers"] == 3
    assert res["agreement"]["gwet_ac1"]["value"] == pytest.approx(gwet_ac1(data, categories=(0, 1)))


# --------------------------------------------------------------------------- analysis: simulated workshops
def test_analysis_agreement_equals_libraries_on_simulated_answers():
    w = simulate_workshop(12, 60, seed=9)
    res = analyse(w.answers, w.plots, n_boot=200, seed=1).to_dict()
    first = w.answers[~w.answers["repeat"]]
    mat = first.pivot(index="reviewer", columns="plot", values="answer").astype(float)
    counts = np.stack([(mat == 0).sum(axis=0), (mat == 1).sum(axis=0)], axis=1)
    ag = res["agreement"]
    assert ag["fleiss_kappa"]["value"] == pytest.approx(sm_fleiss_kappa(counts), abs=1e-12)
    assert ag["fleiss_kappa"]["reviewers"] == 12 and ag["fleiss_kappa"]["plots"] == 60
    assert ag["krippendorff_alpha"]["value"] == pytest.approx(
        krippendorff.alpha(reliability_data=mat.to_numpy(), level_of_measurement="nominal"), abs=1e-12)
    for name in ("fleiss_kappa", "krippendorff_alpha", "gwet_ac1"):
        lo, hi = ag[name]["ci"]
        assert lo < ag[name]["value"] < hi and hi - lo < 0.3


def test_analysis_with_unfinished_reviewers_equals_krippendorff():
    w = simulate_workshop(6, 40, seed=2)
    part = simulate_answers(w.acceptability, {"late": 0.3}, seed=5, answer_share=0.4)
    answers = pd.concat([w.answers, part], ignore_index=True)
    res = analyse(answers, w.plots, n_boot=0).to_dict()
    first = answers[~answers["repeat"]]
    mat = first.pivot(index="reviewer", columns="plot", values="answer").astype(float)
    assert res["agreement"]["krippendorff_alpha"]["value"] == pytest.approx(
        krippendorff.alpha(reliability_data=mat.to_numpy(), level_of_measurement="nominal"), abs=1e-12)
    assert res["agreement"]["fleiss_kappa"]["reviewers"] == 6      # the unfinished reviewer is left out
    late = next(r for r in res["reviewers"] if r["reviewer"] == "late")
    assert late["answers"] == 16 and late["strictness"] is not None


def test_recovery_of_known_strictness_and_threshold():
    """20 simulated reviewers × 120 plots, deviations log-normal around 1, true 50 % deviation
    of a typical reviewer 1.2, strictness spread 1.5 logits (about the spread of Table 1 of
    Polach & Böttcher 2014: 9 % to 95 % Yes)."""
    w = simulate_workshop(20, 120, seed=12, deviation_at_50=1.2, strictness_sd=1.5)
    res = analyse(w.answers, w.plots, n_boot=0).to_dict()
    est = np.array([r["strictness"] for r in res["reviewers"]])
    true = np.array([w.strictness[r["reviewer"]] for r in res["reviewers"]])
    assert scipy.stats.spearmanr(est, true).statistic >= 0.9
    inside = sum(lo <= t <= hi for (lo, hi), t in zip((r["strictness_ci"] for r in res["reviewers"]), true))
    assert inside >= 16                      # 95 % Wald intervals: expect 19 of 20
    th = res["threshold"]
    lo, hi = th["ci"]
    assert lo <= 1.2 <= hi
    # not trivially wide: ±20 % (interpolated between adjacent observed deviations, as the drawn
    # curve is; 0.12–0.42 wide measured on this size, seeds 0–7 and 12, log and linear reviewers)
    assert hi - lo < 0.5
    assert th["deviation_fit"]["plots"] == 120 and th["deviation_fit"]["answers"] == 2400
    # sg_c = 0.25·d·exp(N(0, 0.2²)): regressing on the noisy log C shrinks log d by
    # λ = 0.5²/(0.5² + 0.2²) = 0.862, so a typical reviewer is at ½ where
    # log C = log 0.25 + log 1.2/λ, i.e. C ≈ 0.309
    assert th["sg_c_at_50"] == pytest.approx(0.25 * np.exp(np.log(1.2) / (0.25 / 0.29)), rel=0.12)
    assert th["sg_c_ci"][0] < th["sg_c_at_50"] < th["sg_c_ci"][1]


def test_plots_without_deviation_stay_out_of_the_threshold():
    w = simulate_workshop(10, 60, seed=4, no_deviation_share=0.25)
    res = analyse(w.answers, w.plots, n_boot=0).to_dict()
    with_dev = int(w.plots["deviation"].notna().sum())
    assert 0 < with_dev < 60
    assert res["threshold"]["deviation_fit"]["plots"] == with_dev
    assert res["threshold"]["deviation_fit"]["answers"] == 10 * with_dev


def test_analysis_json_contract_and_reproducibility():
    w = simulate_workshop(8, 30, seed=6, auto_share=0.2, auto_shift=1.0)
    a = analyse(w.answers, w.plots, n_boot=300, seed=3)
    d = a.to_dict()
    assert list(d) == ["table1", "reviewers", "agreement", "threshold", "scaling_effect"]
    json.dumps(d, allow_nan=False)
    assert set(d["reviewers"][0]) >= {"reviewer", "answers", "yes_share", "yes_share_ci", "strictness",
                                      "strictness_ci", "consistency"}
    assert set(d["agreement"]) == {"fleiss_kappa", "krippendorff_alpha", "gwet_ac1"}
    assert all(set(v) >= {"value", "ci"} for v in d["agreement"].values())
    assert set(d["threshold"]) >= {"deviation_at_50", "ci", "sg_c_at_50", "sg_c_ci"}
    assert d["scaling_effect"]["pairs"] == 8 * 6
    assert analyse(w.answers, w.plots, n_boot=300, seed=3).to_dict() == d
    assert analyse(w.answers, w.plots, n_boot=300, seed=4).to_dict()["agreement"] != d["agreement"]
    assert all(v["ci"] is None for v in analyse(w.answers, w.plots, n_boot=0).agreement.values())
    assert len(a.plots) == 30 and {"acceptability", "deviation", "yes_share"} <= set(a.plots[0])


def test_analysis_of_a_workshop_without_answers():
    kinds = {"p1": "Y", "p2": "Q"}
    res = analyse(_answers([]), _plots(kinds, {"p1": 0.5, "p2": 2.0})).to_dict()
    none = {f"{e}_yes{s}": None for e in ("min", "max") for s in ("", "_count", "_answers")}
    assert res["table1"] == [{"kind": "Y", "plots": 1, "reviewers": 0, "answers": 0, **none},
                             {"kind": "Q", "plots": 1, "reviewers": 0, "answers": 0, **none}]
    assert res["reviewers"] == [] and res["scaling_effect"] is None
    assert all(v["value"] is None for v in res["agreement"].values())
    assert res["threshold"]["deviation_at_50"] is None and res["threshold"]["ci"] is None
    assert res["threshold"]["deviation_at_50_status"] == "too few answers to estimate"
    assert res["threshold"]["deviation_n"] == {"answers": 0, "reviewers": 0, "plots": 0}


# --------------------------------------------------------------------------- bad input
@pytest.mark.parametrize("mutate,match", [
    (lambda a, p: (a.drop(columns="scaling"), p), r"answers: missing column\(s\) \['scaling'\]"),
    (lambda a, p: (a.assign(answer=a["answer"].astype(object).where(a.index != 3, "maybe")), p),
     r"answers row 3 \(reviewer 'A', plot 'p3'\): column 'answer' must be True/False, got 'maybe'"),
    (lambda a, p: (a.assign(plot=a["plot"].where(a.index != 2, "zz")), p),
     r"answers row 2 .*plot 'zz' is not among the workshop's plots"),
    (lambda a, p: (a.assign(scaling=a["scaling"].where(a.index != 1, "log")), p),
     r"answers row 1 .*column 'scaling' must be one of \['fixed', 'auto'\], got 'log'"),
    (lambda a, p: (a.assign(seconds=a["seconds"].where(a.index != 0, -2.0)), p),
     r"answers row 0 .*column 'seconds' must be a number ≥ 0, got -2.0"),
    (lambda a, p: (pd.concat([a, a.iloc[[1]]], ignore_index=True), p),
     r"answers row 4 \(reviewer 'A', plot 'p1'\): a second first answer"),
    (lambda a, p: (a, pd.concat([p, p.iloc[[0]]], ignore_index=True)), r"plots row 4: duplicate plot id 'p0'"),
    (lambda a, p: (a, p.assign(deviation=[0.5, -1.0, 1.0, 1.0])),
     r"plots row 1 \(plot 'p1'\): column 'deviation' must be ≥ 0, got -1.0"),
])
def test_bad_input_names_row_and_column(mutate, match):
    kinds = {f"p{i}": "Y" for i in range(4)}
    answers = _answers([("A", f"p{i}", i % 2 == 0) for i in range(4)])
    plots = _plots(kinds, {f"p{i}": 1.0 for i in range(4)})
    a, p = mutate(answers, plots)
    with pytest.raises(InvalidParameter, match=match):
        analyse(a, p)


def test_bench_review_runs_on_a_small_workshop():
    import argparse

    from railval.app.bench import bench_review

    parser = argparse.ArgumentParser()
    bench_review.add_arguments(parser)
    figures = bench_review.run(parser.parse_args(["--reviewers", "5", "--plots", "20", "--boot", "50",
                                                  "--repeat", "1"]))
    assert figures["first_answers"] == 100
    assert figures["answers_total"] == 100 + 5 * 2 + 5 * 2      # 10 % repeats, 10 % automatic scaling
    assert figures["analyse_full"]["wall_ms"] > 0 and figures["baseline_analyse_without_bootstrap"]["cpu_ms"] >= 0
    assert "baseline_rasch_fit_statsmodels_glm_one_call" not in figures


# --------------------------------------------------------------------------- link-robust 50 % point
def test_monotone_threshold_hand_examples():
    """The drawn curve P = expit(isotonic fit) crossing ½, linear in v between adjacent
    values: already monotone → between v = 1 (P = expit 1) and v = 2 (P = expit −1), by
    symmetry 1.5; with a violator (−1 before 1) pooled adjacent violators give the block
    [0, 0], P = ½ on the segment 1 … 2, whose midpoint is 1.5 again."""
    v = np.array([0.5, 1.0, 2.0, 4.0])
    assert monotone_threshold(v, np.array([2.0, 1.0, -1.0, -2.0]), n_boot=0).at_50 == pytest.approx(1.5)
    pooled = monotone_threshold(v, np.array([2.0, -1.0, 1.0, -2.0]), n_boot=0)
    assert pooled.at_50 == pytest.approx(1.5)
    assert pooled.curve_value == tuple(v)
    assert pooled.curve_yes == pytest.approx(scipy.special.expit([2.0, 0.0, 0.0, -2.0]))
    # order of the input does not matter; a fit that never crosses has no value and says where it lies
    assert monotone_threshold(v[::-1], np.array([-2.0, -1.0, 1.0, 2.0]), n_boot=0).at_50 == pytest.approx(1.5)
    above = monotone_threshold(v, np.array([2.0, 1.0, 1.0, 0.5]), n_boot=50)
    assert above.at_50 is None and above.status == "above the observed range"
    assert above.ci is None and above.ci_status == "above the observed range"
    below = monotone_threshold(v, np.array([-0.5, -1.0, -1.0, -2.0]), n_boot=0)
    assert below.at_50 is None and below.status == "below the observed range"
    with pytest.raises(InvalidParameter):
        monotone_threshold(v, np.ones(3))


@pytest.mark.parametrize("response", ["log", "linear", "step"])
def test_fifty_percent_point_does_not_depend_on_the_response_curve(response):
    """Simulated reviewers (20 × 240 plots, true 50 % deviation 1.2, strictness spread 1.5
    logits) answering on log deviation, on the deviation itself and on a noisy step: the
    reported 50 % point is within 10 % of the truth or its interval covers it — on each of
    five workshops. The log-link fit alone misses the linear reviewers (interval excludes
    1.2 on most of them), which is what the model-free estimate repairs."""
    log_missed = 0
    for seed in range(5):
        w = simulate_workshop(20, 240, seed=seed, deviation_at_50=1.2, strictness_sd=1.5,
                              response=response, repeat_share=0.0)
        th = analyse(w.answers, w.plots, n_boot=0, threshold_boot=300, seed=seed).to_dict()["threshold"]
        assert th["method"].startswith("isotonic")
        lo, hi = th["ci"]
        at = th["deviation_at_50"]
        assert abs(at / 1.2 - 1) <= 0.10 or lo <= 1.2 <= hi, (seed, at, lo, hi)
        sens = th["link_sensitivity"]
        assert [r["link"] for r in sens["links"]] == ["log", "sqrt", "linear"]
        assert sens["chosen"] in {"log", "sqrt", "linear"} and sens["relative_spread"] >= 0
        assert th["deviation_fit"]["link"] == sens["chosen"]
        log_fit = sens["links"][0]
        log_missed += not (log_fit["ci"][0] <= 1.2 <= log_fit["ci"][1])
        if response == "linear":       # the likelihood tells the linear reviewers apart
            assert sens["chosen"] in {"linear", "sqrt"}
        json.dumps(th, allow_nan=False)
    if response == "linear":
        assert log_missed >= 4
