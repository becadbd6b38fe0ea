"""The filter kernel of core.filters against the kernel it replaced (branch filt2).

The previous kernel (tile-by-tile forward pass into a time-major buffer, each element moved
by a scalar transposing copy into the buffer and out of it) is copied here unchanged as the
reference: the new kernel must give its values bit for bit (the recursion is the same, in the
same order; only the copies changed), and ``scipy.signal.sosfiltfilt`` is the independent
expectation (Gustafsson 1996, odd extension, docs/validation.md, Throughput).

Run as a script for the figures: ``python -m tests.test_filt2_copies`` (from the repository
root) prints CPU and wall ns per sample of the previous and the current kernel, alternating,
in one process (272 low-pass and 68 band-pass rows × 20 000 samples, one and two threads)
with the load average.
"""

from __future__ import annotations

import numba
import numba.extending
import numpy as np
import pytest
import scipy.signal

from railval.core import filters
from railval.core.errors import InvalidSignal
from railval.core.filters import design, filtfilt_rows

# ---- the previous kernel (core/filters.py before branch filt2), unchanged ----------------
_BLOCK = 32


#: samples per chunk of :func:`_cascade_pass`: all sections run over one chunk (32 signals ×
#: 256 samples × 8 B = 64 KiB, held in the core's cache) before the next
_CHUNK = 256
#: samples per tile of :func:`_filter_block`: 32 signals × 64 samples × 8 B = 16 KiB, held in
#: the L1 cache while it is transposed and every section runs over it (64 measured faster
#: than 32, 128 and 256 on the bench machine, 2026-11-26)
_TILE = 64


@numba.njit(cache=True, nogil=True)
def _cascade_pass(sos, zi, ext, first, stop, step):  # pragma: no cover - compiled
    """One in-place pass of the cascade over ``ext[first:stop:step]`` (shape ``(m, _BLOCK)``,
    time-major), every section starting in the steady state ``zi`` scaled by the first sample
    of the pass (``scipy.signal.sosfilt`` with ``zi·x0``), the sections running one after
    another over chunks of ``_CHUNK`` samples (:func:`_sections_over`). Used by the machine
    limits of ``app/bench/bench_en.py``."""
    z0 = np.empty((sos.shape[0], _BLOCK))
    z1 = np.empty((sos.shape[0], _BLOCK))
    _start_state(zi, ext[first], z0, z1)
    length = (stop - first) // step
    for k0 in range(0, length, _CHUNK):
        k1 = min(k0 + _CHUNK, length)
        _sections_over(sos, z0, z1, ext, first + k0 * step, first + k1 * step, step)


@numba.njit(cache=True, nogil=True, inline="always")
def _start_state(zi, x0, z0, z1):  # pragma: no cover - compiled
    """Steady-state start of every section for the first samples ``x0`` (``zi·x0``, scipy's
    ``sosfiltfilt``)."""
    for s in range(zi.shape[0]):
        for c in range(_BLOCK):
            z0[s, c] = zi[s, 0] * x0[c]
            z1[s, c] = zi[s, 1] * x0[c]


@numba.njit(cache=True, nogil=True)
def _sections_over(sos, z0, z1, ext, first, stop, step):  # pragma: no cover - compiled
    """Every section in turn over ``ext[first:stop:step]`` (time-major, ``_BLOCK`` signals),
    in place, continuing from and updating the section states ``z0``, ``z1``. The recursion is
    scipy's sosfilt (direct form II transposed, the same operations in the same order); the
    inner loop runs over the ``_BLOCK`` independent signals, so it is vectorised and the
    latency of each recursion is hidden by the others. The states are copied into local
    arrays, known not to alias ``ext`` (measured 0.46 instead of 0.69 ns per sample and
    section when working on ``z0``, ``z1`` directly)."""
    zs0 = np.empty(_BLOCK)
    zs1 = np.empty(_BLOCK)
    length = (stop - first) // step
    for s in range(sos.shape[0]):
        b0, b1, b2, a1, a2 = sos[s, 0], sos[s, 1], sos[s, 2], sos[s, 4], sos[s, 5]
        zs0[:] = z0[s]
        zs1[:] = z1[s]
        for k in range(length):
            row = ext[first + k * step]
            for c in range(_BLOCK):
                x = row[c]
                y = b0 * x + zs0[c]
                zs0[c] = b1 * x - a1 * y + zs1[c]
                zs1[c] = b2 * x - a2 * y
                row[c] = y
        z0[s] = zs0
        z1[s] = zs1


@numba.njit(cache=True, nogil=True, inline="always")
def _as_row(address, n):  # pragma: no cover - compiled
    """The float64 row of ``n`` samples at ``address`` (see :func:`_row_addresses`)."""
    return numba.carray(_address_to_pointer(address), (n,))


@numba.extending.intrinsic
def _address_to_pointer(typingctx, address):
    """A ``float64*`` from an integer address (LLVM ``inttoptr``)."""
    sig = numba.types.CPointer(numba.types.float64)(numba.types.intp)

    def codegen(context, builder, signature, args):
        return builder.inttoptr(args[0], context.get_value_type(signature.return_type))

    return sig, codegen


