"""The faster per-section statistics step (core/en_kernels.py) gives the same numbers.

* Order statistics: the histogram now spans the range of every ``STRIDE``-th sample (a
  provisional range) and counts the samples outside it in the end buckets. The bucket index
  stays monotone in the value, so the selection is exact whatever the row; checked here
  against ``numpy.sort`` on rows built to fall outside the provisional range (spikes between
  the strided samples, huge magnitudes, a constant strided sample, crowded end buckets).
* Sliding means: the cumulative trapezoid and the prefix sums of two derived rows carried in
  one loop (:func:`_derived_means`) give bit for bit the numbers of :func:`_integral_at` and
  :func:`_sample_window_means` one row at a time, and those of a numpy reference
  (``numpy.cumsum`` of the trapezoids, the same additions in the same order).
"""

from __future__ import annotations

import numpy as np
import pytest

from railval.core.en_kernels import (
    BUCKETS,
    STRIDE,
    _derived_means,
    _integral_at,
    _sample_window_means,
    select_ranks,
)
from railval.core.orderstat import order_statistics


def _select(x: np.ndarray, ranks: np.ndarray) -> np.ndarray:
    out = np.empty(ranks.size)
    select_ranks(x, ranks, out, np.empty(BUCKETS, np.int64), np.empty(BUCKETS, np.int64),
                 np.empty(ranks.size, np.int64), np.empty(ranks.size, np.int64),
                 np.empty(x.size), np.empty(x.size, np.int64))
    return out


def _rows() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(26)
    n = 10_001
    smooth = np.cumsum(rng.standard_normal(n))
    spikes = smooth.copy()
    spikes[[1, 17, 5003]] = [1e6, -1e6, 3e5]  # between the strided samples
    huge = rng.standard_normal(n)
    huge[[3, 9]] = [1e308, -1e308]  # (x − min)·scale overflows to ±inf
    flat_stride = np.full(n, 2.5)
    flat_stride[np.arange(n) % STRIDE != 0] = rng.standard_normal(n - (n + STRIDE - 1) // STRIDE)
    flat_stride[-1] = 2.5
    tiny = np.full(n, 1.0)
    tiny[7] = np.nextafter(1.0, 2.0)  # strided range empty, true range one ulp
    crowded = rng.standard_normal(n)
    crowded[np.arange(n) % STRIDE != 0] *= 50.0  # most samples outside the strided range
    steps = np.repeat(rng.integers(-3, 4, n // 7 + 1).astype(float), 7)[:n]  # ties
    return {"smooth": smooth, "spikes": spikes, "huge": huge, "flat_stride": flat_stride,
            "tiny": tiny, "crowded": crowded, "steps": steps, "constant": np.full(n, -4.0)}


@pytest.mark.parametrize("name", list(_rows()))
def test_selection_equals_numpy_sort_outside_the_provisional_range(name):
    x = _rows()[name]
    n = x.size
    ranks = np.array(sorted({0, 1, 14, 15, n // 2, n // 2 + 1, n - 16, n - 15, n - 2, n - 1}),
                     dtype=np.int64)
    expected = np.sort(x)[ranks]
    assert _select(x, ranks).tobytes() == expected.tobytes()
    assert order_statistics(np.vstack([x, x[::-1]]), ranks).tobytes() == np.vstack(
        [expected, expected]).tobytes()


def test_the_selection_check_can_fail():
    x = _rows()["spikes"]
    ranks = np.array([0, x.size // 2, x.size - 1], dtype=np.int64)
    wrong = np.sort(x[::STRIDE])[[0, x[::STRIDE].size // 2, -1]]  # the strided sample's
    assert _select(x, ranks).tobytes() != wrong.tobytes()


def _derived_case(rows: int):
    rng = np.random.default_rng(rows)
    n = 3001
    d = np.cumsum(rng.uniform(0.04, 0.06, n))
    v = 0.3 + 0.05 * rng.standard_normal((rows, n))
    h = np.diff(d)
    j = np.sort(rng.integers(0, n - 1, 400)).astype(np.int64)
    u = rng.uniform(0.0, 1.0, j.size) * h[j]
    lo = rng.integers(0, n - 50, 300).astype(np.int64)
    hi = lo + rng.integers(0, 50, lo.size)  # some empty windows (NaN)
    return v, h, j, u, lo, hi


@pytest.mark.parametrize("rows", [1, 2, 5, 12])
def test_paired_prefix_sums_equal_the_row_kernels_and_numpy(rows):
    v, h, j, u, lo, hi = _derived_case(rows)
    at, sampled = np.empty((rows, j.size)), np.empty((rows, lo.size))
    _derived_means(v, h, j, u, at, lo, hi, sampled)
    at_ref, sampled_ref = np.empty_like(at), np.empty_like(sampled)
    _integral_at(v, h, j, u, at_ref)
    _sample_window_means(v, lo, hi, sampled_ref)
    assert at.tobytes() == at_ref.tobytes()
    assert sampled.tobytes() == sampled_ref.tobytes()
    # numpy: cumsum sums in order, as the kernels do
    cum = np.concatenate([np.zeros((rows, 1)),
                          np.cumsum((v[:, 1:] + v[:, :-1]) * 0.5 * h, axis=1)], axis=1)
    slope = (v[:, j + 1] - v[:, j]) / h[j]
    np.testing.assert_array_equal(at, cum[:, j] + v[:, j] * u + 0.5 * slope * u * u)
    pre = np.concatenate([np.zeros((rows, 1)), np.cumsum(v, axis=1)], axis=1)
    count = hi - lo
    with np.errstate(invalid="ignore", divide="ignore"):
        means = np.where(count > 0, (pre[:, hi] - pre[:, lo]) / count, np.nan)
    np.testing.assert_array_equal(sampled, means)


def test_paired_prefix_sums_skip_what_is_not_asked():
    v, h, j, u, lo, hi = _derived_case(3)
    at = np.empty((3, j.size))
    empty = np.empty(0, np.int64)
    _derived_means(v, h, j, u, at, empty, empty, np.empty((3, 0)))
    at_ref = np.empty_like(at)
    _integral_at(v, h, j, u, at_ref)
    assert at.tobytes() == at_ref.tobytes()
    sampled = np.empty((3, lo.size))
    _derived_means(v, h, empty, np.empty(0), np.empty((3, 0)), lo, hi, sampled)
    ref = np.empty_like(sampled)
    _sample_window_means(v, lo, hi, ref)
    assert np.array_equal(sampled, ref, equal_nan=True)
