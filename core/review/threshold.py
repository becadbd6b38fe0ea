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

**The link is not known.** A real panel's response curve is unknown: reviewers may answer on
the deviation itself (logit linear in ``v``) rather than on its log, and fitting the wrong
one biases ``v₅₀`` (measured: 9–16 % low with an interval excluding the truth, for reviewers
linear in ``v``). The reported ``v₅₀`` is therefore model-free in the link
(:func:`monotone_threshold`): each plot's reviewer-adjusted acceptability ``a_p`` (the Rasch
fit of :mod:`.rasch`, on the scale where a typical reviewer says Yes with probability ½ at
``a_p = 0``) is regressed on ``v`` under the only assumption that it does not rise with
``v`` — isotonic regression by pooled adjacent violators (Ayer, Brunk, Ewing, Reid &
Silverman 1955, Ann. Math. Stat. 26:641–647; Barlow, Bartholomew, Bremner & Brunk 1972,
Statistical Inference under Order Restrictions). A typical reviewer's P(Yes) at each
observed value is ``expit`` of that monotone fit — the curve the analysis page draws, a
straight line between adjacent points — and ``v₅₀`` is where that line crosses ½, linearly
interpolated in ``v`` between the adjacent observed values (the isotonic estimate of a
target quantile of Stylianou & Flournoy 2002, Biometrics 58:171–177): one computation for
the number and the chart (:func:`curve_crossing`). A curve that stays above (below) ½ over
the observed values has no ``v₅₀``: it lies above (below) the observed range, and nothing
is extrapolated. Its interval is a percentile bootstrap over plots, the clusters of the
answers (Davison & Hinkley 1997, Bootstrap Methods and their Application, §3.8), each
replicate estimated the same way. The reviewers stay fixed effects: the estimand is this
panel's typical reviewer.

The link sensitivity (:func:`link_sensitivity`) fits the parametric model above with
``log v`` replaced by the Box–Cox power ``x_λ(v) = (v^λ − 1)/λ`` (``log v`` at λ = 0) for
λ = 0, ½, 1 — the transformation of the independent variable of Box & Tidwell 1962
(Technometrics 4:531–550) on a grid, compared by likelihood (same number of parameters, so
also by AIC) — and reports each link's ``v₅₀`` and their spread relative to the reported
value; the curve drawn for a typical reviewer is the link with the largest likelihood.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.optimize
import scipy.special
import scipy.stats

from railval.core.errors import InvalidParameter
from railval.core.review.rasch import DEFAULT_RIDGE

__all__ = ["ABOVE_RANGE", "BELOW_RANGE", "ESTIMATED", "FLAT", "LINKS", "MIN_VALUE", "MonotoneThreshold", "TOO_FEW",
           "ThresholdFit", "curve_crossing", "fit_threshold", "link_name", "link_sensitivity",
           "monotone_threshold", "transform", "yes_curve"]

#: Objective values are clipped to at least this before taking the log (a thousandth of the limit).
MIN_VALUE = 1e-3

#: Box–Cox powers λ of the links compared by :func:`link_sensitivity` (0 = log v, 1 = v).
LINKS = (0.0, 0.5, 1.0)

#: Bootstrap replicates of :func:`monotone_threshold` by default.
DEFAULT_BOOT = 1000

#: ``status`` of a 50 % point with too few answers, plots or values to draw a curve
#: (docs/workshops.md "Too few answers").
TOO_FEW = "too few answers to estimate"

_LINK_NAMES = {0.0: "log", 0.5: "sqrt", 1.0: "linear"}


def link_name(power: float) -> str:
    """``"log"``, ``"sqrt"``, ``"linear"`` or ``"power λ"`` for the Box–Cox power ``λ``.

    Parameters
    ----------
    power : float
        Box–Cox λ.

    Returns
    -------
    str
        The link's name.

    Examples
    --------
    >>> link_name(0.0), link_name(0.5), link_name(1.0)
    ('log', 'sqrt', 'linear')
    """
    return _LINK_NAMES.get(float(power), f"power {power:g}")


