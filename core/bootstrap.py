"""Compiled row statistics of the percentile bootstrap (:func:`railval.core.validation.bootstrap_norm_ci`).

:func:`resample_mean_std` gives, for every row ``r`` of the resample indices ``idx``, the
mean and the sample standard deviation (ddof = 1) of ``d[idx[r]]`` — the float64s of
numpy's ``sample = d[idx]``, ``m = numpy.add.reduce(sample, axis=1) / n``,
``numpy.sqrt(numpy.add.reduce((sample - m[:, None]) ** 2, axis=1) / (n - 1))`` — without
the (n_boot, n) temporaries: each row is gathered into a buffer of n values that stays in
the L1 cache.

Bit for bit the same numbers: numpy reduces a contiguous float64 row by its pairwise sum
(numpy/_core/src/umath/loops_utils.h.src, ``pairwise_sum``: fewer than 8 values summed in
order; up to 128 values in 8 interleaved accumulators combined as
((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7)), the remainder added in order; longer
runs split at n/2 rounded down to a multiple of 8, the halves' sums added), added to the
reduction's initial value +0.0; :func:`_pairwise` is that recursion, operation for
operation (no fast-math: every addition rounded as numpy's). The square root and the
divisions are IEEE 754 correctly rounded in both. tests/test_bootstrap_kernel.py holds
the equality with numpy.

References
----------
Efron, B. & Tibshirani, R. (1993) An Introduction to the Bootstrap, ch. 13 (percentile
interval, pairs resampled with replacement).
Higham, N.J. (1993) The accuracy of floating point summation, SIAM J. Sci. Comput. 14,
783–799 (pairwise summation).
"""

from __future__ import annotations

import functools

import numba
import numpy as np

#: numpy's pairwise-summation block (``PW_BLOCKSIZE``)
_BLOCK = 128
#: stack depth of :func:`_pairwise` (each level halves the run: 2**64 values)
_DEPTH = 130


@numba.njit(cache=True, nogil=True, inline="always")
def _block_sum(buf, lo, n):  # pragma: no cover - compiled
    """numpy's ``pairwise_sum`` of ``buf[lo:lo + n]`` for n ≤ 128."""
    if n < 8:
        res = 0.0
        for i in range(lo, lo + n):
            res += buf[i]
        return res
    r0, r1, r2, r3 = buf[lo], buf[lo + 1], buf[lo + 2], buf[lo + 3]
    r4, r5, r6, r7 = buf[lo + 4], buf[lo + 5], buf[lo + 6], buf[lo + 7]
    stop = lo + n - n % 8
    for i in range(lo + 8, stop, 8):
        r0 += buf[i]
        r1 += buf[i + 1]
        r2 += buf[i + 2]
        r3 += buf[i + 3]
        r4 += buf[i + 4]
        r5 += buf[i + 5]
        r6 += buf[i + 6]
        r7 += buf[i + 7]
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    for i in range(stop, lo + n):
        res += buf[i]
    return res


@numba.njit(cache=True, nogil=True)
def _pairwise(buf, lo, n, work, sums):  # pragma: no cover - compiled
    """numpy's ``pairwise_sum`` of ``buf[lo:lo + n]``: its recursion (split at n/2 rounded
    down to a multiple of 8, left sum + right sum) walked with an explicit stack
    (``work``: int64 (depth, 3) of start, length, state; ``sums``: float64 (depth,) of the
    partial sums), as numba's cache does not hold recursive functions."""
    if n <= _BLOCK:
        return _block_sum(buf, lo, n)
    sp, vp = 1, 0
    work[0, 0], work[0, 1], work[0, 2] = lo, n, 0
    while sp > 0:
        top = sp - 1
        start, length, state = work[top, 0], work[top, 1], work[top, 2]
        if length <= _BLOCK:
            sums[vp] = _block_sum(buf, start, length)
            vp += 1
            sp -= 1
            continue
        half = length // 2
        half -= half % 8
        if state == 0:  # the left half first
            work[top, 2] = 1
            work[sp, 0], work[sp, 1], work[sp, 2] = start, half, 0
            sp += 1
        elif state == 1:  # then the right half
            work[top, 2] = 2
            work[sp, 0], work[sp, 1], work[sp, 2] = start + half, length - half, 0
            sp += 1
        else:  # both done: left + right
            sums[vp - 2] = sums[vp - 2] + sums[vp - 1]
            vp -= 1
            sp -= 1
    return sums[0]


@numba.njit(cache=True, nogil=True, error_model="numpy")
def resample_mean_std(d, idx):  # pragma: no cover - compiled
    """Per row r of ``idx`` (n_boot, n): mean and std (ddof = 1) of ``d[idx[r]]``, as numpy's
    row reductions compute them (module docstring). ``d``: float64 (m,), ``idx``: integer
    indices into ``d``, n ≥ 2."""
    rows, n = idx.shape
    means = np.empty(rows)
    stds = np.empty(rows)
    buf = np.empty(n)
    work = np.empty((_DEPTH, 3), dtype=np.int64)
    sums = np.empty(_DEPTH)
    for r in range(rows):
        for j in range(n):
            buf[j] = d[idx[r, j]]
        mean = (0.0 + _pairwise(buf, 0, n, work, sums)) / n
        for j in range(n):
            x = buf[j] - mean
            buf[j] = x * x
        means[r] = mean
        stds[r] = np.sqrt((0.0 + _pairwise(buf, 0, n, work, sums)) / (n - 1))
    return means, stds


