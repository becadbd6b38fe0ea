"""BufferPool (core/buffers.py) and the pooled outputs of filtfilt_rows (core/filters.py).

Expectations are independent of the pool: values against scipy.signal.sosfiltfilt and
against copies taken before the pool could reuse anything; sharing of memory by
numpy.shares_memory."""

import threading

import numpy as np
import pytest
import scipy.signal

from railval.core import filters
from railval.core.buffers import BufferPool
from railval.core.filters import design, filtfilt_rows

FS = 500.0
MB = 1 << 20


def reference(x, kind):
    return scipy.signal.sosfiltfilt(design(FS, kind, 4).sos, x, axis=-1)


def test_a_free_buffer_is_handed_out_again():
    pool = BufferPool(keep=2, max_bytes=8 * MB, min_bytes=MB)
    a = pool.take((200, 1000))
    address = a.ctypes.data
    del a
    b = pool.take((200, 1000))
    assert b.ctypes.data == address and b.shape == (200, 1000) and b.dtype == np.float64
    assert b.flags.c_contiguous and b.flags.writeable and len(pool._buffers) == 1


def _part_of(a, what):
    if what == "row":
        return a[7]
    if what == "slice":
        return a[7, 100:300]
    if what == "view":
        return a.view(np.int64)[7]
    if what == "transpose":
        return a.T[:, 7]
    return memoryview(a[7])


@pytest.mark.parametrize("keep_what", ["row", "slice", "view", "transpose", "memoryview"])
def test_a_buffer_is_never_handed_out_while_an_array_refers_to_it(keep_what):
    pool = BufferPool(keep=2, max_bytes=8 * MB, min_bytes=MB)
    a = pool.take((200, 1000))
    a[:] = np.arange(200 * 1000).reshape(200, 1000)
    kept = _part_of(a, keep_what)
    expected = np.array(kept, copy=True)
    del a
    b = pool.take((200, 1000))
    c = pool.take((200, 1000))  # the pool is full (keep=2) and nothing is free: a fresh array
    for x in (b, c):
        x[:] = -1.0
        assert not np.shares_memory(x, np.asarray(kept))
    np.testing.assert_array_equal(np.asarray(kept), expected)
    assert len(pool._buffers) == 2 and c.base is None