def transform(values, power: float = 0.0) -> np.ndarray:
    """Box–Cox transform ``x_λ(v) = (v^λ − 1)/λ`` (``log v`` at λ = 0) of ``v`` clipped to
    :data:`MIN_VALUE` (Box & Cox 1964).

    Parameters
    ----------
    values : array_like
        Objective values.
    power : float
        Box–Cox λ.

    Returns
    -------
    ndarray
        The transformed values.
    """
    v = np.maximum(np.asarray(values, dtype=float), MIN_VALUE)
    return np.log(v) if power == 0 else (v ** power - 1.0) / power


def _inverse(x: float, power: float) -> float | None:
    """``v`` with ``x_λ(v) = x``; ``None`` if no positive ``v`` has it."""
    if power == 0:
        return float(np.exp(x)) if np.isfinite(np.exp(x)) else None
    base = 1.0 + power * x
    return float(base ** (1.0 / power)) if base > 0 else None


@dataclass(frozen=True)
class ThresholdFit:
    """Result of :func:`fit_threshold`.

    ``at_50``: the value at which a typical reviewer says Yes with probability ½ (``None``
    if the fitted curve does not fall); ``ci``: its interval ``(low, high)`` or ``None``;
    ``slope``: β (per unit of ``x_λ(v)``, ``log v`` by default); ``intercept``: ``−s̄``, so
    that a typical reviewer's curve is ``expit(intercept + slope · x_λ(v))``; ``strictness``:
    each reviewer's ``s_r − s̄`` (reviewer → value); ``plots``/``answers``: how many entered
    the fit; ``power``: the link's λ; ``loglik``: the log-likelihood of the answers at the fit
    (without the ridge term; ``None`` without a fit)."""

    at_50: float | None
    ci: tuple[float, float] | None
    intercept: float | None
    slope: float | None
    strictness: dict
    plots: int
    answers: int
    power: float = 0.0
    loglik: float | None = None

    def to_dict(self) -> dict:
        return {
            "at_50": self.at_50, "ci": list(self.ci) if self.ci is not None else None,
            "intercept": self.intercept, "slope": self.slope, "plots": self.plots,
            "answers": self.answers, "link": link_name(self.power), "power": self.power,
            "loglik": self.loglik,
        }


def yes_curve(values, intercept: float, slope: float, strictness: float = 0.0,
              power: float = 0.0) -> np.ndarray:
    """P(Yes) at objective ``values`` of a reviewer ``strictness`` logits stricter than the
    typical one: ``expit(intercept + slope · x_λ(v) − strictness)`` with ``intercept = −s̄``,
    ``slope = β`` and ``power = λ`` of a :class:`ThresholdFit` — the fitted curve to draw
    beside the limit 1.0.

    Parameters
    ----------
    values : array_like
        Objective values.
    intercept, slope : float
        Of a :class:`ThresholdFit`.
    strictness : float
        The reviewer's strictness relative to the typical one (logits).
    power : float
        Box–Cox λ of the link.

    Returns
    -------
    ndarray
        P(Yes) at ``values``.
    """
    return scipy.special.expit(intercept + slope * transform(values, power) - strictness)


def _prepare(value, answer, reviewer, plot, ridge):
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
    n_g = int(gi.max()) + 1 if gi.size else 0
    usable = n_g >= 3 and np.unique(v).size >= 2 and y.min(initial=1) != y.max(initial=0)
    return v, y, names, ri, gi, n_g, usable


