"""Statistics of the EN 14363 processing chain (:mod:`railval.core.en14363`): percentiles of
the cumulative distribution, the larger magnitude of the 0.15 % and 99.85 % values, rms and the
distance-based sliding mean.

References: EN 14363:2016 (percentiles 0.15 %, 50 %, 99.85 % of the filtered signal; sliding
mean over 2 m in steps of 0.5 m for the quasi-static values); Polach & Böttcher 2014, Table 2
(the quantities of the DynoTRAIN validation and their statistics). The open choices of these
definitions and the reading railval takes are in docs/validation.md and
:mod:`railval.core.definitions`.
"""

from __future__ import annotations

import numba
import numpy as np

from railval.core.definitions import (
    CHOSEN,
    percentile_ranks,
    percentiles_from_order,
    window_centres,
)
from railval.core.errors import InvalidParameter, InvalidSignal
from railval.core.orderstat import order_statistics

#: numpy.quantile method used for every percentile (EN 14363 cumulative distribution)
QUANTILE_METHOD = CHOSEN.percentile
P_LOW = 0.0015
P_MEDIAN = 0.5
P_HIGH = 0.9985
#: sliding-mean window and step along the track, m
WINDOW_M = 2.0
STEP_M = 0.5
PERCENTILES = (P_LOW, P_MEDIAN, P_HIGH)


def percentile(x: np.ndarray, p, axis: int = -1) -> np.ndarray:
    """EN 14363 percentile value(s) ``p`` (fractions, e.g. 0.9985) along ``axis``.

    Inverse of the empirical cumulative distribution (``numpy.quantile`` with
    ``method="inverted_cdf"``); see the module docstring.
    """
    return np.quantile(np.asarray(x, dtype=np.float64), p, axis=axis, method=QUANTILE_METHOD)


def _row_percentiles(rows: np.ndarray, methods: tuple[str, ...] = (QUANTILE_METHOD,)
                     ) -> list[np.ndarray]:
    """(0.15 %, 50 %, 99.85 %) values of every row under each percentile method, each of shape
    (n_rows, 3): the order statistics the methods read are selected once for all of them
    (:func:`railval.core.orderstat.order_statistics`, exact, no sort of the rows) and the
    percentiles formed from them as :func:`railval.core.definitions.sorted_percentiles`
    forms them from a sorted row."""
    rows = np.atleast_2d(rows)
    n = rows.shape[-1]
    ranks = sorted({r for m in methods for r in percentile_ranks(n, PERCENTILES, m)})
    return _percentiles_of(order_statistics(rows, ranks), ranks, n, methods)


def _percentiles_of(stats: np.ndarray, ranks: list[int], n: int, methods: tuple[str, ...]
                    ) -> list[np.ndarray]:
    """:func:`_row_percentiles` from the order statistics ``stats`` (shape (n_rows,
    len(ranks)); column c holds the samples of 0-based rank ``ranks[c]`` of rows of n)."""
    column = {r: c for c, r in enumerate(ranks)}
    return [percentiles_from_order(lambda i: stats[:, column[i]], n, PERCENTILES, m)
            for m in methods]


def maxabs(p_low: np.ndarray | float, p_high: np.ndarray | float):
    """Larger magnitude of the 0.15 % and 99.85 % values (Polach & Böttcher 2014 Table 2, footnote a)."""
    return np.maximum(np.abs(p_low), np.abs(p_high))


def rms(x: np.ndarray, axis: int = -1) -> np.ndarray:
    """Root mean square ``sqrt(mean(x²))`` along ``axis`` (unit of x)."""
    x = np.asarray(x, dtype=np.float64)
    return np.sqrt(np.mean(x * x, axis=axis))


