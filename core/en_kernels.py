"""The compiled kernels of the EN 14363 statistics, in one file.

They call each other: the per-section step (:func:`_section_kernel`, used by
:mod:`railval.core.en_section`) selects order statistics (:func:`select_ranks`, used by
:mod:`railval.core.orderstat`), sums pairwise (:func:`pairwise_sum`, also used by the Welch
segment mean of :mod:`railval.core.psd`) and integrates the linear interpolant at the window ends
(:func:`_integral_at`, :mod:`railval.core.en_statistics`), finds the sliding windows
(:func:`_window_bounds`), forms the sliding means of every reading (:func:`_sliding_means`)
and reads percentiles off order statistics (:func:`_read_percentiles`). Numba's on-disk cache
(``cache=True``) keys a kernel to the file it is defined in and compiles the compiled functions
it calls into it; a change in a callee defined in another file would leave the caller's cached
code unchanged (numba documentation, "Cache invalidation fails to recognize changes in
functions defined in a different file"). Kept in one file, any change here invalidates every
kernel that could contain it. ``tests/test_architecture.py`` refuses a cached kernel that calls
a compiled function of another module.

The modules named above keep their public functions and re-export these kernels; the
algorithms and their sources are described there (Knuth 1998 §5.2.5 and §5.3.3 for the
selection; numpy's pairwise summation for the sums; docs/validation.md for the sliding
means).
"""

from __future__ import annotations

import numba
import numpy as np

#: rows of at most this many samples are sorted (selection does not pay below)
SMALL_ROW = 256
#: buckets of the histogram pass
BUCKETS = 2048
#: the provisional range of a row is that of every STRIDE-th sample
STRIDE = 16


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
def _strided_range(x, stride):  # pragma: no cover - compiled
    """(min, max) of every ``stride``-th sample of ``x`` and of its last sample: a
    provisional range of the row (samples outside it are counted in the end buckets)."""
    n = x.shape[0]
    a = b = x[n - 1]
    for i in range(0, n, stride):
        v = x[i]
        a = min(a, v)
        b = max(b, v)
    return a, b


@numba.njit(cache=True, nogil=True)
def _rank_buckets(hist, ranks, n, rb, rbelow, slot, start, fill):  # pragma: no cover - compiled
    """The bucket ``rb[j]`` of rank ``ranks[j]`` (row of ``n``) and the number ``rbelow[j]``
    of samples in the buckets before it (bucket b holds ranks below .. below + hist[b] − 1):
    the ranks of the lower half walking the histogram up from the first bucket, the others
    down from the last (the 0.15 %/99.85 % ranks lie near the ends: short walks). Then
    ``slot[b]``: the place of bucket b among those wanted (−1: none), ``start``: where its
    samples go in the candidate array."""
    k = ranks.shape[0]
    b = below = j = 0
    while j < k and 2 * ranks[j] < n:
        while below + hist[b] <= ranks[j]:
            below += hist[b]
            b += 1
        rb[j], rbelow[j] = b, below
        j += 1
    b = hist.shape[0] - 1
    above = 0
    for i in range(k - 1, j - 1, -1):
        while n - above - hist[b] > ranks[i]:
            above += hist[b]
            b -= 1
        rb[i], rbelow[i] = b, n - above - hist[b]
    slot[:] = -1
    n_slots = total = 0
    for j in range(k):
        if slot[rb[j]] < 0:
            slot[rb[j]] = n_slots
            start[n_slots] = total
            fill[n_slots] = 0
            total += hist[rb[j]]
            n_slots += 1