def _newton(x, y, ri, n_r, wt, ridge, start, tol, max_iter):
    """Penalised (weighted) maximum likelihood of ``logit P = b·x − s[ri]`` by Newton's
    method through the Schur complement of the diagonal reviewer block, with step halving.
    Returns ``(b, s, converged)``."""

    def nll(b: float, s: np.ndarray) -> float:
        eta = b * x - s[ri]
        return float(wt @ (np.logaddexp(0.0, eta) - y * eta) + 0.5 * ridge * s @ s)

    if start is None:
        share = np.clip(np.bincount(ri, wt * y, n_r) / np.maximum(np.bincount(ri, wt, n_r), 1e-12), 0.05, 0.95)
        b, s = 0.0, -scipy.special.logit(share)
    else:
        b, s = start[0], start[1].copy()
    f = nll(b, s)
    for _ in range(max_iter):
        pi = scipy.special.expit(b * x - s[ri])
        w = wt * pi * (1.0 - pi)
        h_bb, h_bs, d_s = float(w @ (x * x)), -np.bincount(ri, w * x, n_r), np.bincount(ri, w, n_r) + ridge
        r = wt * (y - pi)
        g_b = -float(r @ x)
        g_s = np.bincount(ri, r, n_r) + ridge * s
        schur = h_bb - float(h_bs @ (h_bs / d_s))
        if not schur > 0 or not np.all(d_s > 0):
            return b, s, False
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
            return b, s, bool(np.isfinite(b) and np.all(np.isfinite(s)))
    return b, s, False


def _loglik(x, y, ri, b, s, wt=None) -> float:
    eta = b * x - s[ri]
    ll = y * eta - np.logaddexp(0.0, eta)
    return float(ll.sum() if wt is None else wt @ ll)


def fit_threshold(value, answer, reviewer, plot, *, ridge: float = DEFAULT_RIDGE,
                  confidence: float = 0.95, tol: float = 1e-9, max_iter: int = 100,
                  power: float = 0.0) -> ThresholdFit:
    """Fit the model of the module docstring for one link; ``v₅₀`` with its interval.

    ``value`` (objective value of the answer's plot), ``answer`` (True = Yes), ``reviewer``
    (who answered, any hashable id) and ``plot`` (the answer's plot, the cluster) are
    per-answer arrays of equal length; answers whose value is NaN are dropped. Needs at
    least 3 plots with two distinct values and both answers present. ``power``: the
    Box–Cox λ of the link (0 = ``log v``, the default; 1 = ``v``).

    Parameters
    ----------
    value, answer, reviewer, plot : array_like
        Per-answer objective value, answer (True = Yes), reviewer id and plot id.
    ridge : float
        Ridge weight on the reviewer strictness.
    confidence : float
        Coverage of the interval of ``v₅₀``.
    tol, max_iter
        Newton convergence tolerance and step limit.
    power : float
        Box–Cox λ of the link.

    Returns
    -------
    ThresholdFit
        The fit, its ``v₅₀`` and interval.
    """
    v, y, names, ri, gi, n_g, usable = _prepare(value, answer, reviewer, plot, ridge)
    n_r = names.size
    empty = ThresholdFit(None, None, None, None, {}, n_g, int(y.size), float(power))
    if not usable:
        return empty
    x = transform(v, power)
    b, s, converged = _newton(x, y, ri, n_r, np.ones_like(y), ridge, None, tol, max_iter)
    if not converged:
        return empty
    s_bar = float(s.mean())
    loglik = _loglik(x, y, ri, b, s)
    strict = {str(n): float(v_) for n, v_ in zip(names.tolist(), (s - s_bar).tolist(), strict=True)}
    if not b < 0:
        return ThresholdFit(None, None, -s_bar, b, strict, n_g, int(y.size), float(power), loglik)
    # cluster-robust covariance of (β, s_1 … s_R): c · H⁻¹ (Σ_g u_g u_gᵀ) H⁻¹
    pi = scipy.special.expit(b * x - s[ri])
    w = pi * (1.0 - pi)
    hess = np.diag(np.concatenate([[float(w @ (x * x))], np.bincount(ri, w, n_r) + ridge]))
    hess[0, 1:] = hess[1:, 0] = -np.bincount(ri, w * x, n_r)
    resid = y - pi
    scores = np.empty((n_g, n_r + 1))
    scores[:, 0] = -np.bincount(gi, resid * x, n_g)
    scores[:, 1:] = np.bincount(gi * n_r + ri, resid, n_g * n_r).reshape(n_g, n_r)
    bread = np.linalg.inv(hess)
    k = n_r + 1
    factor = n_g / (n_g - 1.0) * (y.size - 1.0) / (y.size - k)
    cov = factor * bread @ (scores.T @ scores) @ bread
    x50 = s_bar / b
    grad = np.concatenate([[-s_bar / (b * b)], np.full(n_r, 1.0 / (n_r * b))])
    se = float(np.sqrt(max(grad @ cov @ grad, 0.0)))
    z = scipy.stats.norm.ppf(1.0 - (1.0 - confidence) / 2.0)
    at50 = _inverse(x50, power)
    lo, hi = _inverse(x50 - z * se, power), _inverse(x50 + z * se, power)
    ci = (lo if lo is not None else 0.0, hi) if hi is not None else None
    return ThresholdFit(at50, ci, -s_bar, b, strict, n_g, int(y.size), float(power), loglik)