@numba.njit(cache=True, nogil=True)
def _filter_block(sos, zi, edge, src, out, b, nb, tile, fwd, z0, z1):  # pragma: no cover
    """Forward–backward filter of the ``nb`` (≤ ``_BLOCK``) rows at addresses ``src[b:b + nb]``
    into ``out[b:b + nb]``, tile by tile: the forward pass over the odd extension of ``edge``
    samples at the start (in ``tile``, scipy's ``padtype="odd"``), over the signal (each tile
    transposed into its place in the time-major ``fwd`` and filtered there, in the cache) and
    over the end extension (in ``tile``); then the backward pass from the steady state of the
    last forward output over the end extension and over ``fwd`` from its end, each tile
    transposed into ``out`` once filtered. Every sample is read once from the rows, written
    and read once in ``fwd`` and written once to ``out`` (32 bytes). The backward outputs over
    the start extension are never used, so that part is not run. Columns ``nb:`` hold values
    of an earlier block (or zeros): filtered, never written out."""
    n = out.shape[1]
    for c in range(nb):  # start extension, forward
        row = _as_row(src[b + c], n)
        for i in range(edge):
            tile[i, c] = 2.0 * row[0] - row[edge - i]
    _start_state(zi, tile[0], z0, z1)
    _sections_over(sos, z0, z1, tile, 0, edge, 1)
    for t0 in range(0, n, _TILE):  # the signal, forward
        t1 = min(t0 + _TILE, n)
        for c in range(nb):
            row = _as_row(src[b + c], n)
            for i in range(t0, t1):
                fwd[i, c] = row[i]
        _sections_over(sos, z0, z1, fwd, t0, t1, 1)
    for c in range(nb):  # end extension, forward
        row = _as_row(src[b + c], n)
        for i in range(edge):
            tile[i, c] = 2.0 * row[n - 1] - row[n - 2 - i]
    _sections_over(sos, z0, z1, tile, 0, edge, 1)
    _start_state(zi, tile[edge - 1], z0, z1)  # backward: from the last forward output
    _sections_over(sos, z0, z1, tile, edge - 1, -1, -1)
    for t1 in range(n, 0, -_TILE):  # the signal, backward
        t0 = max(t1 - _TILE, 0)
        _sections_over(sos, z0, z1, fwd, t1 - 1, t0 - 1, -1)
        for c in range(nb):
            dst = out[b + c]
            for i in range(t0, t1):
                dst[i] = fwd[i, c]


@numba.njit(cache=True, nogil=True)
def _filtfilt_kernel(sos, zi, edge, src, out, r0, r1):  # pragma: no cover - compiled
    """:func:`_filtfilt_into` with a time-major buffer of its own (``n × _BLOCK`` float64)."""
    _filtfilt_into(sos, zi, edge, src, out, r0, r1, np.empty((out.shape[1], _BLOCK)))


@numba.njit(cache=True, nogil=True)
def _filtfilt_into(sos, zi, edge, src, out, r0, r1, fwd):  # pragma: no cover - compiled
    """Forward–backward filter the rows ``r0:r1`` (addresses ``src``, ``out.shape[1]`` samples
    each) into ``out``, ``_BLOCK`` rows at a time (:func:`_filter_block`); ``fwd`` (shape
    ``(n, _BLOCK)``, any content) is the time-major buffer of the forward pass, reused from
    block to block."""
    tile = np.empty((edge, _BLOCK))
    if r1 - r0 < _BLOCK:  # a first, partial block: its unused columns start at zero
        tile[:, :] = 0.0
        fwd[:, :] = 0.0
    z0 = np.empty((sos.shape[0], _BLOCK))
    z1 = np.empty((sos.shape[0], _BLOCK))
    for b in range(r0, r1, _BLOCK):
        _filter_block(sos, zi, edge, src, out, b, min(_BLOCK, r1 - b), tile, fwd, z0, z1)


#: the outputs of :func:`filtfilt_rows` (docs/validation.md, Throughput): mapped once and


# ---- tests ----------------------------------------------------------------------------------

FS = 500.0


def _previous(x: np.ndarray, d) -> np.ndarray:
    """``x`` filtered by the previous kernel (32 rows in lockstep, scalar copies)."""
    x = np.ascontiguousarray(x, dtype=np.float64)
    src = x.__array_interface__["data"][0] + x.strides[0] * np.arange(x.shape[0], dtype=np.intp)
    out = np.empty_like(x)
    _filtfilt_kernel(d.sos, d.zi, d.edge, src, out, 0, x.shape[0])
    return out


@pytest.mark.parametrize("kind, order", [("lowpass", 4), ("bandpass", 4), ("lowpass", 2),
                                         ("bandpass", 3)])
@pytest.mark.parametrize("rows, n", [(1, 100), (7, 1000), (16, 777), (17, 640), (33, 1301),
                                     (68, 2000), (100, 129)])
