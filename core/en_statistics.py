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

import numpy as np

from railval.core.definitions import (
    CHOSEN,
    percentile_ranks,
    percentiles_from_order,
    window_centres,
)
from railval.core.en_kernels import _block_sum, _integral_at, pairwise_sum  # noqa: F401
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