@numba.njit(cache=True, nogil=True)
def _select_row(x, ranks, out, hist, slot, start, fill, cand, bucket
                ):  # pragma: no cover - compiled
    """Bucket selection of one row over a provisional range (the algorithm and its
    exactness: :mod:`railval.core.orderstat`)."""
    n = x.shape[0]
    k = ranks.shape[0]
    nb = hist.shape[0]
    mn, mx = _strided_range(x, STRIDE)
    if mn == mx:
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
    # histogram over equal buckets of the provisional range [mn, mx], the samples below it
    # in the first bucket, those above in the last: the bucket index is monotone in the
    # value, so every sample of a bucket lies above those of the buckets before it
    top = float(nb - 1)
    for i in range(n):
        bucket[i] = int(min(max((x[i] - mn) * scale, 0.0), top))
    hist[:] = 0
    for i in range(n):
        hist[bucket[i]] += 1
    rb = np.empty(k, np.int64)
    rbelow = np.empty(k, np.int64)
    _rank_buckets(hist, ranks, n, rb, rbelow, slot, start, fill)
    # gather the samples of those buckets
    for i in range(n):
        s = slot[bucket[i]]
        if s >= 0:
            cand[start[s] + fill[s]] = x[i]
            fill[s] += 1
    # select each rank within its bucket
    for j in range(k):
        s = slot[rb[j]]
        r = ranks[j] - rbelow[j]
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


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _derive(lp, yq, sy, cut0, cut1, wide0, derived):  # pragma: no cover - compiled
    """Step 2: ``derived`` = Y/Q rows (``lp[yq[r, 0]] / lp[yq[r, 1]]``) then ΣY rows
    (``lp[sy[r, 0]] + lp[sy[r, 1]]``) over ``wide0:wide0 + derived.shape[1]``; returns the
    first Y/Q row whose Q is exactly 0 inside ``cut0:cut1`` (−1: none)."""
    n_wide = derived.shape[1]
    n_yq = yq.shape[0]
    zero = -1
    # contiguous row slices and loops without early exit, so that the compiler vectorises
    # them (IEEE division and addition element by element: the same numbers)
    for r in range(n_yq):
        y = lp[yq[r, 0], wide0:wide0 + n_wide]
        q = lp[yq[r, 1], wide0:wide0 + n_wide]
        out = derived[r]
        for i in range(n_wide):
            out[i] = y[i] / q[i]
        if zero < 0:
            qc = lp[yq[r, 1], cut0:cut1]
            hit = False
            for i in range(qc.shape[0]):
                hit |= qc[i] == 0.0
            if hit:
                zero = r
    for r in range(sy.shape[0]):
        a = lp[sy[r, 0], wide0:wide0 + n_wide]
        b = lp[sy[r, 1], wide0:wide0 + n_wide]
        out = derived[n_yq + r]
        for i in range(n_wide):
            out[i] = a[i] + b[i]
    return zero


@numba.njit(cache=True, nogil=True)
def _sample_window_means(v, lo, hi, out):  # pragma: no cover - compiled
    """``out[r, c]`` = mean of ``v[r, lo[c]:hi[c]]`` from the row's prefix sums (``P_0 = 0``,
    ``P_{i+1} = P_i + v_i``, summed in order as numpy's cumsum), ``(P_hi − P_lo)/(hi − lo)``;
    NaN for an empty window — :func:`railval.core.definitions.sample_window_means`."""
    n = v.shape[1]
    cum = np.empty(n + 1)
    for r in range(v.shape[0]):
        cum[0] = 0.0
        for i in range(n):
            cum[i + 1] = cum[i] + v[r, i]
        for c in range(lo.shape[0]):
            count = hi[c] - lo[c]
            out[r, c] = (cum[hi[c]] - cum[lo[c]]) / count if count > 0 else np.nan


