"""The objective value at which a typical reviewer says Yes half of the time (docs/workshops.md).

Each plot carries an objective value ``v`` — its normalised deviation (largest |D_v| / std
limit of the EN 14363 quantities of that signal in that section, Polach & Böttcher 2014 §5,
limit 1.0) or its Sprague–Geers comprehensive error C. The answers are related to it by the
Rasch-type model of :mod:`railval.core.review.rasch` with the plot's acceptability replaced
by a linear function of ``log v`` — a linear logistic test model (Fischer 1973, "The linear
logistic test model as an instrument in educational research", Acta Psychologica 37:359–374):

    logit P(reviewer r says Yes on plot p) = β · log v_p − s_r

with one intercept ``s_r`` per reviewer (strictness at ``v = 1``). A typical reviewer is the
mean of the reviewers on this logit scale, ``s̄ = mean_r s_r`` (as in the Rasch model), and
says Yes with probability ½ at

    v₅₀ = exp(s̄ / β)

(the "median effective level" of a logistic regression, Agresti 2013, Categorical Data
Analysis, 3rd ed., §5.1). Reviewers enter as fixed effects, so the answers on different
plots are independent given the model except through the plot itself; the answers on one
plot are correlated (a plot is more or less acceptable than its ``v`` says), so the
covariance is the cluster-robust sandwich with the plots as clusters (Liang & Zeger 1986,
Biometrika 73:13–22; small-sample factor ``G/(G−1) · (N−1)/(N−K)`` as in statsmodels, G
plots, N answers, K parameters), and the interval of ``log v₅₀`` is the delta method on it
(Agresti 2013 §16.1), exponentiated. The fit is penalised maximum likelihood by Newton's
method with the ridge ``λ/2 Σ s_r²`` of the Rasch fit (keeps reviewers with only Yes or only
No finite; ``ridge = 0`` gives plain maximum likelihood). ``v ≤ 0`` is clipped to
:data:`MIN_VALUE` before the log; answers on plots without a value (NaN) stay out.

``v₅₀`` exists only for a falling curve (β < 0); otherwise it is reported as ``None``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.special
import scipy.stats

from railval.core.errors import InvalidParameter
from railval.core.review.rasch import DEFAULT_RIDGE

__all__ = ["MIN_VALUE", "ThresholdFit", "fit_threshold", "yes_curve"]

#: Objective values are clipped to at least this before taking the log (a thousandth of the limit).
MIN_VALUE = 1e-3


@dataclass(frozen=True)
class ThresholdFit:
    """Result of :func:`fit_threshold`.

    ``at_50``: the value at which a typical reviewer says Yes with probability ½ (``None``
    if the fitted curve does not fall); ``ci``: its interval ``(low, high)`` or ``None``;
    ``slope``: β (per unit of ``log v``); ``intercept``: ``−s̄``, so that a typical
    reviewer's curve is ``expit(intercept + slope · log v)``; ``strictness``: each reviewer's
    ``s_r − s̄`` (reviewer → value); ``plots``/``answers``: how many entered the fit."""

    at_50: float | None
    ci: tuple[float, float] | None
    intercept: float | None
    slope: float | None
    strictness: dict
    plots: int
    answers: int

    def to_dict(self) -> dict:
        return {
            "at_50": self.at_50, "ci": list(self.ci) if self.ci is not None else None,
            "intercept": self.intercept, "slope": self.slope, "plots": self.plots,
            "answers": self.answers,
        }


def yes_curve(values, intercept: float, slope: float, strictness: float = 0.0) -> np.ndarray:
    """P(Yes) at objective ``values`` of a reviewer ``strictness`` logits stricter than the
    typical one: ``expit(intercept + slope · log v − strictness)`` with ``intercept = −s̄``
    and ``slope = β`` of a :class:`ThresholdFit` — the fitted curve to draw beside the limit
    1.0."""
    v = np.maximum(np.asarray(values, dtype=float), MIN_VALUE)
    return scipy.special.expit(intercept + slope * np.log(v) - strictness)


def fit_threshold(value, answer, reviewer, plot, *, ridge: float = DEFAULT_RIDGE,
                  confidence: float = 0.95, tol: float = 1e-9, max_iter: int = 100) -> ThresholdFit:
    """Fit the model of the module docstring; ``v₅₀`` with its interval.

    ``value`` (objective value of the answer's plot), ``answer`` (True = Yes), ``reviewer``
    (who answered, any hashable id) and ``plot`` (the answer's plot, the cluster) are
    per-answer arrays of equal length; answers whose value is NaN are dropped. Needs at
    least 3 plots with two distinct values and both answers present."""
    v = np.asarray(value, dtype=float)
    y = np.asarray(answer, dtype=float)
    rv = np.asarray(reviewer)
    pl = np.asarray(plot)
    if not (v.shape == y.shape == rv.shape == pl.shape) or v.ndim != 1:
        raise InvalidParameter("fit_threshold: value, answer, reviewer and plot must be 1-D of equal length")
    if ridge < 0:
        raise InvalidParameter(f"fit_threshold: ridge must be ≥ 0, got {ridge!r}")
    keep = np.isfinite(v)
    v, y, rv, pl = v[keep], y[keep], rv[keep], pl[keep]
    names, ri = np.unique(rv, return_inverse=True)
    _, gi = np.unique(pl, return_inverse=True)
    n_r, n_g = names.size, int(gi.max()) + 1 if gi.size else 0
    empty = ThresholdFit(None, None, None, None, {}, n_g, int(y.size))
    if n_g < 3 or np.unique(v).size < 2 or y.min(initial=1) == y.max(initial=0):
        return empty
    x = np.log(np.maximum(v, MIN_VALUE))

    def nll(b: float, s: np.ndarray) -> float:
        eta = b * x - s[ri]
        return float(np.sum(np.logaddexp(0.0, eta) - y * eta) + 0.5 * ridge * s @ s)

    def blocks(b: float, s: np.ndarray):
        pi = scipy.special.expit(b * x - s[ri])
        w = pi * (1.0 - pi)
        return pi, float(w @ (x * x)), -np.bincount(ri, w * x, n_r), np.bincount(ri, w, n_r) + ridge

    share = np.clip(np.bincount(ri, y, n_r) / np.bincount(ri, None, n_r), 0.05, 0.95)
    b, s = 0.0, -scipy.special.logit(share)
    f = nll(b, s)
    converged = False
    for _ in range(max_iter):
        pi, h_bb, h_bs, d_s = blocks(b, s)
        g_b = -float((y - pi) @ x)
        g_s = np.bincount(ri, y - pi, n_r) + ridge * s
        schur = h_bb - float(h_bs @ (h_bs / d_s))
        if not schur > 0:
            return empty
        db = (g_b - float(h_bs @ (g_s / d_s))) / schur
        ds = (g_s - h_bs * db) / d_s
        t = 1.0
        while True:
            cb, cs = b - t * db, s - t * ds
            fc = nll(cb, cs)
            if fc <= f + 1e-12 or t < 1e-10:
                break
            t *= 0.5
        b, s, f = cb, cs, fc
        if max(abs(t * db), float(np.max(np.abs(t * ds)))) < tol:
            converged = True
            break
    if not converged or not np.isfinite(b) or not np.all(np.isfinite(s)):
        return empty
    s_bar = float(s.mean())
    strict = {str(n): float(v_) for n, v_ in zip(names.tolist(), (s - s_bar).tolist(), strict=True)}
    if not b < 0:
        return ThresholdFit(None, None, -s_bar, b, strict, n_g, int(y.size))
    # cluster-robust covariance of (β, s_1 … s_R): c · H⁻¹ (Σ_g u_g u_gᵀ) H⁻¹
    pi, h_bb, h_bs, d_s = blocks(b, s)
    hess = np.diag(np.concatenate([[h_bb], d_s]))
    hess[0, 1:] = hess[1:, 0] = h_bs
    resid = y - pi
    scores = np.empty((n_g, n_r + 1))
    scores[:, 0] = -np.bincount(gi, resid * x, n_g)
    scores[:, 1:] = np.bincount(gi * n_r + ri, resid, n_g * n_r).reshape(n_g, n_r)
    bread = np.linalg.inv(hess)
    k = n_r + 1
    factor = n_g / (n_g - 1.0) * (y.size - 1.0) / (y.size - k)
    cov = factor * bread @ (scores.T @ scores) @ bread
    log50 = s_bar / b
    grad = np.concatenate([[-s_bar / (b * b)], np.full(n_r, 1.0 / (n_r * b))])
    se = float(np.sqrt(max(grad @ cov @ grad, 0.0)))
    z = scipy.stats.norm.ppf(1.0 - (1.0 - confidence) / 2.0)
    ci = (float(np.exp(log50 - z * se)), float(np.exp(log50 + z * se)))
    return ThresholdFit(float(np.exp(log50)), ci, -s_bar, b, strict, n_g, int(y.size))
