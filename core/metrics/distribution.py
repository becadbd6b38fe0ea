"""Distribution-based comparison: Kolmogorov–Smirnov, area validation metric, Anderson–Darling.

These metrics compare the empirical cumulative distribution functions (CDF) of the samples of
the measured and the simulated signal and ignore time order ([ref 2] §4):

* **Kolmogorov–Smirnov distance** ``D = sup_x |F_m(x) − F_c(x)|`` ([ref 2] eq. 1),
  dimensionless, 0…1, with the classical two-sample p-value of ``scipy.stats.ks_2samp``.
* **Autocorrelation-aware KS p-value.** The classical p-value treats the ``n`` samples of a
  time series as independent; samples of a low-pass filtered signal at a high sampling rate
  are strongly correlated, so the classical p-value is far too small (a tiny phase or gain
  difference "rejects" every model). We replace ``n`` by an *effective sample size*
  ``n_eff`` per signal and evaluate the same Kolmogorov distribution (``scipy.stats.kstwo``
  with ``round(n1_eff·n2_eff/(n1_eff+n2_eff))``, exactly what ``ks_2samp(method="asymp")``
  does with the nominal sizes). Two estimators of ``n_eff`` are offered:

  - ``"bartlett"`` (default): ``n_eff = n / (1 + 2 Σ_{k=1}^{K} (1 − k/n) ρ_k)`` — the
    variance-inflation factor of the mean of a stationary series (Bartlett 1946; Bayley &
    Hammersley 1946), with the sum truncated before the first lag where the sample
    autocorrelation ``ρ_k`` is ≤ 0. Truncation is necessary: with the mean removed, the
    sample autocorrelations satisfy ``1 + 2 Σ_{k=1}^{n−1} ρ_k = 0`` exactly, so the full sum
    is useless (Thiébaux & Zwiers 1984 discuss such truncated estimators). We choose it as
    default because railway signals are narrow-band (hunting, body modes): their
    autocorrelation is far from the geometric decay an AR(1) model assumes.
  - ``"ar1"``: ``n_eff = n (1 − ρ_1)/(1 + ρ_1)`` from the lag-1 autocorrelation alone
    (Bretherton et al. 1999 eq. 31; Wilks 2011 §5.2.4).

  ``n_eff`` is bounded to ``[2, n]`` (negative correlation never *adds* information here).
* **Area validation metric** ``d = ∫ |F_m(x) − F_c(x)| dx`` (Ferson, Oberkampf & Ginzburg
  2008; [ref 2] eq. 2), in the **unit of the signal**; for two empirical distributions this
  equals the 1-Wasserstein distance (``scipy.stats.wasserstein_distance``).
* **Anderson–Darling k-sample statistic** (Scholz & Stephens 1987) via
  ``scipy.stats.anderson_ksamp`` (midrank variant). Caveats: its p-value is interpolated from
  tabulated critical values and therefore **floored at 0.001 and capped at 0.25** (we report
  ``p_capped``); like the classical KS p-value it assumes independent samples, so for time
  series it is only a relative indicator, never a test decision.

References
----------
Bartlett, M. S. (1946) On the theoretical specification and sampling properties of
autocorrelated time-series. J. R. Stat. Soc. Suppl. 8, 27–41.
Bayley, G. V. & Hammersley, J. M. (1946) The "effective" number of independent observations in
an autocorrelated time series. J. R. Stat. Soc. Suppl. 8, 184–197.
Thiébaux, H. J. & Zwiers, F. W. (1984) The interpretation and estimation of effective sample
size. J. Climate Appl. Meteor. 23, 800–811.
Bretherton, C. S. et al. (1999) The effective number of spatial degrees of freedom of a
time-varying field. J. Climate 12, 1990–2009.
Ferson, S., Oberkampf, W. L. & Ginzburg, L. (2008) Model validation and predictive capability
for the thermal challenge problem. Comput. Methods Appl. Mech. Engrg 197, 2408–2430.
Scholz, F. W. & Stephens, M. A. (1987) K-sample Anderson–Darling tests. J. Amer. Stat. Assoc.
82, 918–924.
Seed 001 (CDF-based validation of a freight wagon model), §4.1–4.2.
"""

from __future__ import annotations

import warnings
from dataclasses import asdict, dataclass

import numpy as np

from railval.core import lazy
from railval.core.errors import InvalidParameter, InvalidSignal
from railval.core.metrics._checks import as_signal

#: imported when first used (railval.core.lazy): a command that never reaches it does not load it
scipy_stats = lazy.module("scipy.stats")