#: most resample indices kept per (seed, quantity, n, n_boot) by :func:`_resample_indices`
_CACHED_DRAW = 1 << 18


#: most pairs whose resample indices are kept as uint16 (:func:`_resample_indices`)
_NARROW = 1 << 16


@functools.lru_cache(maxsize=64)
def _resample_indices(seed_key: tuple, n: int, n_boot: int) -> np.ndarray:
    """The resample indices of :func:`bootstrap_norm_ci` for ``seed_key`` in one draw
    (read-only; every configuration of a run with as many pairs reuses them), as uint16
    when they fit (the kernel reads them once per configuration and quantity: 8 bytes an
    index made the reads of the index arrays the largest part of its time)."""
    idx = np.random.default_rng(list(seed_key)).integers(0, n, size=(n_boot, n))
    if n <= _NARROW:  # the same indices in 2 bytes instead of 8: a quarter of the reads
        idx = idx.astype(np.uint16)
    idx.setflags(write=False)
    return idx


def bootstrap_norm_ci(d: np.ndarray, mean_limit: float, std_limit: float, *, n_boot: int,
                      rng: np.random.Generator | None = None, ci_level: float = 0.95,
                      chunk: int = 2_000_000, seed_key: tuple | None = None
                      ) -> tuple[tuple[float, float], tuple[float, float]]:
    """Percentile bootstrap CIs of mean/mean_limit and std(ddof=1)/std_limit over pairs
    (Efron & Tibshirani 1993, ch. 13: pairs resampled with replacement).

    Parameters
    ----------
    d : numpy.ndarray
        D_v of the pairs of one quantity.
    mean_limit, std_limit : float
        The limits the mean and std are divided by.
    n_boot : int
        Resamples (< 1, or fewer than 2 pairs: NaN intervals).
    rng : numpy.random.Generator, optional
        Source of the resampling.
    ci_level : float
        Confidence level of the intervals.
    chunk : int
        Most resampled values held at once (memory bound).
    seed_key : tuple, optional
        Instead of ``rng``: the seed of ``numpy.random.default_rng``; the indices of a
        single draw (at most :data:`_CACHED_DRAW` values) are kept and reused — the same
        numbers as ``rng=default_rng(list(seed_key))``.

    Returns
    -------
    ((float, float), (float, float))
        The intervals of mean/mean limit and of std/std limit.
    """
    rows = _resampled_rows(d, n_boot=n_boot, rng=rng, chunk=chunk, seed_key=seed_key)
    return bootstrap_cis([rows], [(mean_limit, std_limit)], ci_level)[0]


def _resampled_rows(d: np.ndarray, *, n_boot: int, rng: np.random.Generator | None = None,
                    chunk: int = 2_000_000, seed_key: tuple | None = None
                    ) -> tuple[np.ndarray, np.ndarray] | None:
    """The mean and std (ddof = 1) of every resample of :func:`bootstrap_norm_ci` (None:
    fewer than 2 pairs or no resample)."""
    n = d.size
    if n < 2 or n_boot < 1:
        return None
    if seed_key is not None and n * n_boot <= min(chunk, _CACHED_DRAW):
        # one draw of every resample: default_rng(seed_key).integers(0, n, (n_boot, n)),
        # drawn once per (seed_key, n, n_boot) and reused (what the loop below draws),
        # reduced row by row by a compiled kernel (the float64s of numpy's row mean and std)
        idx = _resample_indices(tuple(seed_key), n, n_boot)
        means, stds = resample_mean_std(np.ascontiguousarray(d, dtype=np.float64), idx)
    else:
        if rng is None:
            rng = np.random.default_rng(list(seed_key))
        means, stds = np.empty(n_boot), np.empty(n_boot)
        rows = max(1, chunk // n)
        for start in range(0, n_boot, rows):
            stop = min(n_boot, start + rows)
            sample = d[rng.integers(0, n, size=(stop - start, n))]
            means[start:stop] = sample.mean(axis=1)
            stds[start:stop] = sample.std(axis=1, ddof=1)
    return means, stds


def bootstrap_cis(rows: list, limits: list[tuple[float, float]], ci_level: float = 0.95
                  ) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    """The percentile intervals of :func:`bootstrap_norm_ci` of several quantities: per
    quantity ``rows`` (means, stds) of :func:`_resampled_rows` (None: NaN intervals) and
    ``limits`` (mean limit, std limit). Every interval of every quantity comes from one
    ``numpy.percentile`` call along the rows of one array — numpy partitions and
    interpolates each row on its own, so each interval is the number of a call on its
    rows alone."""
    a = (1.0 - ci_level) / 2.0
    qs = [100 * a, 100 * (1 - a)]
    nan = (float("nan"), float("nan"))
    held = [k for k, r in enumerate(rows) if r is not None]
    out = [(nan, nan)] * len(rows)
    if not held:
        return out
    stack = np.empty((2 * len(held), rows[held[0]][0].size))
    for j, k in enumerate(held):
        np.divide(rows[k][0], limits[k][0], out=stack[2 * j])
        np.divide(rows[k][1], limits[k][1], out=stack[2 * j + 1])
    lo, hi = np.percentile(stack, qs, axis=1).tolist()
    for j, k in enumerate(held):
        out[k] = ((lo[2 * j], hi[2 * j]), (lo[2 * j + 1], hi[2 * j + 1]))
    return out
