"""The streaming filter kernel of core.filters gives the values of the kernel it replaced.

Two independent expectations: ``scipy.signal.sosfiltfilt`` (odd extension, steady-state
initial conditions, Gustafsson 1996) to 1e-12, and the previous kernel (a full-length
time-major buffer per block of 32 signals, the same recursion in the same order), copied
here as reference, bit for bit (docs/validation.md, Throughput).
"""

from __future__ import annotations

import numba
import numpy as np
import pytest
import scipy.signal

from railval.core import filters
from railval.core.filters import design, filtfilt_rows

FS = 500.0
BLOCK = 32


@numba.njit(cache=True)
def _ref_pass(sos, zi, ext, first, stop, step):
    """The previous ``_cascade_pass``: one in-place pass over ext[first:stop:step]."""
    n_sec = sos.shape[0]
    width = ext.shape[1]  # the kernel's block width (filters._BLOCK)
    z0 = np.empty((n_sec, width))
    z1 = np.empty((n_sec, width))
    for s in range(n_sec):
        for c in range(width):
            z0[s, c] = zi[s, 0] * ext[first, c]
            z1[s, c] = zi[s, 1] * ext[first, c]
    length = (stop - first) // step
    for s in range(n_sec):
        for k in range(length):
            row = ext[first + k * step]
            for c in range(width):
                x = row[c]
                y = sos[s, 0] * x + z0[s, c]
                z0[s, c] = sos[s, 1] * x - sos[s, 4] * y + z1[s, c]
                z1[s, c] = sos[s, 2] * x - sos[s, 5] * y
                row[c] = y


@numba.njit(cache=True)
def _ref_kernel(sos, zi, edge, data, out):
    """The previous ``_filtfilt_rows_kernel``: odd extension into a full-length time-major
    buffer, forward and backward pass over it, copied back."""
    n = data.shape[1]
    m = n + 2 * edge
    ext = np.zeros((m, BLOCK))
    for b in range(0, data.shape[0], BLOCK):
        nb = min(BLOCK, data.shape[0] - b)
        ext[:, :] = 0.0
        for c in range(nb):
            for i in range(edge):
                ext[i, c] = 2.0 * data[b + c, 0] - data[b + c, edge - i]
                ext[n + edge + i, c] = 2.0 * data[b + c, n - 1] - data[b + c, n - 2 - i]
            for i in range(n):
                ext[edge + i, c] = data[b + c, i]
        _ref_pass(sos, zi, ext, 0, m, 1)
        _ref_pass(sos, zi, ext, m - 1, -1, -1)
        for c in range(nb):
            for i in range(n):
                out[b + c, i] = ext[edge + i, c]


def reference(x, kind, order):
    d = design(FS, kind, order)
    x2 = np.atleast_2d(np.asarray(x, dtype=np.float64))
    out = np.empty_like(x2)
    _ref_kernel(d.sos, d.zi, d.edge, x2, out)
    return out[0] if np.ndim(x) == 1 else out


@pytest.mark.parametrize("kind", ["lowpass", "bandpass"])
@pytest.mark.parametrize("order", [1, 2, 3, 4, 5, 6])
@pytest.mark.parametrize("shape", [(1, 301), (31, 1001), (32, 1000), (45, 2999), (70, 777)])
def test_streaming_kernel_equals_previous_kernel_and_scipy(kind, order, shape):
    rng = np.random.default_rng(order * 1000 + shape[0])
    x = rng.standard_normal(shape) * 3.0 + np.linspace(0.0, 5.0, shape[1])
    got = filtfilt_rows(x, FS, kind, order)
    np.testing.assert_array_equal(got, reference(x, kind, order))
    ref = scipy.signal.sosfiltfilt(design(FS, kind, order).sos, x, axis=-1)
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12 * max(1.0, np.abs(ref).max()))
    # list input (rows read in place) and 1-D input give the same bits
    np.testing.assert_array_equal(filtfilt_rows(list(x), FS, kind, order), got)
    np.testing.assert_array_equal(filtfilt_rows(x[-1], FS, kind, order), got[-1])


def test_list_of_views_and_other_dtypes_equal_the_array():
    rng = np.random.default_rng(7)
    big = rng.standard_normal((40, 2 * 1500))
    rows = [big[i, ::2] for i in range(33)]  # strided views: copied to contiguous rows
    rows += [np.float32(1.0) * big[i, :1500].astype(np.float32) for i in range(33, 40)]
    arr = np.array([np.asarray(r, dtype=np.float64) for r in rows])
    np.testing.assert_array_equal(filtfilt_rows(rows, FS, "lowpass"), reference(arr, "lowpass", 4))
    fortran = np.asfortranarray(arr)
    np.testing.assert_array_equal(filtfilt_rows(fortran, FS, "bandpass"),
                                  reference(arr, "bandpass", 4))


def test_both_threads_give_the_bits_of_one(monkeypatch):
    x = np.random.default_rng(3).standard_normal((130, 2500))
    monkeypatch.setenv("RAILVAL_THREADS", "1")
    one = filtfilt_rows(list(x), FS, "bandpass", 4)
    monkeypatch.setenv("RAILVAL_THREADS", "2")
    np.testing.assert_array_equal(filtfilt_rows(list(x), FS, "bandpass", 4), one)
    np.testing.assert_array_equal(one, reference(x, "bandpass", 4))


@pytest.mark.parametrize("wrong", ["padding", "start state", "one ulp"])
def test_a_wrong_kernel_would_be_caught(wrong):
    """The exact comparison tells a kernel with one sample less of padding, a start state off
    by one part in 1e15, or one output off by one ulp."""
    x = np.random.default_rng(5).standard_normal((33, 700))
    d = design(FS, "lowpass", 4)
    src = x.__array_interface__["data"][0] + x.strides[0] * np.arange(33, dtype=np.intp)
    got = np.empty_like(x)
    edge, zi = d.edge, d.zi
    if wrong == "padding":
        edge = d.edge - 1
    elif wrong == "start state":
        zi = zi * (1.0 + 1e-15)
    filters._filtfilt_kernel(d.sos, zi, edge, src, got, 0, 33)
    if wrong == "one ulp":
        got[32, 350] = np.nextafter(got[32, 350], np.inf)
    assert not np.array_equal(got, reference(x, "lowpass", 4))
    np.testing.assert_array_equal(filtfilt_rows(x, FS, "lowpass", 4), reference(x, "lowpass", 4))


def test_cascade_pass_kept_for_the_bench():
    d = design(FS, "lowpass", 4)
    ext = np.random.default_rng(1).standard_normal((600, filters._BLOCK))
    ref = ext.copy()
    filters._cascade_pass(d.sos, d.zi, ext, 0, ext.shape[0], 1)
    _ref_pass(d.sos, d.zi, ref, 0, ref.shape[0], 1)
    np.testing.assert_array_equal(ext, ref)
    filters._cascade_pass(d.sos, d.zi, ext, ext.shape[0] - 1, -1, -1)  # backward, as sosfiltfilt
    _ref_pass(d.sos, d.zi, ref, ref.shape[0] - 1, -1, -1)
    np.testing.assert_array_equal(ext, ref)
    x = np.random.default_rng(2).standard_normal((600, filters._BLOCK))
    y = x.copy()
    filters._cascade_pass(d.sos, d.zi, y, 0, y.shape[0], 1)
    ref_y = scipy.signal.sosfilt(d.sos, x, axis=0, zi=d.zi[:, :, None] * x[0])[0]
    np.testing.assert_allclose(y, ref_y, rtol=0, atol=1e-12)