NEFF_METHODS = ("bartlett", "ar1")


# --------------------------------------------------------------------------- autocorrelation
def autocorrelation(x: np.ndarray, max_lag: int | None = None) -> np.ndarray:
    """Sample autocorrelation ``ρ_k``, ``k = 0 … max_lag`` (biased estimator, ``ρ_0 = 1``).

    ``ρ_k = Σ_{i=0}^{n−1−k} (x_i − x̄)(x_{i+k} − x̄) / Σ (x_i − x̄)²`` computed by FFT with
    zero padding (no circular wrap). Dimensionless.

    Parameters
    ----------
    x : numpy.ndarray
        Signal, shape (n,).
    max_lag : int or None
        Largest lag in samples (default n − 1).

    Returns
    -------
    numpy.ndarray
        ρ_0 … ρ_max_lag, shape (max_lag + 1,).

    Examples
    --------
    >>> autocorrelation(np.array([1.0, -1.0, 1.0, -1.0]), 1)
    array([ 1.  , -0.75])
    """
    a = as_signal(x, "signal", min_len=2)
    n = a.shape[0]
    if max_lag is None:
        max_lag = n - 1
    if not 0 <= max_lag < n:
        raise InvalidParameter(f"max_lag must lie in [0, {n - 1}], got {max_lag}")
    d = a - a.mean()
    var = float(np.dot(d, d))
    if var == 0.0:
        raise InvalidSignal("signal is constant: autocorrelation undefined")
    nfft = 1 << int(2 * n - 1).bit_length()
    spec = np.fft.rfft(d, nfft)
    acov = np.fft.irfft(spec * np.conj(spec), nfft)[: max_lag + 1]
    return acov / var


def effective_sample_size(x: np.ndarray, method: str = "bartlett") -> float:
    """Effective number of independent samples of a time series (see module docstring).

    Parameters
    ----------
    x : 1-D signal (any unit).
    method : ``"bartlett"`` (truncated sum of autocorrelations, default) or ``"ar1"``.

    Returns
    -------
    float in ``[2, n]``.
    """
    a = as_signal(x, "signal", min_len=3)
    n = a.shape[0]
    if method not in NEFF_METHODS:
        raise InvalidParameter(f"n_eff method must be one of {NEFF_METHODS}, got {method!r}")
    if np.ptp(a) == 0.0:
        return float(n)  # constant: no sampling variability to correct
    rho = autocorrelation(a)
    if method == "ar1":
        r1 = float(rho[1])
        n_eff = n * (1.0 - r1) / (1.0 + r1) if r1 > 0 else float(n)
    else:
        nonpos = np.flatnonzero(rho[1:] <= 0.0)
        k_stop = int(nonpos[0]) + 1 if nonpos.size else n  # first lag with ρ_k ≤ 0
        k = np.arange(1, k_stop)
        inflation = 1.0 + 2.0 * float(np.sum((1.0 - k / n) * rho[1:k_stop]))
        n_eff = n / inflation
    return float(min(max(n_eff, 2.0), n))


# --------------------------------------------------------------------------- Kolmogorov–Smirnov
@dataclass(frozen=True)
class KSResult:
    """Two-sample Kolmogorov–Smirnov comparison.

    ``D``: distance (0…1); ``p``: classical p-value (``ks_2samp``, independent samples);
    ``p_eff``: p-value with effective sample sizes; ``n_eff_measured``/``n_eff_simulated``:
    effective sizes used; ``neff_method``: estimator name.
    """

    D: float
    p: float
    p_eff: float
    n_eff_measured: float
    n_eff_simulated: float
    neff_method: str

    def to_dict(self) -> dict[str, float | str]:
        return asdict(self)


def ks_pvalue(d: float, n1: float, n2: float) -> float:
    """Asymptotic two-sided two-sample KS p-value for sizes ``n1``, ``n2`` (may be effective).

    Uses the Kolmogorov distribution of ``D_n`` with ``n = round(n1 n2 / (n1 + n2))`` (≥ 1),
    ``scipy.stats.kstwo.sf(d, n)`` — the formula of ``ks_2samp(method="asymp")``.

    Parameters
    ----------
    d : float
        KS distance D in [0, 1].
    n1, n2 : float
        Sample sizes (possibly effective, non-integer).

    Returns
    -------
    float
        p-value in [0, 1].
    """
    if not 0.0 <= d <= 1.0:
        raise InvalidParameter(f"KS distance must lie in [0, 1], got {d!r}")
    en = max(1, int(np.round(n1 * n2 / (n1 + n2))))
    return float(np.clip(scipy_stats.kstwo.sf(d, en), 0.0, 1.0))


