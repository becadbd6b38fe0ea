"""ISO/TS 18571 objective rating of a simulated curve against a reference (measured) curve.

ISO/TS 18571:2014 ("Road vehicles — Objective rating metric for non-ambiguous signals")
combines four sub-scores, each in [0, 1] (1 = identical):

1. **Corridor score Z** (on the unshifted curves). With ``T_norm = max_i |T_i|`` the inner and
   outer corridor half-widths are ``δ_i = a0 · T_norm`` and ``δ_o = b0 · T_norm`` (defaults
   a0 = 0.05, b0 = 0.5). Per sample ``C_i = 1`` if ``|C_i − T_i| < δ_i``, 0 if ``> δ_o``,
   else ``((δ_o − |C_i − T_i|)/(δ_o − δ_i))^kz`` (kz = 2); ``Z = mean_i C_i``.
2. **Phase score E_P.** The comparison curve is shifted against the reference by ``n`` samples,
   ``|n| ≤ ε_P · N`` (default ε_P = 0.2, i.e. 20 % of the duration), in both directions; the
   shift ``n_ε`` maximising the Pearson correlation of the overlapping parts is chosen.
   Ties: zero shift is kept unless another shift beats its correlation by more than
   ``RHO_TIE_TOL`` = 1e-9; in general the smallest |n| among the shifts within that
   tolerance of the largest correlation wins (:func:`railval.core.metrics.sync.best_lag_index`)
   — whole-period shifts of exactly in-phase periodic curves differ only by rounding noise
   (~1e-16) and must not move the shift. ``E_P = 1`` for ``n_ε = 0``, 0 for ``|n_ε| ≥ ε_P N``, else
   ``((ε_P N − |n_ε|)/(ε_P N))^kp`` (kp = 1). Magnitude and slope use the shifted, truncated
   curves.
3. **Magnitude score E_M.** Dynamic time warping (squared-difference local cost, Sakoe–Chiba
   band of radius ``ceil(w · N')`` samples, default w = 0.1) aligns the shifted curves; along
   the warping path ``e_M = Σ |C_w − T_w| / Σ |T_w|``; ``E_M = ((ε_M − e_M)/ε_M)^km`` for
   ``e_M < ε_M``, else 0 (ε_M = 0.5, km = 1).
4. **Slope score E_S.** Derivatives by central differences (one-sided at the ends), smoothed
   by a 9-point moving average (windows 1, 3, 5, 7 at the ends); ``e_S = Σ |C'_i − T'_i| /
   Σ |T'_i|``; ``E_S = ((ε_S − e_S)/ε_S)^ks`` for ``e_S < ε_S``, else 0 (ε_S = 2, ks = 1).

Overall rating ``R = 0.4 Z + 0.2 E_P + 0.2 E_M + 0.2 E_S``; grade *excellent* for R > 0.94,
*good* for R > 0.80, *fair* for R > 0.58, else *poor*.

The DTW kernel is compiled with numba (``cache=True``); it back-tracks from checkpoints
(the band row before every block of √N rows, recomputing one block at a time), so memory is
O(√N · band): ≈ 9 MB for a 20 000-sample curve with the default 10 % band.

References
----------
ISO/TS 18571:2014 Road vehicles — Objective rating metric for non-ambiguous signals.
Barbat, S. et al. (2013) Objective rating metric for dynamic systems. Proc. 23rd ESV
Conference, paper 13-0317 (the CORA/EEARTH basis of ISO/TS 18571).
Sakoe, H. & Chiba, S. (1978) Dynamic programming algorithm optimization for spoken word
recognition. IEEE Trans. ASSP 26(1), 43–49 (band-constrained DTW).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numba
import numpy as np

from railval.core.errors import InvalidParameter, InvalidSignal
from railval.core.metrics._checks import as_pair, fraction, positive
from railval.core.metrics.sync import RHO_TIE_TOL, best_lag_index, lag_correlations

GRADES = (("excellent", 0.94), ("good", 0.80), ("fair", 0.58))
WEIGHTS = (0.4, 0.2, 0.2, 0.2)


@dataclass(frozen=True)
class ISOParameters:
    """Parameters of ISO/TS 18571 with the standard's defaults (all dimensionless).

    a0, b0: inner/outer corridor half-width as fraction of max |reference|; kz: corridor
    exponent; max_shift: phase-shift bound as fraction of the duration; kp: phase exponent;
    dtw_window: DTW band radius as fraction of the (shifted) length; eps_mag, km: magnitude
    allowance and exponent; eps_slope, ks: slope allowance and exponent; weights: of Z, E_P,
    E_M, E_S (sum 1).
    """

    a0: float = 0.05
    b0: float = 0.5
    kz: float = 2.0
    max_shift: float = 0.2
    kp: float = 1.0
    dtw_window: float = 0.1
    eps_mag: float = 0.5
    km: float = 1.0
    eps_slope: float = 2.0
    ks: float = 1.0
    weights: tuple[float, float, float, float] = WEIGHTS

    def __post_init__(self) -> None:
        fraction(self.a0, "ISO 18571 a0 (inner corridor)", hi=1.0)
        fraction(self.b0, "ISO 18571 b0 (outer corridor)", hi=10.0)
        if self.b0 <= self.a0:
            raise InvalidParameter(f"ISO 18571 b0 must exceed a0={self.a0}, got {self.b0}")
        fraction(self.max_shift, "ISO 18571 max_shift", hi=1.0, hi_open=True)
        fraction(self.dtw_window, "ISO 18571 dtw_window", hi=1.0)
        for name in ("kz", "kp", "km", "ks", "eps_mag", "eps_slope"):
            positive(getattr(self, name), f"ISO 18571 {name}")
        w = tuple(float(x) for x in self.weights)
        if len(w) != 4 or min(w) < 0 or not math.isclose(sum(w), 1.0, abs_tol=1e-9):
            raise InvalidParameter(f"ISO 18571 weights must be 4 values ≥ 0 summing to 1, got {self.weights!r}")


@dataclass(frozen=True)
class ISORating:
    """ISO/TS 18571 result: sub-scores, overall rating, grade and intermediate errors.

    ``shift_samples``: phase shift n_ε (positive: simulated delayed); ``e_mag``/``e_slope``:
    magnitude and slope errors before scoring.
    """

    corridor: float
    phase: float
    magnitude: float
    slope: float
    rating: float
    grade: str
    shift_samples: int
    e_mag: float
    e_slope: float

    def to_dict(self) -> dict[str, float | int | str]:
        return asdict(self)


def grade(rating: float) -> str:
    """ISO/TS 18571 grade: excellent > 0.94, good > 0.80, fair > 0.58, else poor.

    Parameters
    ----------
    rating : float
        Overall rating R in [0, 1].

    Returns
    -------
    str
        ``"excellent"``, ``"good"``, ``"fair"`` or ``"poor"``.

    Examples
    --------
    >>> grade(0.9)
    'good'
    """
    r = float(rating)
    if not math.isfinite(r) or not -1e-12 <= r <= 1.0 + 1e-12:
        raise InvalidParameter(f"ISO 18571 rating must lie in [0, 1], got {rating!r}")
    for name, bound in GRADES:
        if r > bound:
            return name
    return "poor"


def corridor_score(reference: np.ndarray, comparison: np.ndarray, *, a0: float = 0.05,
                   b0: float = 0.5, kz: float = 2.0) -> float:
    """ISO/TS 18571 corridor score Z (see module docstring), in [0, 1].

    Parameters
    ----------
    reference, comparison : numpy.ndarray
        Measured and simulated curve, shape (N,), same unit.
    a0, b0 : float
        Inner and outer corridor half-width as fractions of ``max |reference|``.
    kz : float
        Exponent of the transition between the corridors.

    Returns
    -------
    float
        Z, dimensionless in [0, 1] (1 = inside the inner corridor everywhere).

    Examples
    --------
    >>> corridor_score(np.array([0.0, 1.0, 0.0]), np.array([0.0, 1.0, 0.6]))
    0.6666666666666666
    """
    t, c = as_pair(reference, comparison, min_len=1)
    t_norm = float(np.max(np.abs(t)))
    if t_norm == 0.0:
        raise InvalidSignal("reference curve is identically zero: ISO 18571 corridors have zero width")
    d_in, d_out = a0 * t_norm, b0 * t_norm
    diff = np.abs(c - t)
    score = ((d_out - np.clip(diff, d_in, d_out)) / (d_out - d_in)) ** kz
    return float(np.mean(score))


def phase_shift(reference: np.ndarray, comparison: np.ndarray, max_shift: float = 0.2) -> int:
    """Shift n_ε (samples, positive: comparison delayed) maximising the overlap correlation,
    ``|n| ≤ floor(max_shift · N)``. Ties within ``RHO_TIE_TOL`` of the largest correlation go
    to the smallest |n| (−n before +n): zero shift stays unless a shift beats it by more
    than the tolerance.

    Parameters
    ----------
    reference, comparison : numpy.ndarray
        Measured and simulated curve, shape (N,).
    max_shift : float
        ε_P, the largest shift as a fraction of N.

    Returns
    -------
    int
        n_ε in samples.
    """
    t, c = as_pair(reference, comparison)
    n = t.shape[0]
    k = min(math.floor(max_shift * n), n - 2)
    lags, rho = lag_correlations(t, c, k)
    return int(lags[best_lag_index(lags, rho, RHO_TIE_TOL)])


def phase_score(n_shift: int, n: int, *, max_shift: float = 0.2, kp: float = 1.0) -> float:
    """ISO/TS 18571 phase score E_P from the shift ``n_shift`` of ``n``-sample curves.

    Parameters
    ----------
    n_shift : int
        Phase shift n_ε in samples (:func:`phase_shift`).
    n : int
        Curve length N in samples.
    max_shift, kp : float
        ε_P (fraction of N) and the exponent.

    Returns
    -------
    float
        E_P, dimensionless in [0, 1].

    Examples
    --------
    >>> phase_score(10, 100)
    0.5
    """
    bound = max_shift * n
    s = abs(int(n_shift))
    if s == 0:
        return 1.0
    if s >= bound:
        return 0.0
    return float(((bound - s) / bound) ** kp)


@numba.njit(cache=True, nogil=True)
def _dtw_rows(x, y, radius, i_start, i_stop, prev_row, out):  # pragma: no cover - compiled
    """Accumulated DTW costs of rows ``i_start … i_stop−1`` of the band, from the band of row
    ``i_start − 1`` (``prev_row``, unused for ``i_start = 0``). ``out[r, b]`` is the cost of
    cell ``(i, j) = (i_start + r, i_start + r − radius + 1 + b)``; cells off the grid are inf.
    Recursion: ``D(i, j) = (x_i − y_j)² + min(D(i−1, j−1), D(i−1, j), D(i, j−1))``."""
    n = x.shape[0]
    width = 2 * radius - 1
    inf = np.inf
    prev = prev_row
    for r in range(i_stop - i_start):
        i = i_start + r
        row = out[r]
        lo = i - radius + 1  # column of band index 0
        j0 = max(0, lo)
        j1 = min(n, i + radius)
        for b in range(width):
            row[b] = inf
        xi = x[i]
        left = inf
        for j in range(j0, j1):
            b = j - lo
            d = xi - y[j]
            if i == 0:
                best = 0.0 if j == 0 else left
            else:
                # in the band of row i-1, column j-1 has index b and column j index b+1
                best = prev[b] if j > 0 else inf
                if b + 1 < width:
                    best = min(best, prev[b + 1])
                best = min(best, left)
            left = d * d + best
            row[b] = left
        prev = row
    return out


@numba.njit(cache=True, nogil=True)
def _dtw_band_error(x, y, radius):  # pragma: no cover - compiled
    """Band-constrained DTW of x (comparison) and y (reference), squared local cost; returns
    (Σ|x_w − y_w|, Σ|y_w|, path length, accumulated cost) along the optimal path.

    Memory-lean back-tracking: the forward pass keeps only the band row before every block
    of ``√N`` rows (checkpoints); the back-track recomputes one block at a time and picks,
    at each cell, the predecessor of least accumulated cost (diagonal first, then vertical,
    then horizontal on ties) — the same path a stored-choice implementation follows, at two
    forward passes and O(√N · band) memory.
    """
    n = x.shape[0]
    width = 2 * radius - 1
    inf = np.inf
    seg = max(1, int(math.sqrt(n)))
    nseg = (n + seg - 1) // seg
    checkpoints = np.empty((nseg, width))  # band of the row before block k
    buf = np.empty((seg, width))
    prev = np.full(width, inf)
    for k in range(nseg):
        i0 = k * seg
        i1 = min(n, i0 + seg)
        checkpoints[k, :] = prev
        _dtw_rows(x, y, radius, i0, i1, prev, buf)
        prev = buf[i1 - i0 - 1].copy()
    total = prev[radius - 1]  # cell (n-1, n-1)
    i = n - 1
    j = n - 1
    num = 0.0
    den = 0.0
    steps = 0
    k = nseg - 1
    i0 = k * seg
    _dtw_rows(x, y, radius, i0, min(n, i0 + seg), checkpoints[k], buf)
    while True:
        num += abs(x[i] - y[j])
        den += abs(y[j])
        steps += 1
        if i == 0 and j == 0:
            break
        b = j - (i - radius + 1)
        dg = inf
        vt = inf
        if i > 0:
            prow = buf[i - 1 - i0] if i - 1 >= i0 else checkpoints[k]
            if j > 0:
                dg = prow[b]
            if b + 1 < width:
                vt = prow[b + 1]
        hz = buf[i - i0][b - 1] if (j > 0 and b > 0) else inf
        if dg <= vt and dg <= hz:
            i -= 1
            j -= 1
        elif vt <= hz:
            i -= 1
        else:
            j -= 1
        if i < i0:
            k -= 1
            i0 = k * seg
            _dtw_rows(x, y, radius, i0, min(n, i0 + seg), checkpoints[k], buf)
    return num, den, steps, total


def dtw_magnitude_error(reference: np.ndarray, comparison: np.ndarray, window: float = 0.1) -> float:
    """ISO/TS 18571 magnitude error ``e_M = Σ|C_w − T_w| / Σ|T_w|`` along the DTW path.

    Sakoe–Chiba band ``|i − j| < ceil(window · N)`` (at least 1, i.e. no warping).

    Parameters
    ----------
    reference, comparison : numpy.ndarray
        Shifted, truncated measured and simulated curves, shape (N',), same unit.
    window : float
        Band radius w as a fraction of N'.

    Returns
    -------
    float
        e_M, dimensionless (0 = equal magnitudes).
    """
    t, c = as_pair(reference, comparison, min_len=1)
    n = t.shape[0]
    radius = n if window >= 1.0 else min(n, max(1, math.ceil(window * n)))
    num, den, _, _ = _dtw_band_error(c, t, radius)
    if den == 0.0:
        raise InvalidSignal("reference curve is zero along the DTW path: ISO 18571 magnitude error undefined")
    return float(num / den)


def dtw_cost(reference: np.ndarray, comparison: np.ndarray, window: float = 1.0) -> float:
    """Accumulated squared-difference DTW cost within the band (for tests and diagnostics)."""
    t, c = as_pair(reference, comparison, min_len=1)
    n = t.shape[0]
    radius = n if window >= 1.0 else min(n, max(1, math.ceil(window * n)))
    return float(_dtw_band_error(c, t, radius)[3])


def smoothed_slope(x: np.ndarray, dt: float) -> np.ndarray:
    """Derivative by central differences (one-sided at the ends) smoothed by a centred 9-point
    moving average; windows of 1, 3, 5, 7 samples at the first/last four samples.

    Parameters
    ----------
    x : numpy.ndarray
        Curve, shape (N,), unit u.
    dt : float
        Sample interval in s.

    Returns
    -------
    numpy.ndarray
        Slope in u/s, shape (N,).
    """
    a = np.asarray(x, dtype=np.float64)
    n = a.shape[0]
    if n < 9:
        raise InvalidSignal(f"ISO 18571 slope score needs ≥ 9 samples after the phase shift, got {n}")
    g = np.gradient(a, dt)
    cs = np.concatenate([[0.0], np.cumsum(g)])
    out = np.empty(n)
    out[4:n - 4] = (cs[9:] - cs[:-9]) / 9.0
    for idx, w in enumerate((1, 3, 5, 7)):
        out[idx] = cs[w] / w
        out[n - 1 - idx] = (cs[n] - cs[n - w]) / w
    return out


def slope_error(reference: np.ndarray, comparison: np.ndarray, dt: float) -> float:
    """``e_S = Σ |C'_i − T'_i| / Σ |T'_i|`` of the smoothed slopes (dimensionless).

    Parameters
    ----------
    reference, comparison : numpy.ndarray
        Measured and simulated curve, shape (N,), same unit.
    dt : float
        Sample interval in s.

    Returns
    -------
    float
        e_S, dimensionless.
    """
    ts = smoothed_slope(reference, dt)
    cs = smoothed_slope(comparison, dt)
    den = float(np.sum(np.abs(ts)))
    if den == 0.0:
        raise InvalidSignal("reference curve has zero slope everywhere: ISO 18571 slope error undefined")
    return float(np.sum(np.abs(cs - ts)) / den)


def _allowance_score(err: float, eps: float, k: float) -> float:
    if err <= 0.0:
        return 1.0
    if err >= eps:
        return 0.0
    return float(((eps - err) / eps) ** k)


def iso18571(reference: np.ndarray, comparison: np.ndarray, fs: float,
             params: ISOParameters | None = None) -> ISORating:
    """ISO/TS 18571 objective rating of ``comparison`` (simulated) against ``reference``
    (measured); equal-length curves sampled at ``fs`` Hz (see module docstring for the
    formulas). Returns an :class:`ISORating`; all scores dimensionless in [0, 1].

    Parameters
    ----------
    reference, comparison : numpy.ndarray
        Measured and simulated curve, shape (N,), same unit.
    fs : float
        Sampling rate in Hz.
    params : ISOParameters or None
        Corridor, phase, magnitude and slope settings; ``None`` = the ISO/TS 18571 defaults.

    Returns
    -------
    ISORating
    """
    p = params or ISOParameters()
    t, c = as_pair(reference, comparison, min_len=12)
    fs = positive(fs, "fs", "Hz")
    n = t.shape[0]
    z = corridor_score(t, c, a0=p.a0, b0=p.b0, kz=p.kz)
    shift = phase_shift(t, c, p.max_shift)
    ep = phase_score(shift, n, max_shift=p.max_shift, kp=p.kp)
    if shift >= 0:
        ts, cs = t[: n - shift], c[shift:]
    else:
        ts, cs = t[-shift:], c[: n + shift]
    e_mag = dtw_magnitude_error(ts, cs, p.dtw_window)
    em = _allowance_score(e_mag, p.eps_mag, p.km)
    e_slope = slope_error(ts, cs, 1.0 / fs)
    es = _allowance_score(e_slope, p.eps_slope, p.ks)
    wz, wp, wm, ws = p.weights
    r = float(min(1.0, max(0.0, wz * z + wp * ep + wm * em + ws * es)))
    return ISORating(corridor=z, phase=ep, magnitude=em, slope=es, rating=r, grade=grade(r),
                     shift_samples=shift, e_mag=e_mag, e_slope=e_slope)