@numba.njit(cache=True, nogil=True)
def _pair_prefix(v, r, m, h, ct, cs):  # pragma: no cover - compiled
    """The prefix sums of rows ``r .. r + m − 1`` (m = 1 or 2) of ``v``: ``ct[q]`` the
    cumulative trapezoid of :func:`_integral_at`, ``cs[q]`` the prefix sums of
    :func:`_sample_window_means` — the same additions in the same order, the (up to four)
    independent running sums carried in one loop so that one addition need not wait for
    the one before it."""
    n = v.shape[1]
    a = v[r]
    b = v[r + m - 1]
    ta = tb = 0.0
    sa = sb = 0.0
    ct[0, 0] = ct[1, 0] = 0.0
    cs[0, 0] = cs[1, 0] = 0.0
    for i in range(1, n):
        ta = ta + (a[i] + a[i - 1]) * 0.5 * h[i - 1]
        tb = tb + (b[i] + b[i - 1]) * 0.5 * h[i - 1]
        sa = sa + a[i - 1]
        sb = sb + b[i - 1]
        ct[0, i] = ta
        ct[1, i] = tb
        cs[0, i] = sa
        cs[1, i] = sb
    cs[0, n] = sa + a[n - 1]
    cs[1, n] = sb + b[n - 1]


@numba.njit(cache=True, nogil=True)
def _derived_means(v, h, j, u, at, lo, hi, sampled):  # pragma: no cover - compiled
    """:func:`_integral_at` (``at``, when ``j`` is not empty) and
    :func:`_sample_window_means` (``sampled``, when ``lo`` is not empty) of the rows of
    ``v``, two rows at a time from one pass of their prefix sums (:func:`_pair_prefix`):
    the same operations in the same order, so the same numbers."""
    rows, n = v.shape
    ct = np.empty((2, n))
    cs = np.empty((2, n + 1))
    for r in range(0, rows, 2):
        m = min(2, rows - r)
        _pair_prefix(v, r, m, h, ct, cs)
        for q in range(m):
            x = v[r + q]
            for k in range(j.shape[0]):
                jj = j[k]
                uu = u[k]
                slope = (x[jj + 1] - x[jj]) / h[jj]
                at[r + q, k] = ct[q, jj] + x[jj] * uu + 0.5 * slope * uu * uu
            for c in range(lo.shape[0]):
                count = hi[c] - lo[c]
                sampled[r + q, c] = ((cs[q, hi[c]] - cs[q, lo[c]]) / count if count > 0
                                     else np.nan)


@numba.njit(cache=True, nogil=True)
def _window_bounds(d, origins, n_cs, half, step, j, u, lo, hi):  # pragma: no cover - compiled
    """The window ends on the distance axis ``d`` of the grids with centres
    ``c_k = (origins[g] + half) + step·k``, k < ``n_cs[g]`` (as
    :func:`railval.core.definitions.window_centres` forms them): into ``j``/``u`` the
    interval and offset of every window start, then every window end, grid after grid
    (``clip(searchsorted(d, x, "right") − 1, 0, n − 2)`` and ``x − d[j]``,
    :func:`railval.core.en_statistics._window_ends`); when ``lo`` is not empty, into
    ``lo``/``hi`` the first sample in and the first past the closed window
    ``[c − half, c + half]``, then the half-open one, grid after grid
    (``searchsorted`` left / right resp. left, :func:`railval.core.en_section._sample_bounds`).
    The centres increase, so each search walks on from the previous result (``a``: the
    first sample ≥ x, ``searchsorted`` left; ``b``: the first sample > x, right): the same
    comparisons decide, so the same indices."""
    n = d.shape[0]
    samples = lo.shape[0] > 0
    pos = 0
    s_pos = 0
    for g in range(origins.shape[0]):
        base = origins[g] + half
        k_n = n_cs[g]
        for e in range(2):
            a = 0
            b = 0
            for k in range(k_n):
                c = base + step * k
                x = c - half if e == 0 else c + half
                while a < n and d[a] < x:
                    a += 1
                if b < a:
                    b = a
                while b < n and d[b] <= x:
                    b += 1
                jj = min(max(b - 1, 0), n - 2)
                j[pos] = jj
                u[pos] = x - d[jj]
                pos += 1
                if samples:
                    if e == 0:
                        lo[s_pos + k] = a
                        lo[s_pos + k_n + k] = a
                    else:
                        hi[s_pos + k] = b
                        hi[s_pos + k_n + k] = a
        s_pos += 2 * k_n