def sliding_mean_distance(values: np.ndarray, distance_m: np.ndarray, start_m: float,
                          end_m: float, window_m: float = WINDOW_M,
                          step_m: float = STEP_M, *,
                          origin_m: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Sliding mean over ``window_m`` metres evaluated every ``step_m`` metres of distance.

    The signal is taken as piecewise linear between samples on the distance axis (so variable
    speed is handled exactly); its integral ``C(x) = ∫ s dx`` is the cumulative trapezoid at
    the samples and a quadratic in between. The mean over the window centred at ``x`` is
    ``(C(x + w/2) − C(x − w/2)) / w``. Centres are ``origin_m + w/2 + k·step_m`` up to
    ``end_m − w/2`` with ``origin_m = start_m`` unless given (the alternative grid starts at
    the first evaluated sample): every window lies inside the evaluated range.

    ``values``: shape (n,) or (n_rows, n); ``distance_m``: strictly increasing, shape (n,), m.
    Returns ``(centres_m, means)``, means shaped (n_rows, n_centres) (or (n_centres,)).

    References: Polach & Böttcher 2014 Table 2 ("sliding mean, 2 m window, step 0.5 m"); EN 14363.
    """
    d = np.asarray(distance_m, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64)
    one_d = v.ndim == 1
    if one_d:
        v = v[np.newaxis, :]
    _check_sliding_range(d, start_m, end_m, window_m, step_m)
    (centres, means), = _interpolant_means(
        v, d, start_m, end_m, window_m, step_m, [start_m if origin_m is None else origin_m])
    return centres, (means[0] if one_d else means)


def _check_sliding_range(d: np.ndarray, start_m: float, end_m: float, window_m: float,
                         step_m: float) -> None:
    if window_m <= 0 or step_m <= 0:
        raise InvalidParameter(
            f"window_m and step_m must be > 0 m, got window_m={window_m}, step_m={step_m}")
    if end_m - start_m < window_m:
        raise InvalidSignal(
            f"evaluated range {start_m}–{end_m} m is shorter than the {window_m} m sliding "
            f"window")
    if start_m < d[0] or end_m > d[-1]:
        raise InvalidSignal(
            f"evaluated range {start_m}–{end_m} m exceeds the distance axis "
            f"{d[0]:.3f}–{d[-1]:.3f} m")


def _interpolant_means(v: np.ndarray, d: np.ndarray, start_m: float, end_m: float,
                       window_m: float, step_m: float, origins) -> list[tuple[np.ndarray, np.ndarray]]:
    """Distance-weighted window means of the rows of ``v`` for the grid of each origin in
    ``origins``; the cumulative integral is formed once for all of them."""
    grids, j_all, u_all = _window_ends(d, start_m, end_m, window_m, step_m, origins)
    at = np.empty((v.shape[0], j_all.size))
    _integral_at(np.ascontiguousarray(v), np.diff(d), j_all, u_all, at)
    return _means_from_integrals(at, grids, window_m)


def _window_ends(d: np.ndarray, start_m: float, end_m: float, window_m: float, step_m: float,
                 origins) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    """The window centres of each origin's grid, and the interval ``j`` and offset ``u`` (m)
    on the distance axis ``d`` of every window start, then every window end, grid after grid
    (the points :func:`_integral_at` evaluates)."""
    half = window_m / 2.0
    grids, js, us = [], [], []
    for origin in origins:
        centres = window_centres(start_m, end_m, origin, window_m, step_m)
        grids.append(centres)
        for x in (centres - half, centres + half):
            j = np.clip(np.searchsorted(d, x, side="right") - 1, 0, d.size - 2)
            js.append(j)
            us.append(x - d[j])
    return grids, np.concatenate(js), np.concatenate(us)


def _means_from_integrals(at: np.ndarray, grids: list[np.ndarray], window_m: float
                          ) -> list[tuple[np.ndarray, np.ndarray]]:
    """``(centres, means)`` per grid from the integrals ``at`` at the window starts and ends
    (columns in the order of :func:`_window_ends`)."""
    out = []
    pos = 0
    for centres in grids:
        k = centres.size
        out.append((centres, (at[:, pos + k:pos + 2 * k] - at[:, pos:pos + k]) / window_m))
        pos += 2 * k
    return out


@numba.njit(cache=True, nogil=True)
def _integral_at(v, h, j, u, out):  # pragma: no cover - compiled
    """``out[r, k]`` = C(x_k) of row r, the integral of the piecewise-linear signal from the
    first sample to ``x_k = d[j[k]] + u[k]``: the cumulative trapezoid at the samples
    (``C_0 = 0``, ``C_i = C_{i−1} + 0.5·(v_i + v_{i−1})·h_{i−1}``, summed in order as numpy's
    cumsum sums) plus the quadratic of the interval ``[d_j, d_{j+1}]``:
    ``C_j + v_j·u + 0.5·slope·u²`` with ``slope = (v_{j+1} − v_j)/h_j`` — the same operations
    in the same order as the former numpy expression, so the same numbers."""
    rows, n = v.shape
    cum = np.empty(n)
    for r in range(rows):
        cum[0] = 0.0
        for i in range(1, n):
            cum[i] = cum[i - 1] + (v[r, i] + v[r, i - 1]) * 0.5 * h[i - 1]
        for k in range(j.shape[0]):
            jj = j[k]
            uu = u[k]
            slope = (v[r, jj + 1] - v[r, jj]) / h[jj]
            out[r, k] = cum[jj] + v[r, jj] * uu + 0.5 * slope * uu * uu


@numba.njit(cache=True, nogil=True)
def _block_sum(a, lo, n):  # pragma: no cover - compiled
    """numpy's sum of a run of at most 128: sequential below 8, else eight interleaved
    partial sums combined pairwise, then the rest."""
    if n < 8:
        res = 0.0
        for i in range(lo, lo + n):
            res += a[i]
        return res
    r = a[lo:lo + 8].copy()
    i = 8
    while i < n - n % 8:
        for k in range(8):
            r[k] += a[lo + i + k]
        i += 8
    res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
    for k in range(i, n):
        res += a[lo + k]
    return res


@numba.njit(cache=True, nogil=True)
def pairwise_sum(a, lo, n):  # pragma: no cover - compiled
    """``a[lo:lo + n].sum()`` as numpy sums a contiguous run, so the same number: runs of at
    most 128 by :func:`_block_sum`, longer ones split at a multiple of 8 near the half and
    the halves' sums added (Higham 1993; numpy's ``pairwise_sum``). The recursion is walked
    with an explicit stack (a cached compiled function must not call itself)."""
    if n <= 128:
        return _block_sum(a, lo, n)
    los = np.empty(64, np.int64)
    ns = np.empty(64, np.int64)
    stage = np.zeros(64, np.int64)
    left = np.empty(64)
    top = 0
    los[0] = lo
    ns[0] = n
    ret = 0.0
    while top >= 0:
        m = ns[top]
        if m <= 128:
            ret = _block_sum(a, los[top], m)
            top -= 1
            continue
        half = m // 2 - (m // 2) % 8
        if stage[top] == 0:
            stage[top] = 1
            los[top + 1], ns[top + 1], stage[top + 1] = los[top], half, 0
            top += 1
        elif stage[top] == 1:
            left[top] = ret
            stage[top] = 2
            los[top + 1], ns[top + 1], stage[top + 1] = los[top] + half, m - half, 0
            top += 1
        else:
            ret = left[top] + ret
            top -= 1
    return ret