#: ``status`` of a 50 % point: the curve crosses ½ inside the observed values (a number).
ESTIMATED = "estimated"
#: ``status``: the curve stays above ½ at every observed value (the 50 % point lies beyond the
#: largest value; no number is extrapolated).
ABOVE_RANGE = "above the observed range"
#: ``status``: the curve is below ½ already at the smallest observed value.
BELOW_RANGE = "below the observed range"
#: ``status``: the curve is exactly ½ at every observed value (no point to name).
FLAT = "flat at 50 % over the observed range"


@dataclass(frozen=True)
class MonotoneThreshold:
    """Result of :func:`monotone_threshold`.

    ``at_50``: where the drawn curve (``curve_value``, ``curve_yes``) crosses ½ (``None``
    unless ``status`` is :data:`ESTIMATED`); ``status``: :data:`ESTIMATED`,
    :data:`ABOVE_RANGE`, :data:`BELOW_RANGE` (or ``"too few answers to estimate"`` set by the
    caller); ``ci``: the percentile interval (``None`` without one, see ``ci_status``);
    ``ci_status``: ``None`` or :data:`ABOVE_RANGE` / :data:`BELOW_RANGE` when the interval
    reaches beyond the observed values (more than the tail share of the replicates never
    cross inside their range); ``plots``: the plots used; ``boot_valid``: replicates that
    crossed inside the observed range, out of ``n_boot``."""

    at_50: float | None
    ci: tuple[float, float] | None
    plots: int
    boot_valid: int
    n_boot: int
    #: the monotone fit on the full data: values sorted, P(Yes) of a typical reviewer there,
    #: ``expit(fitted a_p)``; the curve drawn is the straight line through these points
    #: (empty without a fit)
    curve_value: tuple[float, ...] = ()
    curve_yes: tuple[float, ...] = ()
    status: str = ESTIMATED
    ci_status: str | None = None


