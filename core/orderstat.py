"""Order statistics of many rows without sorting them: the k-th smallest samples of each row,
exact, for the percentile values of the EN 14363 chain (:mod:`railval.core.en14363`).

A percentile reading needs only a few order statistics of each row (the inverse of the
empirical distribution reads one sample of rank ⌈n·p⌉; numpy's linear reading the two
around ``(n − 1)·p``, :func:`railval.core.definitions.sorted_percentiles`). Sorting the row
costs ``O(n log n)``; :func:`order_statistics` selects them by distribution (bucket)
selection: a provisional range, that of every ``STRIDE``-th sample (1/16 of the row); a
histogram over :data:`BUCKETS` equal buckets of that range, the samples below it counted in
the first bucket and those above in the last (the bucket index
``min(max(⌊(x − min)·B/(max − min)⌋, 0), B − 1)``, clamped before the conversion, is monotone
in x, so a bucket's samples all lie above those of the buckets before it, whichever range is
used); the samples of the buckets holding a wanted rank gathered; the rank within its bucket
is then selected among these few samples (``numpy.partition``). A provisional range that
misses samples only makes the end buckets larger (the 0.15 % and 99.85 % ranks of a row lie
near its strided extremes, a few dozen candidates); a strided sample of one value falls back
to the full range, computed in four independent lanes (the comparisons of one lane do not
wait for the others). The bucket index of each sample is computed once, for the histogram
and the gather. The result is exact — the samples a full
sort gives at those positions — whatever the distribution (a crowded bucket only costs time). Rows run on the
cores in parallel (compiled kernel without the GIL, :func:`railval.core.workers.split_rows`).
Rows of at most :data:`NUMPY_SORT_ROW` samples are sorted by numpy instead (its vectorised
sort is faster there; a sort gives the same order statistics).

References
----------
Knuth, D.E. (1998) The Art of Computer Programming vol. 3, 2nd ed., §5.2.5 (distribution
sorting) and §5.3.3 (selection); Hoare, C.A.R. (1961) Algorithm 65: FIND, Comm. ACM 4(7).
"""

from __future__ import annotations

import numpy as np

# the compiled selection lives with the kernels that call it (one file for numba's cache)
from railval.core.en_kernels import (  # noqa: F401 - re-exported
    BUCKETS,
    SMALL_ROW,
    _order_statistics_kernel,
    _range,
    _select_row,
    select_ranks,
)
from railval.core.errors import InvalidParameter

#: rows of at most this many samples are sorted by numpy (its vectorised sort beats the
#: compiled selection up to a few thousand samples: 3.3 µs against 8.9 µs per row of 1000,
#: 20 µs against 28 µs per row of 2000 on the bench machine, AVX-512)
NUMPY_SORT_ROW = 3000


def order_statistics(rows: np.ndarray, ranks) -> np.ndarray:
    """The samples of 0-based ranks ``ranks`` of every row of ``rows`` (shape (n_rows, n)),
    i.e. ``numpy.sort(rows, axis=-1)[:, ranks]`` — exactly, without sorting the rows; returns
    shape (n_rows, len(ranks)). Rows must not hold NaN (the EN chain refuses non-finite
    samples before)."""
    from railval.core.workers import split_rows

    arr = np.ascontiguousarray(np.atleast_2d(np.asarray(rows, dtype=np.float64)))
    order = np.asarray(ranks, dtype=np.int64)
    n = arr.shape[1]
    if order.ndim != 1 or np.any(order < 0) or np.any(order >= n):
        raise InvalidParameter(f"ranks must be 1-D within 0..{n - 1}, got {ranks!r}")
    if n <= NUMPY_SORT_ROW:
        return np.sort(arr, axis=-1)[:, order]
    uniq, back = np.unique(order, return_inverse=True)
    out = np.empty((arr.shape[0], uniq.size))
    if arr.shape[0] and uniq.size:
        # a part of at least ~200 000 samples: smaller ones cost more to hand over than to do
        split_rows(lambda a, b: _order_statistics_kernel(arr, uniq, out, a, b), arr.shape[0],
                   min_rows=max(1, 200_000 // max(n, 1)))
    return out[:, back]