@numba.njit(cache=True, nogil=True)
def _read_percentiles(stats, cols, mode, g, omg, out):  # pragma: no cover - compiled
    """``out[m, t]`` = percentile t of method m from the order statistics ``stats`` by the
    recipe of :func:`railval.core.definitions.percentile_recipe`: mode 0 the statistic
    ``stats[cols[m, t, 0]]`` itself (inverted CDF); else numpy's lerp of ``a`` =
    ``stats[cols[m, t, 0]]`` and ``b`` = ``stats[cols[m, t, 1]]`` with ``diff = b − a``:
    mode 1 ``a + diff·g``, mode 2 ``b − diff·omg`` (``omg = 1 − g``, formed by the caller)
    — :func:`railval.core.definitions.percentiles_from_order`, the same operations."""
    for m in range(cols.shape[0]):
        for t in range(cols.shape[1]):
            a = stats[cols[m, t, 0]]
            md = mode[m, t]
            if md == 0:
                out[m, t] = a
            else:
                b = stats[cols[m, t, 1]]
                diff = b - a
                if md == 2:
                    out[m, t] = b - diff * omg[m, t]
                else:
                    out[m, t] = a + diff * g[m, t]


@numba.njit(cache=True, nogil=True)
def _rows_percentiles(stats, cols, mode, g, omg, out):  # pragma: no cover - compiled
    """:func:`_read_percentiles` of every row of ``stats`` into ``out[:, r, :]``."""
    tmp = np.empty((cols.shape[0], cols.shape[1]))
    for r in range(stats.shape[0]):
        _read_percentiles(stats[r], cols, mode, g, omg, tmp)
        for m in range(cols.shape[0]):
            for t in range(cols.shape[1]):
                out[m, r, t] = tmp[m, t]


@numba.njit(cache=True, nogil=True)
def _sliding_means(at, n_cs, sampled, window_m, win_hi, means, bad, slot
                   ):  # pragma: no cover - compiled
    """The sliding means of every reading's grid and window, variant ``v = 3·grid + window``
    (window: interpolant, closed samples, half-open samples;
    :data:`railval.core.definitions.SLIDING_VARIANTS` order; only ``v = 0`` when
    ``sampled`` has no columns): the distance-weighted means ``(at[:, end] − at[:, start])
    / window_m`` (:func:`railval.core.en_statistics._means_from_integrals`) or the
    sample-window means (the columns of ``sampled``), row r of variant v into the first
    ``n_cs[grid]`` columns of row ``slot[v]·rows + r`` of ``means``. Where no sample lies on
    the upper end of a window of a grid (``win_hi`` of its closed and half-open windows
    equal; the lower ends are equal by construction, :func:`_window_bounds`) the half-open
    means are the closed ones: that variant gets the closed variant's slot and no rows of
    its own. ``bad[v, r]``: the row holds a non-finite mean. Returns the slots used."""
    rows = at.shape[0]
    n_win = 3 if sampled.shape[1] else 1
    a_pos = 0
    s_pos = 0
    used = 0
    for q in range(n_cs.shape[0]):
        k = n_cs[q]
        for w in range(n_win):
            v = q * n_win + w
            if w == 2:
                same = True
                for i in range(k):
                    if win_hi[s_pos - k + i] != win_hi[s_pos + i]:
                        same = False
                        break
                if same:
                    slot[v] = slot[v - 1]
                    for r in range(rows):
                        bad[v, r] = bad[v - 1, r]
                    s_pos += k
                    continue
            slot[v] = used
            for r in range(rows):
                out = means[used * rows + r]
                finite = True
                if w == 0:
                    for i in range(k):
                        x = (at[r, a_pos + k + i] - at[r, a_pos + i]) / window_m
                        out[i] = x
                        finite &= np.isfinite(x)
                else:
                    for i in range(k):
                        x = sampled[r, s_pos + i]
                        out[i] = x
                        finite &= np.isfinite(x)
                bad[v, r] = not finite
            used += 1
            if w > 0:
                s_pos += k
        a_pos += 2 * k
    return used


