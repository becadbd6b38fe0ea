"""Synchronisation of a simulated signal to a measured one by bounded cross-correlation.

Seed 000 §4.2 (Figure 9) shows that large Sprague–Geers phase errors come mostly from the
synchronisation of simulation and measurement, not from the model; railval therefore
reports every metric both raw and after removing the lag estimated here.

Convention: a **positive lag τ** means the simulated signal is *delayed* with respect to the
measurement, ``c(t) ≈ m(t − τ)``. For every integer lag ``k`` with ``|k| ≤ K`` the Pearson
correlation coefficient of the overlapping parts (``m[0:n−k]`` with ``c[k:n]`` for ``k ≥ 0``)
is evaluated — the cross products come from one FFT correlation, the overlap means and
variances from prefix sums, so all ``2K + 1`` coefficients cost ``O(n log n)``. The lag of the
largest coefficient is chosen; **ties** — every lag whose coefficient lies within
``RHO_TIE_TOL`` (1e-9) of the largest — go to the smallest |lag| (and, between ±k, to −k), so
an in-phase periodic pair (whose whole-period lags all correlate to 1 up to rounding noise of
~1e-16) keeps lag 0 instead of a rounding-dependent multiple of the period
(:func:`best_lag_index`). ``K = round(max_lag_s · fs)`` is capped at ``n // 2`` so the
synchronised overlap always keeps at least half of the samples. Lags whose overlap has no
variance in either signal score 0. Optional sub-sample refinement fits a parabola through
the peak and its two neighbours (the standard three-point peak interpolation) and shifts
the simulated signal by linear interpolation (which slightly attenuates content near the
Nyquist frequency).

Using the normalised coefficient per overlap (rather than the raw cross-product sum) avoids
the bias of the raw sum towards small lags on short overlaps (Bendat & Piersol 2010, §8.4).

References
----------
Bendat, J. S. & Piersol, A. G. (2010) Random Data: Analysis and Measurement Procedures, 4th
ed., Wiley, ch. 5 and 8 (cross-correlation, time-delay estimation).
Polach & Böttcher 2014 §4.2: influence of synchronisation on the phase error.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from railval.core import lazy
from railval.core.errors import InvalidParameter
from railval.core.metrics._checks import as_pair, positive

#: imported when first used (railval.core.lazy): a command that never reaches it does not load it
scipy_signal = lazy.module("scipy.signal")

DEFAULT_MAX_LAG_S = 2.0
#: correlation coefficients closer than this to the largest one count as ties (dimensionless)
RHO_TIE_TOL = 1e-9
#: a lag within this share of the search bound K is flagged as unreliable (``near_bound``)
NEAR_BOUND_SHARE = 0.05


@dataclass(frozen=True)
class SyncResult:
    """Estimated lag of simulated behind measured.

    ``lag_samples`` (float if refined), ``lag_s`` = lag_samples / fs in s, ``correlation``:
    Pearson coefficient at the chosen integer lag, ``max_lag_samples``: searched bound ``K``,
    ``at_bound``: the best lag lies on ±K (the true lag may be outside the window),
    ``refined``: sub-sample refinement applied.

    ``near_bound`` (property): |lag| ≥ (1 − NEAR_BOUND_SHARE)·K, i.e. within 5 % of the search
    bound; ``reliable`` (property) is its negation — a lag at or near the bound may be
    limited by the window rather than found inside it.
    """

    lag_samples: float
    lag_s: float
    correlation: float
    max_lag_samples: int
    at_bound: bool
    refined: bool

    @property
    def near_bound(self) -> bool:
        k = self.max_lag_samples
        return bool(k > 0 and abs(self.lag_samples) >= (1.0 - NEAR_BOUND_SHARE) * k)

    @property
    def reliable(self) -> bool:
        return not self.near_bound

    def to_dict(self) -> dict[str, float | int | bool]:
        return {**asdict(self), "near_bound": self.near_bound, "reliable": self.reliable}


def best_lag_index(lags: np.ndarray, rho: np.ndarray, tol: float = RHO_TIE_TOL) -> int:
    """Index of the chosen lag: among the lags whose coefficient is within ``tol`` of the
    largest, the smallest |lag| (−k before +k). With ``tol = 0`` this is the first maximum
    counted outwards from lag 0.

    Parameters
    ----------
    lags : numpy.ndarray
        Lags in samples, shape (K,).
    rho : numpy.ndarray
        Correlation coefficient per lag, shape (K,).
    tol : float
        Tie tolerance on the coefficient.

    Returns
    -------
    int
        Index into ``lags``.

    Examples
    --------
    >>> best_lag_index(np.array([-1, 0, 1]), np.array([0.9, 0.9, 0.5]))
    1
    """
    lags = np.asarray(lags)
    rho = np.asarray(rho, dtype=np.float64)
    candidates = np.flatnonzero(rho >= rho.max() - tol)
    order = np.lexsort((lags[candidates], np.abs(lags[candidates])))  # |lag|, then lag
    return int(candidates[order[0]])


def lag_correlations(measured: np.ndarray, simulated: np.ndarray, max_lag: int) -> tuple[np.ndarray, np.ndarray]:
    """Pearson correlation of the overlaps for integer lags ``−max_lag … max_lag``.

    Returns ``(lags, rho)``; ``rho[j]`` belongs to ``lags[j]`` (samples, sign convention of the
    module docstring).

    Parameters
    ----------
    measured, simulated : numpy.ndarray
        Signals, shape (N,), one grid.
    max_lag : int
        Largest lag K in samples.

    Returns
    -------
    tuple of numpy.ndarray
        ``lags`` (2K + 1,) in samples and ``rho`` (2K + 1,), dimensionless.
    """
    m, c = as_pair(measured, simulated)
    n = m.shape[0]
    if not 0 <= max_lag < n:
        raise InvalidParameter(f"max_lag must lie in [0, {n - 1}] samples, got {max_lag}")
    # scale-free and better conditioned prefix sums
    m = (m - m.mean()) / (np.abs(m).max() or 1.0)
    c = (c - c.mean()) / (np.abs(c).max() or 1.0)
    full = scipy_signal.correlate(c, m, mode="full", method="auto")  # full[n-1+k] = Σ_i c[i+k] m[i]
    lags = np.arange(-max_lag, max_lag + 1)
    cross = full[n - 1 + lags]
    pm = np.concatenate([[0.0], np.cumsum(m)])
    pm2 = np.concatenate([[0.0], np.cumsum(m * m)])
    pc = np.concatenate([[0.0], np.cumsum(c)])
    pc2 = np.concatenate([[0.0], np.cumsum(c * c)])
    k = np.abs(lags)
    length = (n - k).astype(np.float64)
    # k ≥ 0: m[0:n-k], c[k:n];  k < 0: m[|k|:n], c[0:n-|k|]
    m_lo = np.where(lags >= 0, 0, k)
    c_lo = np.where(lags >= 0, k, 0)
    sm = pm[m_lo + n - k] - pm[m_lo]
    sm2 = pm2[m_lo + n - k] - pm2[m_lo]
    sc = pc[c_lo + n - k] - pc[c_lo]
    sc2 = pc2[c_lo + n - k] - pc2[c_lo]
    cov = cross - sm * sc / length
    vm = sm2 - sm * sm / length
    vc = sc2 - sc * sc / length
    tol = 1e-12 * length
    ok = (vm > tol) & (vc > tol)
    rho = np.zeros_like(cov)
    rho[ok] = cov[ok] / np.sqrt(vm[ok] * vc[ok])
    return lags, np.clip(rho, -1.0, 1.0)


def estimate_lag(measured: np.ndarray, simulated: np.ndarray, fs: float, *,
                 max_lag_s: float = DEFAULT_MAX_LAG_S, subsample: bool = False) -> SyncResult:
    """Lag of ``simulated`` behind ``measured`` (s) by bounded cross-correlation.

    Parameters
    ----------
    measured, simulated : equal-length signals on one grid.
    fs : sampling rate in Hz.
    max_lag_s : search window ±max_lag_s in s (default 2 s), capped at half the signal.
    subsample : refine the peak by three-point parabolic interpolation.

    Returns
    -------
    SyncResult
        Lag in samples and s (positive: simulated delayed) and the correlation at it.
    """
    m, c = as_pair(measured, simulated)
    fs = positive(fs, "fs", "Hz")
    if not np.isfinite(max_lag_s) or max_lag_s < 0:
        raise InvalidParameter(f"max_lag_s must be a finite value ≥ 0 s, got {max_lag_s!r}")
    n = m.shape[0]
    big_k = int(min(round(max_lag_s * fs), n // 2))
    lags, rho = lag_correlations(m, c, big_k)
    j = best_lag_index(lags, rho)
    lag = float(lags[j])
    refined = False
    if subsample and 0 < j < rho.shape[0] - 1:
        y0, y1, y2 = rho[j - 1], rho[j], rho[j + 1]
        denom = y0 - 2.0 * y1 + y2
        if denom < 0.0:
            lag += float(np.clip(0.5 * (y0 - y2) / denom, -0.5, 0.5))
            refined = True
    return SyncResult(lag_samples=lag, lag_s=lag / fs, correlation=float(rho[j]),
                      max_lag_samples=big_k, at_bound=bool(big_k > 0 and abs(lags[j]) == big_k),
                      refined=refined)


def apply_lag(measured: np.ndarray, simulated: np.ndarray, lag_samples: float) -> tuple[np.ndarray, np.ndarray]:
    """Remove a lag: return the overlapping parts ``(m_s, c_s)`` with ``c_s[i] ≈ c(i + τ)``.

    Integer lags cut both signals to the overlap; fractional lags evaluate the simulated
    signal at ``i + τ`` by linear interpolation for every ``i`` where that lies in the record.

    Parameters
    ----------
    measured, simulated : numpy.ndarray
        Signals, shape (N,), same unit and grid.
    lag_samples : float
        τ in samples (positive: simulated delayed).

    Returns
    -------
    tuple of numpy.ndarray
        ``(m_s, c_s)``, both of the overlap length.
    """
    m, c = as_pair(measured, simulated)
    n = m.shape[0]
    tau = float(lag_samples)
    if not np.isfinite(tau) or abs(tau) > n - 2:
        raise InvalidParameter(f"lag must be finite with |lag| ≤ {n - 2} samples, got {lag_samples!r}")
    if tau == round(tau):
        k = round(tau)
        if k >= 0:
            return m[: n - k], c[k:]
        return m[-k:], c[: n + k]
    i = np.arange(n)
    keep = (i + tau >= 0) & (i + tau <= n - 1)
    return m[keep], np.interp(i[keep] + tau, i, c)
