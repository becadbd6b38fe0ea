"""The objective value at which a typical reviewer says Yes half of the time (docs/workshops.md).

Each plot carries an objective value ``v`` — its normalised deviation (largest |D_v| / std
limit of the EN 14363 quantities of that signal in that section, Polach & Böttcher 2014 §3.1,
limit 1.0) or its Sprague–Geers comprehensive error C. The answers are related to it by a
logistic regression on ``log v`` with each reviewer's strictness (from the Rasch model,
:mod:`railval.core.review.rasch`) as a fixed offset:

    logit P(reviewer r says Yes on plot p) = β0 + β1 · log v_p − strictness_r

so a typical reviewer (strictness 0, the mean) says Yes with probability ½ at
``v₅₀ = exp(−β0 / β1)`` (Agresti 2013, Categorical Data Analysis, 3rd ed., §5.1: the "median
effective level" −α/β of a logistic regression). The fit is maximum likelihood by Newton's
method. The answers on one plot are correlated (a plot has an acceptability of its own beyond
``v``), so the covariance of (β0, β1) is the cluster-robust sandwich with the plots as
clusters (Liang & Zeger 1986, Biometrika 73:13–22; with the small-sample factor
``G/(G−1) · (N−1)/(N−K)`` that statsmodels applies, G plots, N answers, K = 2), and the
interval of ``log v₅₀`` is the delta method on it (Agresti 2013 §16.1.1), exponentiated.
Strictness offsets are held at their estimates. ``v ≤ 0`` is clipped to :data:`MIN_VALUE`
before the log; answers on plots without a value (NaN) stay out.

``v₅₀`` exists only for a falling curve (β1 < 0); otherwise it is reported as ``None``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.special
import scipy.stats

from railval.core.errors import InvalidParameter

__all__ = ["MIN_VALUE", "ThresholdFit", "cluster_covariance", "fit_threshold", "yes_curve"]

#: Objective values are clipped to at least this before taking the log (a thousandth of the limit).
MIN_VALUE = 1e-3


@dataclass(frozen=True)
class ThresholdFit:
    """Result of :func:`fit_threshold`.

    ``at_50``: the value at which a typical reviewer says Yes with probability ½ (``None``
    if the fitted curve does not fall); ``ci``: its bootstrap interval ``(low, high)`` or
    ``None``; ``intercept``/``slope``: β0, β1 of the fit on ``log v``; ``plots``/``answers``:
    how many entered the fit."""

    at_50: float | None
    ci: tuple[float, float] | None
    intercept: float | None
    slope: float | None
    plots: int
    answers: int

    def to_dict(self) -> dict:
        return {
            "at_50": self.at_50, "ci": list(self.ci) if self.ci is not None else None,
            "intercept": self.intercept, "slope": self.slope, "plots": self.plots,
            "answers": self.answers,
        }


def yes_curve(values, intercept: float, slope: float, strictness: float = 0.0) -> np.ndarray:
    """P(Yes) of a reviewer of the given strictness (0 = typical) at objective ``values``:
    ``expit(β0 + β1 log v − strictness)`` — the fitted curve to draw beside the limit 1.0."""
    v = np.maximum(np.asarray(values, dtype=float), MIN_VALUE)
    return scipy.special.expit(intercept + slope * np.log(v) - strictness)


def _newton(x: np.ndarray, y: np.ndarray, off: np.ndarray, max_iter: int = 100,
            tol: float = 1e-10) -> tuple[np.ndarray, bool]:
    """Logistic fit ``logit π = b0 + b1 x − off`` by Newton–Raphson with step halving
    (Agresti 2013 §4.6.1); returns ``(coefficients, converged)``."""
    design = np.stack([np.ones_like(x), x], axis=1)

    def nll(b: np.ndarray) -> float:
        eta = design @ b - off
        return float(np.sum(np.logaddexp(0.0, eta) - y * eta))

    beta = np.array([float(np.mean(off)), 0.0])
    f = nll(beta)
    for _ in range(max_iter):
        pi = scipy.special.expit(design @ beta - off)
        grad = design.T @ (y - pi)
        hess = (design * (pi * (1.0 - pi))[:, None]).T @ design
        try:
            step = np.linalg.solve(hess, grad)
        except np.linalg.LinAlgError:
            return beta, False
        t = 1.0
        while True:
            cand = beta + t * step
            fc = nll(cand)
            if fc <= f + 1e-12 or t < 1e-10:
                break
            t *= 0.5
        beta, f = cand, fc
        if np.max(np.abs(t * step)) < tol:
            return beta, bool(np.all(np.isfinite(beta)))
    return beta, False


def cluster_covariance(x, y, offset, cluster, beta) -> np.ndarray:
    """Cluster-robust (sandwich) covariance of the logistic coefficients ``beta`` of
    ``logit π = b0 + b1 x − offset`` (Liang & Zeger 1986): ``H⁻¹ (Σ_g u_g u_gᵀ) H⁻¹ · c``
    with ``u_g`` the score summed over cluster ``g``, ``H`` the information and
    ``c = G/(G−1) · (N−1)/(N−K)``."""
    x, y, off = (np.asarray(v, dtype=float) for v in (x, y, offset))
    _, g = np.unique(np.asarray(cluster), return_inverse=True)
    n_g = int(g.max()) + 1
    design = np.stack([np.ones_like(x), x], axis=1)
    pi = scipy.special.expit(design @ beta - off)
    hess = (design * (pi * (1.0 - pi))[:, None]).T @ design
    resid = y - pi
    scores = np.stack([np.bincount(g, resid, n_g), np.bincount(g, resid * x, n_g)], axis=1)
    bread = np.linalg.inv(hess)
    n, k = y.size, 2
    factor = n_g / (n_g - 1.0) * (n - 1.0) / (n - k)
    return factor * bread @ (scores.T @ scores) @ bread


def fit_threshold(value, answer, offset, plot, *, confidence: float = 0.95) -> ThresholdFit:
    """Fit the curve of the module docstring and the 50 % value with its interval.

    ``value`` (objective value of the answer's plot), ``answer`` (True = Yes), ``offset``
    (the answering reviewer's strictness) and ``plot`` (the answer's plot id or index, the
    cluster) are per-answer arrays of equal length. Answers whose value or offset is NaN are
    dropped. Needs at least 3 plots, two distinct values and both answers."""
    v = np.asarray(value, dtype=float)
    y = np.asarray(answer, dtype=float)
    off = np.asarray(offset, dtype=float)
    pl = np.asarray(plot)
    if not (v.shape == y.shape == off.shape == pl.shape) or v.ndim != 1:
        raise InvalidParameter("fit_threshold: value, answer, offset and plot must be 1-D of equal length")
    keep = np.isfinite(v) & np.isfinite(off)
    v, y, off, pl = v[keep], y[keep], off[keep], pl[keep]
    n_plots = int(np.unique(pl).size)
    empty = ThresholdFit(None, None, None, None, n_plots, int(y.size))
    if n_plots < 3 or np.unique(v).size < 2 or y.min(initial=1) == y.max(initial=0):
        return empty
    x = np.log(np.maximum(v, MIN_VALUE))
    beta, ok = _newton(x, y, off)
    if not ok:
        return empty
    b0, b1 = float(beta[0]), float(beta[1])
    if not b1 < 0:
        return ThresholdFit(None, None, b0, b1, n_plots, int(y.size))
    log50 = -b0 / b1
    cov = cluster_covariance(x, y, off, pl, beta)
    grad = np.array([-1.0 / b1, b0 / (b1 * b1)])
    se = float(np.sqrt(max(grad @ cov @ grad, 0.0)))
    z = scipy.stats.norm.ppf(1.0 - (1.0 - confidence) / 2.0)
    ci = (float(np.exp(log50 - z * se)), float(np.exp(log50 + z * se)))
    return ThresholdFit(float(np.exp(log50)), ci, b0, b1, n_plots, int(y.size))