def test_current_kernel_equals_previous_bit_for_bit_and_scipy(kind, order, rows, n):
    d = design(FS, kind, order)
    x = np.random.default_rng(rows * 1000 + n).standard_normal((rows, n)) * 50.0 + 3.0
    if n <= d.edge:  # shorter than the padding: refused, as scipy refuses it
        with pytest.raises(InvalidSignal, match="must exceed the filter padding"):
            filtfilt_rows(x, FS, kind, order)
        with pytest.raises(ValueError):
            scipy.signal.sosfiltfilt(d.sos, x, axis=-1)
        return
    got = filtfilt_rows(x, FS, kind, order)
    np.testing.assert_array_equal(got, _previous(x, d))
    ref = scipy.signal.sosfiltfilt(d.sos, x, axis=-1)
    assert np.max(np.abs(got - ref)) <= 1e-12 * np.max(np.abs(ref))


def test_list_of_rows_equals_previous_bit_for_bit():
    d = design(FS, "lowpass")
    rows = [np.random.default_rng(i).standard_normal(900) for i in range(21)]
    np.testing.assert_array_equal(filtfilt_rows(rows, FS, "lowpass"), _previous(np.array(rows), d))


@pytest.mark.parametrize("nb", [1, 8, 11, 16])
def test_rows_into_tile_is_the_transpose(nb):
    """The copy-in helper puts row c, samples t0:t1, into column c of the time-major buffer and
    touches nothing else (a wrong row, sample or column would change the sentinel layout)."""
    n, t0, t1 = 200, 64, 128 + 5
    x = np.arange(40 * n, dtype=np.float64).reshape(40, n)
    src = x.__array_interface__["data"][0] + x.strides[0] * np.arange(40, dtype=np.intp)
    fwd = np.full((n, filters._BLOCK), -1.0)
    filters._rows_into_tile(src, 3, nb, n, fwd, t0, t1)
    expected = np.full_like(fwd, -1.0)
    expected[t0:t1, :nb] = x[3:3 + nb, t0:t1].T
    np.testing.assert_array_equal(fwd, expected)


@pytest.mark.parametrize("nb", [1, 8, 13, 16])
def test_tile_into_rows_is_the_transpose(nb):
    n, t0, t1 = 150, 3, 67
    fwd = np.arange(n * filters._BLOCK, dtype=np.float64).reshape(n, filters._BLOCK)
    out = np.full((30, n), -1.0)
    filters._tile_into_rows(fwd, out, 5, nb, t0, t1)
    expected = np.full_like(out, -1.0)
    expected[5:5 + nb, t0:t1] = fwd[t0:t1, :nb].T
    np.testing.assert_array_equal(out, expected)


# ---- figures (run as a script) --------------------------------------------------------------
def _run(into, block, d, src, out, fwds, threads):
    """Rows of ``src`` into ``out`` with the kernel ``into`` on one or two threads."""
    import threading

    n_rows = src.shape[0]
    if threads == 1:
        into(d.sos, d.zi, d.edge, src, out, 0, n_rows, fwds[0])
        return
    half = (n_rows // 2 + block - 1) // block * block
    t = threading.Thread(target=into, args=(d.sos, d.zi, d.edge, src, out, 0, half, fwds[0]))
    t.start()
    into(d.sos, d.zi, d.edge, src, out, half, n_rows, fwds[1])
    t.join()


def _bench(reps: int = 6) -> None:
    """Previous and current kernel alternating in one process: CPU and wall ns per sample."""
    import os
    import time

    kernels = {"previous": (_filtfilt_into, _BLOCK), "current": (filters._filtfilt_into,
                                                                 filters._BLOCK)}
    for kind, rows in (("lowpass", 272), ("bandpass", 68)):
        d = design(FS, kind)
        x = np.random.default_rng(0).standard_normal((rows, 20_000))
        src = x.__array_interface__["data"][0] + x.strides[0] * np.arange(rows, dtype=np.intp)
        outs = {k: np.empty_like(x) for k in kernels}
        fwds = {k: [np.zeros((20_000, b)), np.zeros((20_000, b))] for k, (_, b) in kernels.items()}
        for threads in (1, 2):
            res = {k: [] for k in kernels}
            for r in range(reps + 1):  # the first round compiles and warms
                for k, (into, block) in kernels.items():
                    c0, w0 = time.process_time(), time.perf_counter()
                    _run(into, block, d, src, outs[k], fwds[k], threads)
                    c1, w1 = time.process_time(), time.perf_counter()
                    if r:
                        res[k].append(((c1 - c0) / x.size * 1e9, (w1 - w0) / x.size * 1e9))
            assert np.array_equal(outs["previous"], outs["current"])
            for k, v in res.items():
                a = np.array(v)
                print(f"{kind:8s} {rows:3d} rows, {threads} thread(s), {k:8s}: CPU ns/sample "
                      f"median {np.median(a[:, 0]):.2f} min {a[:, 0].min():.2f}; wall median "
                      f"{np.median(a[:, 1]):.2f} min {a[:, 1].min():.2f}; "
                      f"load {os.getloadavg()[0]:.2f}", flush=True)


if __name__ == "__main__":  # the module under its package name, as the kernels' cache knows it
    import importlib

    importlib.import_module("tests.test_filt2_copies")._bench()
