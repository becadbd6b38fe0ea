"""The workshop's 50 % value is the crossing of the curve the analysis page draws (issue 39).

The reported value and the drawn "monotone fit, typical reviewer" come from one computation
(:func:`railval.core.review.threshold.monotone_threshold`). These tests recompute both
independently of it — pooled adjacent violators written out here (Ayer et al. 1955) instead
of ``scipy.optimize.isotonic_regression``, the crossing by walking the drawn segments — on
simulated workshops of 1 to 20 reviewers and 12 to 120 plots, and check the n that each
figure carries and the "too few answers to estimate" floor (docs/workshops.md).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from railval.core.review import analyse, monotone_threshold, simulate_workshop
from railval.core.review.analysis import MIN_ANSWERS, MIN_PLOTS

TOO_FEW = "too few answers to estimate"


def _pava_decreasing(a: list[float]) -> list[float]:
    """Falling isotonic regression by pooled adjacent violators, unit weights, by hand."""
    blocks: list[list[float]] = []            # [sum, count]
    for x in a:
        blocks.append([x, 1.0])
        while len(blocks) > 1 and blocks[-2][0] / blocks[-2][1] < blocks[-1][0] / blocks[-1][1]:
            s, c = blocks.pop()
            blocks[-1][0] += s
            blocks[-1][1] += c
    out: list[float] = []
    for s, c in blocks:
        out += [s / c] * int(c)
    return out


def _drawn_curve(plots: list[dict], column: str) -> tuple[list[float], list[float]]:
    """The points of the drawn curve, recomputed: plots with a value and an acceptability,
    sorted by value (stable), P = 1/(1 + exp(−fit))."""
    pts = [(max(p[column], 1e-3), p["acceptability"]) for p in plots
           if p[column] is not None and p["acceptability"] is not None]
    pts.sort(key=lambda t: t[0])
    fit = _pava_decreasing([a for _, a in pts])
    return [v for v, _ in pts], [1.0 / (1.0 + math.exp(-f)) for f in fit]


def _crossing_by_segments(v: list[float], p: list[float]) -> float | str:
    """Where the straight segments through (v, p) cross ½ — or where the curve lies."""
    if all(x > 0.5 for x in p):
        return "above the observed range"
    if all(x < 0.5 for x in p):
        return "below the observed range"
    flat = [v[i] for i, x in enumerate(p) if x == 0.5]
    if flat:
        return (flat[0] + flat[-1]) / 2
    for i in range(len(v) - 1):
        if p[i] > 0.5 > p[i + 1]:
            return v[i] + (v[i + 1] - v[i]) * (p[i] - 0.5) / (p[i] - p[i + 1])
    raise AssertionError("a falling curve with points on both sides must cross")


SIZES = [  # reviewers, plots, seed, response: small and large, one panelist to twenty
    (1, 24, 3, "log"), (2, 16, 5, "linear"), (3, 12, 1, "log"), (5, 40, 2, "step"), (20, 120, 12, "log"),
    (8, 60, 4, "linear"),
]


@pytest.mark.parametrize("reviewers,plots,seed,response", SIZES)
def test_reported_value_is_the_crossing_of_the_drawn_curve(reviewers, plots, seed, response):
    w = simulate_workshop(reviewers, plots, seed=seed, deviation_at_50=0.9, response=response,
                          repeat_share=0.0)
    res = analyse(w.answers, w.plots, n_boot=0, threshold_boot=200, seed=seed)
    th = res.to_dict()["threshold"]
    json.dumps(th, allow_nan=False)
    for column, key, ci_key in (("deviation", "deviation_at_50", "ci"), ("sg_c", "sg_c_at_50", "sg_c_ci")):
        v, p = _drawn_curve(res.plots, column)
        curve = th[f"{column}_curve"]
        assert curve["value"] == pytest.approx(v, rel=1e-12)
        assert curve["yes"] == pytest.approx(p, abs=1e-9)          # the chart draws exactly these
        expected = _crossing_by_segments(v, p)
        n = th[f"{column}_n"]
        with_value = [q for q in res.plots if q[column] is not None and q["acceptability"] is not None]
        assert n == {"answers": sum(q["answers"] for q in with_value), "reviewers": reviewers,
                     "plots": len(with_value)}
        assert n["answers"] >= MIN_ANSWERS and n["plots"] >= MIN_PLOTS
        if isinstance(expected, str):
            assert th[key] is None and th[f"{key}_status"] == expected
            continue
        assert th[f"{key}_status"] == "estimated"
        assert th[key] == pytest.approx(expected, rel=1e-12)
        assert v[0] <= th[key] <= v[-1]            # inside the observed range, never extrapolated
        ci = th[ci_key]
        assert (ci is None) == (th[f"{ci_key}_status"] is not None)
        if ci is not None:
            assert ci[0] <= ci[1] and v[0] <= ci[0] and ci[1] <= v[-1]


def test_one_panelist_twelve_answers_crossing_and_too_few():
    """The reported case: one panelist, 12 answers. The computation behind the figure still
    equals the drawn curve's crossing, but 12 answers are below the floor, so the JSON says
    "too few answers to estimate" with its n instead of a number; strictness of a lone
    reviewer is not estimable."""
    w = simulate_workshop(1, 12, seed=3, deviation_at_50=0.9, repeat_share=0.0)
    res = analyse(w.answers, w.plots, n_boot=0, threshold_boot=100)
    v, p = _drawn_curve(res.plots, "deviation")
    mono = monotone_threshold([q["deviation"] for q in res.plots], [q["acceptability"] for q in res.plots],
                              n_boot=0)
    assert mono.at_50 == pytest.approx(_crossing_by_segments(v, p), rel=1e-12)
    assert 0.75 < mono.at_50 < 0.80          # the curve falls from 0.86 to 0.08 between 0.75 and 0.80
    d = res.to_dict()
    th = d["threshold"]
    assert th["deviation_at_50"] is None and th["ci"] is None
    assert th["deviation_at_50_status"] == TOO_FEW and th["sg_c_at_50_status"] == TOO_FEW
    assert th["deviation_n"] == {"answers": 12, "reviewers": 1, "plots": 12}
    assert (th["min_answers"], th["min_plots"]) == (MIN_ANSWERS, MIN_PLOTS)
    (rv,) = d["reviewers"]
    assert rv["strictness"] is None and rv["strictness_ci"] is None
    assert "cannot be estimated with one reviewer" in rv["strictness_note"]
    # Table 1: every share with the answers it rests on
    for row in d["table1"]:
        assert row["answers"] == row["plots"] == 2
        assert row["min_yes"] == row["min_yes_count"] / row["min_yes_answers"]


def test_plateau_up_to_the_last_yes_value_is_not_averaged_away():
    """The shape of the report in issue 39: P(Yes) 0.77 at every deviation up to 0.9, then
    the answers turn to No. The 50 % point lies between 0.9 and the next deviation — not
    inside the plateau, where block centres in log v put it (0.28 before)."""
    v = np.array([0.06, 0.1, 0.15, 0.2, 0.3, 0.45, 0.6, 0.75, 0.9, 0.95, 1.3, 1.6])
    a = np.r_[np.full(9, math.log(0.77 / 0.23)), np.full(3, -2.5)]
    m = monotone_threshold(v, a, n_boot=0)
    p_lo, p_hi = 0.77, 1 / (1 + math.exp(2.5))
    assert m.at_50 == pytest.approx(0.9 + 0.05 * (p_lo - 0.5) / (p_lo - p_hi), rel=1e-9)
    assert 0.9 < m.at_50 < 0.95 and m.status == "estimated"


def test_curve_above_or_below_the_range_is_said_not_extrapolated():
    """24 plots all answered Yes by two reviewers: the curve never reaches 50 %; the value is
    None and its status says where it lies. All No: below the observed range."""
    import pandas as pd

    plots = pd.DataFrame({"plot": [f"p{i}" for i in range(24)], "kind": ["Y"] * 24,
                          "deviation": np.linspace(0.1, 2.0, 24), "sg_c": np.linspace(0.02, 0.5, 24)})
    for answer, where in ((True, "above the observed range"), (False, "below the observed range")):
        answers = pd.DataFrame({"reviewer": [r for r in ("A", "B") for _ in range(24)],
                                "plot": [f"p{i}" for _ in range(2) for i in range(24)],
                                "answer": [answer] * 48, "repeat": [False] * 48,
                                "scaling": ["fixed"] * 48, "seconds": [2.0] * 48})
        th = analyse(answers, plots, n_boot=0, threshold_boot=50).to_dict()["threshold"]
        assert th["deviation_at_50"] is None and th["deviation_at_50_status"] == where
        assert th["ci"] is None and th["ci_status"] == where
        assert th["deviation_n"] == {"answers": 48, "reviewers": 2, "plots": 24}


def test_curve_flat_at_one_half_names_no_point():
    """A typical reviewer at exactly 50 % at every value: no 50 % point, not the midpoint of
    the range; flat only on part of the range: the midpoint of that part."""
    from railval.core.review.threshold import FLAT, curve_crossing

    v = np.array([0.2, 0.5, 1.0, 2.0])
    flat = monotone_threshold(v, np.zeros(4), n_boot=30)
    assert flat.at_50 is None and flat.status == FLAT
    assert curve_crossing(v, [0.9, 0.5, 0.5, 0.1]) == (0.75, "estimated")
