"""The objective value at which a typical reviewer says Yes half of the time (docs/workshops.md).

Each plot carries an objective value ``v`` — its normalised deviation (largest |D_v| / std
limit of the EN 14363 quantities of that signal in that section, Polach & Böttcher 2014 §3.1,
limit 1.0) or its Sprague–Geers comprehensive error C. The answers are related to it by a
logistic regression on ``log v`` with each reviewer's strictness (from the Rasch model,
:mod:`railval.core.review.rasch`) as a fixed offset:

    logit P(reviewer r says Yes on plot p) = β0 + β1 · log v_p − strictness_r

so a typical reviewer (strictness 0, the mean) says Yes with probability ½ at
``v₅₀ = exp(−β0 / β1)`` (Agresti 2013, Categorical Data Analysis, 3rd ed., §5.1: the "median
effective level" −α/β of a logistic regression). The interval is a percentile bootstrap
over plots (Efron & Tibshirani 1993, An Introduction to the Bootstrap, ch. 13): plots are
resampled with replacement together with all their answers, which keeps the correlation of
the answers on one plot; strictness offsets are held at their estimates. ``v ≤ 0`` is
clipped to :data:`MIN_VALUE` before the log; plots without a value (NaN) stay out.

``v₅₀`` exists only for a falling curve (β1 < 0); otherwise it is reported as ``None``.
The interval is taken over the bootstrap replicates with a falling curve; if more than
``(1 − confidence)/2`` of the replicates have none, the interval is undetermined (``None``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.special

from railval.core.errors import InvalidParameter

__all__ = ["MIN_VALUE", "ThresholdFit", "fit_threshold", "yes_curve"]

#: Objective values are clipped to at least this before taking the log (a thousandth of the limit).
MIN_VALUE = 1e-3


@dataclass(frozen=True)
class ThresholdFit:
    """Result of :func:`fit_threshold`.

    ``at_50``: the value at which a typical reviewer says Yes with probability ½ (``None``
    if the fitted curve does not fall); ``ci``: its bootstrap interval ``(low, high)`` or
    ``None``; ``intercept``/``slope``: β0, β1 of the fit on ``log v``; ``plots``/``answers``:
    how many entered the fit; ``boot_valid``: bootstrap replicates with a falling curve."""

    at_50: float | None
    ci: tuple[float, float] | None
    intercept: float | None
    slope: float | None
    plots: int
    answers: int
    boot_valid: int

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


def _newton_batch(x: np.ndarray, y: np.ndarray, off: np.ndarray, w: np.ndarray,
                  start: np.ndarray, max_iter: int = 50, tol: float = 1e-10) -> tuple[np.ndarray, np.ndarray]:
    """Logistic fits ``logit π = b0 + b1 x − off`` for every weight row of ``w`` at once
    (Newton–Raphson, Agresti 2013 §4.6.1); returns ``(coefficients (B × 2), converged (B))``."""
    n_rep = w.shape[0]
    beta = np.tile(start, (n_rep, 1)).astype(float)
    done = np.zeros(n_rep, dtype=bool)
    for _ in range(max_iter):
        eta = beta[:, :1] + beta[:, 1:] * x[None, :] - off[None, :]
        pi = scipy.special.expit(eta)
        r = w * (y[None, :] - pi)
        v = w * pi * (1.0 - pi)
        g0, g1 = r.sum(axis=1), r @ x
        h00, h01, h11 = v.sum(axis=1), v @ x, v @ (x * x)
        det = h00 * h11 - h01 * h01
        with np.errstate(divide="ignore", invalid="ignore"):
            d0 = (h11 * g0 - h01 * g1) / det
            d1 = (h00 * g1 - h01 * g0) / det
        step = np.stack([d0, d1], axis=1)
        step[~np.isfinite(step)] = 0.0
        step = np.clip(step, -5.0, 5.0)
        beta = beta + np.where(done[:, None], 0.0, step)
        done |= np.max(np.abs(step), axis=1) < tol
        if done.all():
            break
    return beta, done & np.all(np.isfinite(beta), axis=1)


def fit_threshold(value, answer, offset, plot, *, n_boot: int = 1000, confidence: float = 0.95,
                  rng: np.random.Generator | None = None) -> ThresholdFit:
    """Fit the curve of the module docstring and the 50 % value with its bootstrap interval.

    ``value`` (objective value of the answer's plot), ``answer`` (True = Yes), ``offset``
    (the answering reviewer's strictness) and ``plot`` (integer plot index 0 … P−1) are
    per-answer arrays of equal length. Answers whose value is NaN are dropped.
    ``n_boot = 0`` skips the interval."""
    v = np.asarray(value, dtype=float)
    y = np.asarray(answer, dtype=float)
    off = np.asarray(offset, dtype=float)
    pl = np.asarray(plot, dtype=np.int64)
    if not (v.shape == y.shape == off.shape == pl.shape) or v.ndim != 1:
        raise InvalidParameter("fit_threshold: value, answer, offset and plot must be 1-D of equal length")
    keep = np.isfinite(v) & np.isfinite(off)
    v, y, off, pl = v[keep], y[keep], off[keep], pl[keep]
    used_plots, pl = np.unique(pl, return_inverse=True)
    n_plots = used_plots.size
    empty = ThresholdFit(None, None, None, None, int(n_plots), int(y.size), 0)
    if n_plots < 3 or np.unique(v).size < 2 or y.min(initial=1) == y.max(initial=0):
        return empty
    x = np.log(np.maximum(v, MIN_VALUE))
    start = np.array([float(np.mean(off)), 0.0])
    beta, ok = _newton_batch(x, y, off, np.ones((1, y.size)), start)
    if not ok[0]:
        return empty
    b0, b1 = float(beta[0, 0]), float(beta[0, 1])
    at_50 = float(np.exp(-b0 / b1)) if b1 < 0 else None
    ci = None
    valid = 0
    if n_boot > 0 and at_50 is not None:
        rng = np.random.default_rng(0) if rng is None else rng
        draws = rng.integers(0, n_plots, size=(n_boot, n_plots))
        w_plot = np.zeros((n_boot, n_plots))
        np.add.at(w_plot, (np.repeat(np.arange(n_boot), n_plots), draws.ravel()), 1.0)
        bb, okb = _newton_batch(x, y, off, w_plot[:, pl], beta[0])
        good = okb & (bb[:, 1] < 0)
        valid = int(good.sum())
        alpha = (1.0 - confidence) / 2.0
        if n_boot - valid <= alpha * n_boot:
            log50 = -bb[good, 0] / bb[good, 1]
            lo, hi = np.quantile(log50, [alpha, 1.0 - alpha])
            ci = (float(np.exp(lo)), float(np.exp(hi)))
    return ThresholdFit(at_50, ci, b0, b1, int(n_plots), int(y.size), valid)