@numba.njit(cache=True, nogil=True)
def _row_extremes(x, n_lo, n_hi, lo, hi):  # pragma: no cover - compiled
    """The ``n_lo`` smallest samples of the row ``x`` (finite; ``n_lo``, ``n_hi`` ≤ len(x))
    into ``lo[:n_lo]``, its ``n_hi`` largest into ``hi[:n_hi]``, each ascending: one pass, a
    sample entering a buffer by insertion only when it passes its end (Knuth 1998 §5.3.3).
    ``lo[i]``, ``hi[i]``: the samples of 0-based ranks i and ``len(x) − n_hi + i`` — the
    numbers a sort puts there (only a zero's sign may differ where −0.0 and 0.0 tie)."""
    lo[:n_lo] = np.inf
    hi[:n_hi] = -np.inf
    t_lo, t_hi = (np.inf if n_lo else -np.inf), (-np.inf if n_hi else np.inf)
    last, n, i = n_lo - 1, x.shape[0], 0
    while i < n:
        stop = min(i + 8, n)
        if stop - i == 8:  # a block of 8 none of which enters a buffer is passed over
            a0 = min(min(x[i], x[i + 1]), min(x[i + 2], x[i + 3]))
            a1 = min(min(x[i + 4], x[i + 5]), min(x[i + 6], x[i + 7]))
            b0 = max(max(x[i], x[i + 1]), max(x[i + 2], x[i + 3]))
            b1 = max(max(x[i + 4], x[i + 5]), max(x[i + 6], x[i + 7]))
            if not (min(a0, a1) < t_lo or max(b0, b1) > t_hi):
                i = stop
                continue
        for e in range(i, stop):
            v = x[e]
            if v < t_lo:
                j = last
                while j > 0 and lo[j - 1] > v:
                    lo[j] = lo[j - 1]
                    j -= 1
                lo[j] = v
                t_lo = lo[last]
            if v > t_hi:
                j = 0
                while j < n_hi - 1 and hi[j + 1] < v:
                    hi[j] = hi[j + 1]
                    j += 1
                hi[j] = v
                t_hi = hi[0]
        i = stop


@numba.njit(cache=True, nogil=True)
def _end_counts(ranks, k):  # pragma: no cover - compiled
    """``(n_lo, n_hi)``: the smallest and largest samples of a row of ``k`` holding ranks."""
    n_lo = n_hi = 0
    for rk in ranks:
        n_lo, n_hi = (max(n_lo, rk + 1), n_hi) if 2 * rk < k else (n_lo, max(n_hi, k - rk))
    return n_lo, n_hi


@numba.njit(cache=True, nogil=True)
def _end_stats(x, ranks, n_lo, n_hi, lo, hi, out):  # pragma: no cover - compiled
    """``out[c]``: the sample of rank ``ranks[c]`` of ``x`` by :func:`_row_extremes` (``n_lo``,
    ``n_hi``: :func:`_end_counts`; ``lo``, ``hi`` at least that long)."""
    k = x.shape[0]
    _row_extremes(x, n_lo, n_hi, lo, hi)
    for c in range(ranks.shape[0]):
        rk = ranks[c]
        out[c] = lo[rk] if 2 * rk < k else hi[rk - (k - n_hi)]