def curve_crossing(value, yes) -> tuple[float | None, str]:
    """Where the polyline through the points ``(value[k], yes[k])`` — a non-increasing curve of
    P(Yes), in the order given — crosses ½: ``(v₅₀, ESTIMATED)``, or ``(None, ABOVE_RANGE)``
    if every point is above ½, ``(None, BELOW_RANGE)`` if every point is below.

    Between the last point above ½ (``k``) and the next one (below ½), linear interpolation in
    ``v``: ``v₅₀ = v_k + (v_{k+1} − v_k)(P_k − ½)/(P_k − P_{k+1})`` — the linearly
    interpolated isotonic estimate of a target quantile (Stylianou & Flournoy 2002,
    "Dose finding using the biased coin up-and-down design and isotonic regression",
    Biometrics 58:171–177). Points exactly at ½ form the segment where the curve equals ½;
    its midpoint is returned — unless every point is at ½: ``(None, FLAT)``. This is the
    crossing of the line a chart draws through the same points (straight segments in ``v``),
    so the reported value and the drawn curve agree.

    Parameters
    ----------
    value : array_like
        Objective values, sorted ascending (ties allowed).
    yes : array_like
        P(Yes) at each value, non-increasing.

    Returns
    -------
    tuple of (float or None, str)
        The 50 % value and its status.

    Examples
    --------
    >>> curve_crossing([0.5, 1.0, 2.0], [0.9, 0.7, 0.3])
    (1.5, 'estimated')
    >>> curve_crossing([0.5, 1.0], [0.9, 0.7])
    (None, 'above the observed range')
    """
    v = np.asarray(value, dtype=float)
    p = np.asarray(yes, dtype=float)
    if v.shape != p.shape or v.ndim != 1 or v.size == 0:
        raise InvalidParameter("curve_crossing: value and yes must be 1-D of equal, non-zero length")
    at = np.flatnonzero(p == 0.5)
    if at.size == v.size:
        return None, FLAT
    if at.size:
        return float(0.5 * (v[at[0]] + v[at[-1]])), ESTIMATED
    above = np.flatnonzero(p > 0.5)
    if not above.size:
        return None, BELOW_RANGE
    k = int(above.max())
    if k == v.size - 1:
        return None, ABOVE_RANGE
    return float(v[k] + (v[k + 1] - v[k]) * (p[k] - 0.5) / (p[k] - p[k + 1])), ESTIMATED


def _curve(v: np.ndarray, a: np.ndarray, w: np.ndarray | None) -> np.ndarray:
    """P(Yes) of a typical reviewer at the sorted values ``v``: ``expit`` of the falling
    isotonic regression (pooled adjacent violators) of the acceptabilities ``a``."""
    return scipy.special.expit(scipy.optimize.isotonic_regression(a, weights=w, increasing=False).x)


def _percentile_ci(draws: np.ndarray, confidence: float) -> tuple[tuple[float, float] | None, str | None]:
    """Percentile interval of the replicates ``draws`` (``±inf`` = beyond the observed range
    of that replicate; they keep their place in the order, so leaving them out cannot narrow
    the interval) — Efron & Tibshirani 1993, An Introduction to the Bootstrap, §13.3."""
    q = (1.0 - confidence) / 2.0
    lo, hi = np.quantile(draws, [q, 1.0 - q], method="inverted_cdf")
    if np.isposinf(hi):
        return None, ABOVE_RANGE
    if np.isneginf(lo):
        return None, BELOW_RANGE
    return (float(lo), float(hi)), None


