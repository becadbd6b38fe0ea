"""Order statistics of many rows without sorting them: the k-th smallest samples of each row,
exact, for the percentile values of the EN 14363 chain (:mod:`railval.core.en14363`).

A percentile reading needs only a few order statistics of each row (the inverse of the
empirical distribution reads one sample of rank ⌈n·p⌉; numpy's linear reading the two
around ``(n − 1)·p``, :func:`railval.core.definitions.sorted_percentiles`). Sorting the row
costs ``O(n log n)``; :func:`order_statistics` selects them by distribution (bucket)
selection in three passes over the row: its range; a histogram over :data:`BUCKETS` equal
buckets of the range (the bucket index ``⌊(x − min)·B/(max − min)⌋`` is monotone in x, so a
bucket's samples all lie above those of the buckets before it); the samples of the buckets
holding a wanted rank gathered; the rank within its bucket is then selected among these few
samples (``numpy.partition``). The range pass runs in four independent lanes (the
comparisons of one lane do not wait for the others) and the bucket index of each sample is
computed once, for the histogram and the gather. The result is exact — the samples a full
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

import numba
import numpy as np

from railval.core.errors import InvalidParameter

#: rows of at most this many samples are sorted (selection does not pay below)
SMALL_ROW = 256
#: buckets of the histogram pass
BUCKETS = 2048
#: rows of at most this many samples are sorted by numpy (its vectorised sort beats the
#: compiled selection up to a few thousand samples: 3.3 µs against 8.9 µs per row of 1000,
#: 20 µs against 28 µs per row of 2000 on the bench machine, AVX-512)
NUMPY_SORT_ROW = 3000


@numba.njit(cache=True, nogil=True)
def _range(x):  # pragma: no cover - compiled
    """(min, max) of a row without NaN, in four independent lanes (the comparisons of one
    lane do not wait for those of the others); min and max are exact in any order."""
    n = x.shape[0]
    a0 = a1 = a2 = a3 = b0 = b1 = b2 = b3 = x[0]
    i = 0
    while i + 4 <= n:
        v0, v1, v2, v3 = x[i], x[i + 1], x[i + 2], x[i + 3]
        a0 = min(a0, v0)
        a1 = min(a1, v1)
        a2 = min(a2, v2)
        a3 = min(a3, v3)
        b0 = max(b0, v0)
        b1 = max(b1, v1)
        b2 = max(b2, v2)
        b3 = max(b3, v3)
        i += 4
    for j in range(i, n):
        a0 = min(a0, x[j])
        b0 = max(b0, x[j])
    return min(min(a0, a1), min(a2, a3)), max(max(b0, b1), max(b2, b3))


@numba.njit(cache=True, nogil=True)
def _select_row(x, ranks, out, hist, slot, start, fill, cand, bucket
                ):  # pragma: no cover - compiled
    n = x.shape[0]
    k = ranks.shape[0]
    nb = hist.shape[0]
    mn, mx = _range(x)
    if mn == mx:
        for j in range(k):
            out[j] = mn
        return
    scale = nb / (mx - mn)
    if not np.isfinite(scale):  # a range too narrow for the buckets: sort
        srt = np.sort(x)
        for j in range(k):
            out[j] = srt[ranks[j]]
        return
    # histogram over equal buckets of [mn, mx]; the bucket index is monotone in the value,
    # so every sample of a bucket lies above those of the buckets before it
    for i in range(n):
        bucket[i] = min(int((x[i] - mn) * scale), nb - 1)
    hist[:] = 0
    for i in range(n):
        hist[bucket[i]] += 1
    # the bucket of each wanted rank and the samples below that bucket
    slot[:] = -1
    n_slots = 0
    total = 0
    below = 0
    b = 0
    for j in range(k):
        while below + hist[b] <= ranks[j]:
            below += hist[b]
            b += 1
        if slot[b] < 0:
            slot[b] = n_slots
            start[n_slots] = total
            fill[n_slots] = 0
            total += hist[b]
            n_slots += 1
    # gather the samples of those buckets
    for i in range(n):
        s = slot[bucket[i]]
        if s >= 0:
            cand[start[s] + fill[s]] = x[i]
            fill[s] += 1
    # select each rank within its bucket
    b = 0
    below = 0
    for j in range(k):
        while below + hist[b] <= ranks[j]:
            below += hist[b]
            b += 1
        s = slot[b]
        r = ranks[j] - below
        seg = cand[start[s]:start[s] + fill[s]]
        out[j] = np.partition(seg, r)[r] if seg.shape[0] > 1 else seg[0]


@numba.njit(cache=True, nogil=True)
def select_ranks(x, ranks, out, hist, slot, start, fill, cand, bucket
                 ):  # pragma: no cover - compiled
    """The samples of 0-based ranks ``ranks`` (ascending, unique) of the row ``x`` into
    ``out``: a row of at most :data:`SMALL_ROW` samples sorted, a longer one selected
    (:func:`_select_row`); the work arrays (``hist``, ``slot``: :data:`BUCKETS`; ``start``,
    ``fill``: len(ranks); ``cand``, ``bucket`` (int64): len(x)) are reused from row to row. For compiled callers
    (:mod:`railval.core.en_section`)."""
    if x.shape[0] <= SMALL_ROW:
        srt = np.sort(x)
        for j in range(ranks.shape[0]):
            out[j] = srt[ranks[j]]
        return
    _select_row(x, ranks, out, hist, slot, start, fill, cand, bucket)


@numba.njit(cache=True, nogil=True)
def _order_statistics_kernel(rows, ranks, out, r0, r1):  # pragma: no cover - compiled
    n = rows.shape[1]
    k = ranks.shape[0]
    hist = np.empty(BUCKETS, np.int64)
    slot = np.empty(BUCKETS, np.int64)
    start = np.empty(k, np.int64)
    fill = np.empty(k, np.int64)
    cand = np.empty(n)
    bucket = np.empty(n, np.int64)
    for r in range(r0, r1):
        select_ranks(rows[r], ranks, out[r], hist, slot, start, fill, cand, bucket)


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