def kolmogorov_smirnov(measured: np.ndarray, simulated: np.ndarray, *,
                       neff_method: str = "bartlett") -> KSResult:
    """KS distance ([ref 2] eq. 1), classical and autocorrelation-aware p-values.

    The samples need not share a grid or length. ``D`` and ``p`` are those of
    ``scipy.stats.ks_2samp`` (``method="auto"``); ``p_eff`` uses :func:`effective_sample_size`.

    Parameters
    ----------
    measured, simulated : numpy.ndarray
        Samples, shape (N_m,) and (N_c,), same unit.
    neff_method : str
        Estimator of :func:`effective_sample_size` for ``p_eff``.

    Returns
    -------
    KSResult
    """
    m = as_signal(measured, "measured", min_len=3)
    c = as_signal(simulated, "simulated", min_len=3)
    res = scipy_stats.ks_2samp(m, c)
    d = float(res.statistic)
    n1 = effective_sample_size(m, neff_method)
    n2 = effective_sample_size(c, neff_method)
    return KSResult(D=d, p=float(res.pvalue), p_eff=ks_pvalue(d, n1, n2),
                    n_eff_measured=n1, n_eff_simulated=n2, neff_method=neff_method)


# --------------------------------------------------------------------------- area metric
def area_validation_metric(measured: np.ndarray, simulated: np.ndarray) -> float:
    """Area between the empirical CDFs, ``∫ |F_m(x) − F_c(x)| dx``, in the signal's unit.

    Ferson et al. (2008); [ref 2] eq. 2. Both CDFs are step functions, so the integral is the
    exact sum over the intervals between consecutive pooled sample values of
    ``|F_m − F_c| · Δx``. Equals ``scipy.stats.wasserstein_distance(measured, simulated)``.

    Parameters
    ----------
    measured, simulated : numpy.ndarray
        Samples, shape (N_m,) and (N_c,), same unit.

    Returns
    -------
    float
        Area in the signal's unit (0 = equal distributions).

    Examples
    --------
    >>> area_validation_metric(np.array([0.0, 1.0]), np.array([1.0, 2.0]))
    1.0
    """
    m = np.sort(as_signal(measured, "measured", min_len=1))
    c = np.sort(as_signal(simulated, "simulated", min_len=1))
    pooled = np.sort(np.concatenate([m, c]))
    dx = np.diff(pooled)
    fm = np.searchsorted(m, pooled[:-1], side="right") / m.shape[0]
    fc = np.searchsorted(c, pooled[:-1], side="right") / c.shape[0]
    return float(np.sum(np.abs(fm - fc) * dx))


# --------------------------------------------------------------------------- Anderson–Darling
@dataclass(frozen=True)
class ADResult:
    """k-sample Anderson–Darling (k = 2): normalised statistic, tabulated p-value (clipped to
    [0.001, 0.25] by scipy, ``p_capped`` says whether it hit a bound)."""

    statistic: float
    p: float
    p_capped: bool

    def to_dict(self) -> dict[str, float | bool]:
        return asdict(self)


def anderson_darling(measured: np.ndarray, simulated: np.ndarray) -> ADResult:
    """Anderson–Darling k-sample test of ``measured`` vs ``simulated`` (Scholz & Stephens 1987).

    ``scipy.stats.anderson_ksamp([measured, simulated], variant="midrank")``; scipy's warning
    that the p-value was floored/capped is turned into the ``p_capped`` flag. The statistic is
    the normalised ``(A²_kN − (k−1)) / σ_N``; larger means more different.

    Parameters
    ----------
    measured, simulated : numpy.ndarray
        Samples, shape (N_m,) and (N_c,), same unit.

    Returns
    -------
    ADResult
    """
    m = as_signal(measured, "measured", min_len=2)
    c = as_signal(simulated, "simulated", min_len=2)
    if np.ptp(np.concatenate([m, c])) == 0.0:
        raise InvalidSignal("Anderson–Darling needs at least two distinct values in the pooled samples")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = scipy_stats.anderson_ksamp([m, c], variant="midrank")
    capped = any("p-value" in str(w.message) for w in caught)
    unexpected = [w for w in caught if "p-value" not in str(w.message)]
    for w in unexpected:  # re-raise anything we did not expect (pytest turns it into an error)
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return ADResult(statistic=float(res.statistic), p=float(res.pvalue), p_capped=bool(capped))
