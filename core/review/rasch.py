"""Reviewer strictness and plot acceptability: a Rasch-type logistic model (docs/workshops.md).

The model (Rasch 1960, "Probabilistic models for some intelligence and attainment tests",
Danish Institute for Educational Research — person ability and item difficulty; here the
plot plays the person and the reviewer the item):

    logit P(reviewer r answers Yes on plot p) = acceptability_p − strictness_r

fitted by joint maximum likelihood with a small ridge penalty ``λ/2 (Σ a_p² + Σ s_r²)``
(a Gaussian prior of standard deviation ``1/√λ``, which keeps plots or reviewers with only
Yes or only No answers finite), by Newton's method on the exact gradient and Hessian (solved through the Schur complement
of the diagonal plot block). The
likelihood only identifies differences ``a_p − s_r``; the reported scale is centred so that
the mean strictness of the reviewers is 0 ("a typical reviewer"), and a reviewer with
strictness +1 needs a plot one logit more acceptable than a typical reviewer does to say Yes
equally often. Intervals are Wald intervals ``± z·se`` from the inverse of the penalised
observed information, transformed to the centred scale (Agresti 2013, Categorical Data
Analysis, 3rd ed., on the Rasch model as a logistic model with subject and item effects).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.special
import scipy.stats

from railval.core.errors import InvalidParameter

__all__ = ["DEFAULT_RIDGE", "RaschFit", "fit_rasch"]

#: Ridge weight λ of the penalty λ/2·(Σa² + Σs²): prior standard deviation 1/√λ ≈ 4.5 logits,
#: weak against the information of a reviewer with tens of answers (docs/workshops.md).
DEFAULT_RIDGE = 0.05


@dataclass(frozen=True)
class RaschFit:
    """Result of :func:`fit_rasch`, on the centred scale (mean strictness 0).

    ``strictness``/``strictness_se``: per reviewer index; ``acceptability``/``acceptability_se``:
    per plot index; ``iterations``: Newton steps taken; ``converged``: the gradient norm fell
    below the tolerance."""

    strictness: np.ndarray
    strictness_se: np.ndarray
    acceptability: np.ndarray
    acceptability_se: np.ndarray
    iterations: int
    converged: bool

    def strictness_ci(self, confidence: float = 0.95) -> tuple[np.ndarray, np.ndarray]:
        """Wald interval ``strictness ± z·se`` per reviewer."""
        z = scipy.stats.norm.ppf(1.0 - (1.0 - confidence) / 2.0)
        return self.strictness - z * self.strictness_se, self.strictness + z * self.strictness_se

    def acceptability_ci(self, confidence: float = 0.95) -> tuple[np.ndarray, np.ndarray]:
        """Wald interval ``acceptability ± z·se`` per plot."""
        z = scipy.stats.norm.ppf(1.0 - (1.0 - confidence) / 2.0)
        return (self.acceptability - z * self.acceptability_se,
                self.acceptability + z * self.acceptability_se)


def fit_rasch(reviewer, plot, answer, *, n_reviewers: int | None = None, n_plots: int | None = None,
              ridge: float = DEFAULT_RIDGE, tol: float = 1e-8, max_iter: int = 100) -> RaschFit:
    """Fit ``logit P(yes) = acceptability[plot] − strictness[reviewer]`` (module docstring).

    Newton's method on the penalised log-likelihood, step-halving when the objective would
    rise; intervals from the inverse penalised information, centred on the mean strictness.

    Parameters
    ----------
    reviewer, plot : array_like of int
        Reviewer and plot indices (0 … n−1) of each answer, of equal length with ``answer``.
        Each (reviewer, plot) pair should occur once (first answers only).
    answer : array_like of bool or {0, 1}
        True/1 = Yes.
    n_reviewers, n_plots : int, optional
        Numbers of reviewers and plots (default: largest index + 1).
    ridge : float
        Ridge weight λ > 0 of the penalty λ/2·(Σa² + Σs²).
    tol : float
        Convergence: largest absolute gradient component below this.
    max_iter : int
        Newton steps at most.

    Returns
    -------
    RaschFit
        Strictness and acceptability with standard errors on the centred scale.

    Examples
    --------
    Three reviewers on three plots; the second says No once, the third twice:

    >>> fit = fit_rasch([0, 0, 0, 1, 1, 1, 2, 2, 2], [0, 1, 2, 0, 1, 2, 0, 1, 2],
    ...                 [1, 1, 1, 1, 1, 0, 1, 0, 0])
    >>> fit.converged, fit.strictness.round(2).tolist()
    (True, [-2.75, 0.17, 2.58])
    """
    model = _RaschModel.of(reviewer, plot, answer, n_reviewers, n_plots, ridge)
    theta, it, converged = model.newton(tol, max_iter)
    return model.centred(theta, it, converged)


@dataclass(frozen=True)
class _RaschModel:
    """The penalised likelihood of :func:`fit_rasch` on checked data: plot index ``p``,
    reviewer index ``r``, answers ``y`` (0/1), ``npl`` plots, ``nr`` reviewers, ridge λ;
    parameters ``θ = [acceptability (npl), strictness (nr)]``."""

    p: np.ndarray
    r: np.ndarray
    y: np.ndarray
    npl: int
    nr: int
    ridge: float

    @classmethod
    def of(cls, reviewer, plot, answer, n_reviewers: int | None, n_plots: int | None,
           ridge: float) -> _RaschModel:
        """The model of the given data; :class:`InvalidParameter` names what is wrong."""
        r = np.asarray(reviewer, dtype=np.int64)
        p = np.asarray(plot, dtype=np.int64)
        y = np.asarray(answer, dtype=float)
        if not (r.shape == p.shape == y.shape) or r.ndim != 1:
            raise InvalidParameter(f"fit_rasch: reviewer, plot and answer must be 1-D of equal length, "
                                   f"got {r.shape}, {p.shape}, {y.shape}")
        if not ridge > 0:
            raise InvalidParameter(f"fit_rasch: ridge must be > 0, got {ridge!r}")
        if np.any((y != 0) & (y != 1)):
            raise InvalidParameter("fit_rasch: answers must be 0/1 (No/Yes)")
        nr = int(r.max()) + 1 if n_reviewers is None else int(n_reviewers)
        npl = int(p.max()) + 1 if n_plots is None else int(n_plots)
        if r.size and (r.min() < 0 or r.max() >= nr or p.min() < 0 or p.max() >= npl):
            raise InvalidParameter("fit_rasch: reviewer/plot index out of range")
        return cls(p, r, y, npl, nr, float(ridge))

    def objective(self, th: np.ndarray) -> float:
        """Penalised negative log-likelihood."""
        eta = th[self.p] - th[self.npl + self.r]
        return float(np.sum(np.logaddexp(0.0, eta) - self.y * eta) + 0.5 * self.ridge * th @ th)

    def information(self, th: np.ndarray):
        """Penalised observed information in blocks: diagonal ``d_a`` (plots), diagonal
        ``d_s`` (reviewers) and the plots × reviewers block ``cross`` (= −w_pr)."""
        npl, nr = self.npl, self.nr
        pi = scipy.special.expit(th[self.p] - th[npl + self.r])
        wgt = pi * (1.0 - pi)
        d_a = np.bincount(self.p, wgt, npl) + self.ridge
        d_s = np.bincount(self.r, wgt, nr) + self.ridge
        cross = -np.bincount(self.p * nr + self.r, wgt, npl * nr).reshape(npl, nr)
        return pi, d_a, d_s, cross

    @staticmethod
    def schur(d_a, d_s, cross):
        """Cholesky factor of the Schur complement ``S = D_s − Cᵀ D_a⁻¹ C`` (reviewers ×
        reviewers) — the plot block is diagonal, so only an nr × nr system is solved."""
        m = cross / d_a[:, None]
        s_mat = np.diag(d_s) - np.einsum("pr,pq->rq", cross, m)
        return m, scipy.linalg.cho_factor(s_mat, lower=True)

    def newton(self, tol: float, max_iter: int) -> tuple[np.ndarray, int, bool]:
        """(θ, Newton steps taken, converged) from θ = 0, step-halving when the objective
        would rise."""
        npl, nr = self.npl, self.nr
        theta = np.zeros(npl + nr)
        f = self.objective(theta)
        it = 0
        for it in range(1, max_iter + 1):
            pi, d_a, d_s, cross = self.information(theta)
            resid = self.y - pi
            g_a = self.ridge * theta[:npl] - np.bincount(self.p, resid, npl)
            g_s = self.ridge * theta[npl:] + np.bincount(self.r, resid, nr)
            if max(np.max(np.abs(g_a), initial=0.0), np.max(np.abs(g_s), initial=0.0)) < tol:
                return theta, it, True
            m, chol = self.schur(d_a, d_s, cross)
            step_s = scipy.linalg.cho_solve(chol, g_s - m.T @ g_a)
            step_a = (g_a - cross @ step_s) / d_a
            step = np.concatenate([step_a, step_s])
            t = 1.0
            while True:
                cand = theta - t * step
                fc = self.objective(cand)
                if fc <= f + 1e-12 or t < 1e-8:
                    break
                t *= 0.5
            theta, f = cand, fc
        return theta, it, False

    def centred(self, theta: np.ndarray, it: int, converged: bool) -> RaschFit:
        """The fit on the centred scale. Covariance = inverse information, by blocks:
        ``Σ_ss = S⁻¹``, ``Σ_as = −M S⁻¹``, ``Σ_aa = D_a⁻¹ + M S⁻¹ Mᵀ`` (``M = D_a⁻¹ C``); then
        centred on the mean strictness: ``s_c = s − s̄``, ``a_c = a − s̄``."""
        npl, nr = self.npl, self.nr
        _, d_a, d_s, cross = self.information(theta)
        m, chol = self.schur(d_a, d_s, cross)
        s_inv = scipy.linalg.cho_solve(chol, np.eye(nr))
        m_sinv = np.einsum("pr,rq->pq", m, s_inv)
        var_a = 1.0 / d_a + np.einsum("pq,pq->p", m_sinv, m)
        cov_a_sbar = -m_sinv.mean(axis=1)
        var_sbar = float(s_inv.mean())
        var_s_c = np.diag(s_inv) - 2.0 * s_inv.mean(axis=1) + var_sbar
        var_a_c = var_a - 2.0 * cov_a_sbar + var_sbar
        s_bar = float(theta[npl:].mean())
        return RaschFit(
            strictness=theta[npl:] - s_bar, strictness_se=np.sqrt(np.clip(var_s_c, 0.0, None)),
            acceptability=theta[:npl] - s_bar, acceptability_se=np.sqrt(np.clip(var_a_c, 0.0, None)),
            iterations=it, converged=converged,
        )