@numba.njit(cache=True, nogil=True)
def _sliding_percentiles(means, n_cs, n_win, slot, ranks, n_ranks, cols, mode, g, omg, bad,
                         pct):  # pragma: no cover - compiled
    """``pct[v, m, r, :]``: the percentiles under each method of the sliding means of
    variant v, row r (the first ``n_cs[grid]`` values of row ``slot[v]·rows + r`` of
    ``means``, :func:`_sliding_means`, unsorted): the order statistics ``ranks[grid,
    :n_ranks[grid]]`` (near the two ends of the row: the 0.15 % and 99.85 % values) selected
    by :func:`_row_extremes`, read by the grid's recipe (:func:`_read_percentiles`); those
    of the variant before for one sharing its slot; 0 for a row marked in ``bad``."""
    rows = bad.shape[1]
    stats = np.empty(ranks.shape[1])
    tmp = np.empty((cols.shape[1], cols.shape[2]))
    for q in range(n_cs.shape[0]):
        k = n_cs[q]
        n_lo, n_hi = _end_counts(ranks[q, :n_ranks[q]], k)
        lo, hi = np.empty(max(n_lo, 1)), np.empty(max(n_hi, 1))
        for w in range(n_win):
            v = q * n_win + w
            shared = w > 0 and slot[v] == slot[v - 1]
            for r in range(rows):
                if not (shared or bad[v, r]):
                    _end_stats(means[slot[v] * rows + r, :k], ranks[q, :n_ranks[q]], n_lo,
                               n_hi, lo, hi, stats)
                    _read_percentiles(stats, cols[q], mode[q], g[q], omg[q], tmp)
                for m in range(pct.shape[1]):
                    for t in range(pct.shape[3]):
                        pct[v, m, r, t] = (pct[v - 1, m, r, t] if shared else 0.0 if bad[v, r]
                                           else tmp[m, t])


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _section_kernel(lp, sel, yq, sy, bp, cut0, cut1, wide0, ranks, derived, out_lp, out_bp,
                    out_rms, d, j, u, at, win_lo, win_hi, sampled, origins, n_cs, window_m,
                    step_m, recipe, bp_recipe, pct_lp, pct_bp, s_means, s_bad, s_slot,
                    s_ranks, s_n_ranks, s_recipe, s_pct):  # pragma: no cover - compiled
    """One section: the derived rows (:func:`_derive`), the order statistics ``ranks`` of
    the evaluated part of the low-pass rows ``sel`` and of the derived rows into ``out_lp``
    (in that order), those of ``bp_recipe[0]`` (the 0.15 %/99.85 % values' ranks,
    :func:`_end_stats`) of every band-pass row into ``out_bp``; their percentiles under each
    method into ``pct_lp``/``pct_bp`` (:func:`_rows_percentiles` by ``recipe``/``bp_recipe``
    (cols, mode, g, 1 − g)); the band-pass rows' rms (numpy's ``sqrt(mean(x²))``,
    :func:`pairwise_sum`). When ``n_cs`` is not empty: the window ends of the grids from
    ``origins`` on ``d[wide0:]`` (:func:`_window_bounds`: ``j``, ``u``; with ``win_lo``, the
    sample windows), the integrals and sample-window means of the derived rows
    (:func:`_derived_means`), the sliding means of every grid and window
    (:func:`_sliding_means`: ``s_means``/``s_bad``/``s_slot``) and their percentiles
    (:func:`_sliding_percentiles` by ``s_ranks``/``s_recipe``: ``s_pct``). Returns the Y/Q
    row with Q = 0 in the evaluated range (nothing selected), else
    −2 − (the slots of sliding means used), or −1 without sliding means."""
    zero = _derive(lp, yq, sy, cut0, cut1, wide0, derived)
    if zero >= 0:
        return zero
    k = ranks.shape[0]
    n = cut1 - cut0
    hist = np.empty(BUCKETS, np.int64)
    slot = np.empty(BUCKETS, np.int64)
    start = np.empty(k, np.int64)
    fill = np.empty(k, np.int64)
    cand = np.empty(n)
    bucket = np.empty(n, np.int64)
    n_sel = sel.shape[0]
    for s in range(n_sel):
        select_ranks(lp[sel[s], cut0:cut1], ranks, out_lp[s], hist, slot, start, fill, cand,
                     bucket)
    for r in range(derived.shape[0]):
        select_ranks(derived[r, cut0 - wide0:cut1 - wide0], ranks, out_lp[n_sel + r], hist,
                     slot, start, fill, cand, bucket)
    b_ranks, b_cols, b_mode, b_g, b_omg = bp_recipe
    n_lo, n_hi = _end_counts(b_ranks, n)
    lo, hi = np.empty(max(n_lo, 1)), np.empty(max(n_hi, 1))
    for r in range(bp.shape[0]):
        _end_stats(bp[r, cut0:cut1], b_ranks, n_lo, n_hi, lo, hi, out_bp[r])
        for i in range(n):
            cand[i] = bp[r, cut0 + i] * bp[r, cut0 + i]
        out_rms[r] = np.sqrt(pairwise_sum(cand, 0, n) / n)
    cols, mode, g, omg = recipe
    _rows_percentiles(out_lp, cols, mode, g, omg, pct_lp)
    _rows_percentiles(out_bp, b_cols, b_mode, b_g, b_omg, pct_bp)
    if n_cs.shape[0]:
        n_wide = derived.shape[1]
        _window_bounds(d[wide0:wide0 + n_wide], origins, n_cs, window_m / 2.0, step_m, j, u,
                       win_lo, win_hi)
        h = np.empty(n_wide - 1)
        for i in range(n_wide - 1):
            h[i] = d[wide0 + i + 1] - d[wide0 + i]
        _derived_means(derived, h, j, u, at, win_lo, win_hi, sampled)
        used = _sliding_means(at, n_cs, sampled, window_m, win_hi, s_means, s_bad, s_slot)
        s_cols, s_mode, s_g, s_omg = s_recipe
        _sliding_percentiles(s_means, n_cs, 3 if sampled.shape[1] else 1, s_slot, s_ranks,
                             s_n_ranks, s_cols, s_mode, s_g, s_omg, s_bad, s_pct)
        return -2 - used
    return -1