def monotone_threshold(value, acceptability, *, n_boot: int = DEFAULT_BOOT,
                       seed: int | np.random.Generator = 0, confidence: float = 0.95) -> MonotoneThreshold:
    """``v₅₀`` without a link (module docstring, last part): per plot its objective
    ``value`` and its reviewer-adjusted ``acceptability`` (the Rasch fit's ``a_p``, on the
    scale where a typical reviewer says Yes with probability ½ at ``a_p = 0``). The falling
    isotonic regression of ``a_p`` on ``v`` (pooled adjacent violators) gives a typical
    reviewer's P(Yes) = expit(fit) at each value — the curve; ``v₅₀`` is where the straight
    line through those points crosses ½ (:func:`curve_crossing`), so the reported value is
    the crossing of the drawn curve. The interval resamples the plots (``n_boot`` replicates,
    the multiplicities as weights) and applies the same two steps to each replicate
    (percentile bootstrap over plots, the clusters of the answers: Davison & Hinkley 1997,
    Bootstrap Methods and their Application, §3.8); a replicate whose curve does not cross
    inside its values counts as beyond the range (see :class:`MonotoneThreshold`). Plots
    whose value or acceptability is not finite stay out; ``v ≤ 0`` is clipped to
    :data:`MIN_VALUE`.

    Parameters
    ----------
    value, acceptability : array_like
        Per plot its objective value and its Rasch acceptability.
    n_boot : int
        Bootstrap replicates (0 = no interval).
    seed : int or numpy.random.Generator
        Random seed or generator of the bootstrap.
    confidence : float
        Coverage of the interval.

    Returns
    -------
    MonotoneThreshold
        ``v₅₀`` (or where it lies), its interval and the fitted falling curve.
    """
    if int(n_boot) < 0:
        raise InvalidParameter(f"monotone_threshold: n_boot must be ≥ 0, got {n_boot!r}")
    v = np.asarray(value, dtype=float)
    a = np.asarray(acceptability, dtype=float)
    if v.shape != a.shape or v.ndim != 1:
        raise InvalidParameter("monotone_threshold: value and acceptability must be 1-D of equal length")
    keep = np.isfinite(v) & np.isfinite(a)
    v, a = np.maximum(v[keep], MIN_VALUE), a[keep]
    order = np.argsort(v, kind="stable")
    v, a = v[order], a[order]
    n = v.size
    if n < 3 or np.unique(v).size < 2:
        return MonotoneThreshold(None, None, n, 0, int(n_boot), status=TOO_FEW)
    yes = _curve(v, a, None)
    at50, status = curve_crossing(v, yes)
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    draws = np.empty(int(n_boot))
    for b in range(int(n_boot)):
        wt = np.bincount(rng.integers(0, n, n), minlength=n).astype(float)
        k = wt > 0
        c, where = curve_crossing(v[k], _curve(v[k], a[k], wt[k]))
        draws[b] = c if c is not None else {ABOVE_RANGE: np.inf, BELOW_RANGE: -np.inf}.get(where, np.nan)
    draws = draws[~np.isnan(draws)]                 # a flat replicate names no point, on no side
    ci, ci_status = _percentile_ci(draws, confidence) if draws.size else (None, None)
    return MonotoneThreshold(at50, ci, n, int(np.isfinite(draws).sum()), int(n_boot),
                             tuple(float(x) for x in v), tuple(float(x) for x in yes), status, ci_status)


def link_sensitivity(value, answer, reviewer, plot, *, powers=LINKS, reference: float | None = None,
                     ridge: float = DEFAULT_RIDGE, confidence: float = 0.95) -> tuple[ThresholdFit, dict]:
    """Fit :func:`fit_threshold` under every link of ``powers``; return the fit with the
    largest likelihood and ``{"chosen", "links": [{link, power, at_50, ci, loglik}],
    "relative_spread"}`` — the spread (largest − smallest ``v₅₀`` over the links) relative
    to ``reference`` (the reported ``v₅₀``; default the chosen link's), ``None`` if a link
    has no ``v₅₀``.

    Parameters
    ----------
    value, answer, reviewer, plot : array_like
        As in :func:`fit_threshold`.
    powers : sequence of float
        Box–Cox λ of the links compared.
    reference : float, optional
        The reported ``v₅₀`` the spread is relative to.
    ridge, confidence : float
        As in :func:`fit_threshold`.

    Returns
    -------
    tuple of (ThresholdFit, dict)
        The likeliest link's fit and the comparison of the links.
    """
    if not powers:
        raise InvalidParameter("link_sensitivity: powers must name at least one link")
    fits = [fit_threshold(value, answer, reviewer, plot, ridge=ridge, confidence=confidence,
                          power=float(p)) for p in powers]
    valid = [f for f in fits if f.loglik is not None]
    best = max(valid, key=lambda f: f.loglik) if valid else fits[0]
    ref = best.at_50 if reference is None else reference
    values = [f.at_50 for f in fits]
    spread = None
    if ref and all(x is not None for x in values):
        spread = (max(values) - min(values)) / ref
    return best, {
        "chosen": link_name(best.power) if valid else None,
        "links": [{"link": link_name(f.power), "power": f.power, "at_50": f.at_50,
                   "ci": list(f.ci) if f.ci else None, "loglik": f.loglik} for f in fits],
        "relative_spread": spread,
    }