def test_requests_outside_the_range_or_overaligned_are_plain_arrays():
    pool = BufferPool(keep=2, max_bytes=8 * MB, min_bytes=MB)
    small, large = pool.take((100,)), pool.take((2 * MB,))
    assert small.base is None and large.base is None and not pool._buffers
    odd = pool.take((MB // 16,), np.dtype((np.void, 32)))  # dtype alignment 1: served
    del odd
    assert len(pool._buffers) == 1


def test_sized_buffers_follow_the_requests():
    pool = BufferPool(keep=2, max_bytes=64 * MB, min_bytes=MB)
    a = pool.take((3 * MB // 8,), np.float64)  # 3 MB
    size, address = pool._buffers[0].nbytes, pool._buffers[0].ctypes.data  # no reference kept
    assert 3 * MB <= size <= 3 * MB * 9 // 8 and a.ctypes.data == address
    del a
    b = pool.take((int(2.5 * MB),), np.uint8)  # more than half of it: the same buffer
    assert b.ctypes.data == address
    del b
    c = pool.take((MB,), np.uint8)  # a third of it: a second, smaller buffer
    assert c.ctypes.data != address and len(pool._buffers) == 2
    assert sorted(x.nbytes for x in pool._buffers) == [MB, size]
    d = pool.take((40 * MB,), np.uint8)  # none fits, pool full: the idle one is replaced
    assert len(pool._buffers) == 2 and not np.shares_memory(c, d)
    assert sorted(x.nbytes for x in pool._buffers) == [MB, 40 * MB]
    assert any(np.shares_memory(d, x) for x in pool._buffers)


def test_the_buffers_together_stay_below_the_total():
    pool = BufferPool(keep=4, max_bytes=8 * MB, min_bytes=MB, max_total_bytes=10 * MB)
    a = pool.take((6 * MB,), np.uint8)
    b = pool.take((3 * MB,), np.uint8)  # 9 MB kept
    c = pool.take((2 * MB,), np.uint8)  # would make 11 MB while both are in use: plain
    assert c.base is None and sum(x.nbytes for x in pool._buffers) == 9 * MB
    del a, c
    d = pool.take((5 * MB // 2,), np.uint8)  # the idle 6 MB buffer is dropped for room
    assert sorted(x.nbytes for x in pool._buffers) == [5 * MB // 2, 3 * MB]
    assert not np.shares_memory(b, d)


def test_fixed_buffers_serve_every_size_in_range():
    pool = BufferPool(keep=1, max_bytes=4 * MB, min_bytes=MB, fixed=True)
    a = pool.take((MB,), np.uint8)
    assert pool._buffers[0].nbytes == 4 * MB
    del a
    b = pool.take((4 * MB,), np.uint8)
    assert np.shares_memory(b, pool._buffers[0])


def test_threads_never_share_a_buffer():
    pool = BufferPool(keep=3, max_bytes=8 * MB, min_bytes=MB)
    errors: list[str] = []

    def work(k):
        for i in range(200):
            a = pool.take((MB // 8 + 1000 * (i % 3),))
            a[:] = k
            if not (a == k).all():  # another thread wrote into the same memory
                errors.append(f"thread {k} step {i}")
            del a

    threads = [threading.Thread(target=work, args=(k,)) for k in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors and len(pool._buffers) <= 3


def test_filter_output_kept_from_an_earlier_call_is_not_overwritten():
    rng = np.random.default_rng(11)
    x1, x2 = rng.standard_normal((70, 5000)), rng.standard_normal((70, 5000))  # 2.8 MB
    first = filtfilt_rows(x1, FS, "lowpass")
    row = first[40]
    part = first[3, 1000:2000]
    del first
    second = filtfilt_rows(x2, FS, "lowpass")
    assert not np.shares_memory(second, row) and not np.shares_memory(second, part)
    ref1 = reference(x1, "lowpass")
    np.testing.assert_array_equal(row, ref1[40])
    np.testing.assert_array_equal(part, ref1[3, 1000:2000])
    np.testing.assert_array_equal(second, reference(x2, "lowpass"))


def test_filter_outputs_reuse_the_memory_of_dropped_results():
    rng = np.random.default_rng(12)
    x = rng.standard_normal((40, 6000))  # 1.9 MB: above the pool's 1 MB
    first = filtfilt_rows(list(x), FS, "bandpass")
    address = first.ctypes.data
    assert any(np.shares_memory(first, b) for b in filters._OUTPUTS._buffers)
    del first
    again = filtfilt_rows(list(x[::-1]), FS, "bandpass")
    assert again.ctypes.data == address
    np.testing.assert_array_equal(again, reference(x[::-1], "bandpass"))
    one = filtfilt_rows(x[5], FS, "lowpass")  # 1-D: a row of a fresh (small) array
    np.testing.assert_array_equal(one, reference(x[5], "lowpass"))


@pytest.mark.parametrize("rows", [5, 33, 70])
def test_stale_forward_buffers_do_not_reach_the_output(rows):
    """The pooled forward-pass buffer holds an earlier call's values (here NaN); outputs are
    the bits of scipy's all the same (full blocks, a partial last block, a lone partial one)."""
    n = 9000  # 9000 × 32 × 8 B = 2.3 MB forward buffer: pooled
    bad = np.full((64, n), np.nan)
    poisoned = filtfilt_rows(bad, FS, "lowpass")
    assert np.isnan(poisoned).all()
    del poisoned
    x = np.random.default_rng(rows).standard_normal((rows, n))
    np.testing.assert_array_equal(filtfilt_rows(x, FS, "lowpass"), reference(x, "lowpass"))
    np.testing.assert_array_equal(filtfilt_rows(x, FS, "bandpass"), reference(x, "bandpass"))


def test_a_pool_handing_out_a_used_buffer_would_be_caught(monkeypatch):
    """If the pool ignored live references, the kept row of the first result would change."""

    class Careless(BufferPool):
        def _idle(self):
            return list(range(len(self._buffers)))

    monkeypatch.setattr(filters, "_OUTPUTS", Careless(keep=1, max_bytes=64 * MB, min_bytes=MB))
    rng = np.random.default_rng(13)
    x1, x2 = rng.standard_normal((40, 6000)), rng.standard_normal((40, 6000))
    row = filtfilt_rows(x1, FS, "lowpass")[0]
    filtfilt_rows(x2, FS, "lowpass")
    assert not np.array_equal(row, reference(x1, "lowpass")[0])