@numba.njit(cache=True, nogil=True)
def _welch_density(spec, first, n_seg, rows, even, out):  # pragma: no cover - compiled
    """The end of :func:`scipy.signal.welch` over the segment spectra of many blocks
    (:func:`railval.core.psd.welch_blocks`; ``spec`` row ``(first[j] + p)·rows + r`` = row r
    of block j, segment p < n_seg[j]): ``re² + im²``, doubled except DC and an even length's
    Nyquist bin (``·2``), then the mean over the segments as numpy takes it on scipy's layout
    (the segments' sum as numpy's pairwise sum: in order from 0.0 below 8 segments, else
    :func:`pairwise_sum`; ÷ their count; one segment as it is) — the same operations in the
    same order, so the same numbers."""
    n_f = spec.shape[1]
    last = n_f - 1 if even else n_f
    vals = np.empty(max(1, n_seg.max()))
    acc = np.empty(n_f)
    for j in range(n_seg.shape[0]):
        k = n_seg[j]
        for r in range(rows):
            o = out[j, r]
            if k == 1:
                x = spec[first[j] * rows + r]
                for q in range(n_f):
                    o[q] = x[q].real * x[q].real + x[q].imag * x[q].imag
                for q in range(1, last):
                    o[q] = o[q] * 2.0
            elif k < 8:
                acc[:] = 0.0
                for p in range(k):
                    x = spec[(first[j] + p) * rows + r]
                    acc[0] += x[0].real * x[0].real + x[0].imag * x[0].imag
                    for q in range(1, last):
                        acc[q] += (x[q].real * x[q].real + x[q].imag * x[q].imag) * 2.0
                    for q in range(last, n_f):
                        acc[q] += x[q].real * x[q].real + x[q].imag * x[q].imag
                for q in range(n_f):
                    o[q] = acc[q] / k
            else:
                for q in range(n_f):
                    for p in range(k):
                        x = spec[(first[j] + p) * rows + r, q]
                        v = x.real * x.real + x.imag * x.imag
                        if 0 < q < last:
                            v = v * 2.0
                        vals[p] = v
                    o[q] = pairwise_sum(vals, 0, k) / k
