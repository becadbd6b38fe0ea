"""The verified-array cache of the codec (db/codec.py, ``VERIFIED``): a blob decoded and
verified once is not decoded again in the process, the first read is always verified, and a
blob that differs from the one verified is decoded and verified again (issue 26)."""

from __future__ import annotations

import numpy as np
import pytest

from railval.core.errors import InvalidSignal
from railval.db import codec


@pytest.fixture(autouse=True)
def _fresh_cache():
    codec.VERIFIED.clear()
    yield
    codec.VERIFIED.clear()


def test_second_verified_decode_comes_from_the_cache():
    a = np.random.default_rng(0).standard_normal(5000)
    blob, sha = codec.encode(a)
    hits = codec.VERIFIED.hits
    first = codec.decode(blob, sha)
    assert codec.VERIFIED.hits == hits
    second = codec.decode(bytes(blob), sha)  # an equal blob read again (another bytes object)
    assert codec.VERIFIED.hits == hits + 1
    np.testing.assert_array_equal(first, a)
    np.testing.assert_array_equal(second, a)
    second[0] = 99.0  # the caller's copy: the cache keeps the verified samples
    np.testing.assert_array_equal(codec.decode(blob, sha), a)
    codec.decode(blob)  # without an expected hash the cache is not used
    assert codec.VERIFIED.hits == hits + 2


def test_first_read_is_verified_and_a_changed_blob_is_verified_again():
    a = np.arange(3000, dtype=np.float64)
    blob, sha = codec.encode(a)
    with pytest.raises(InvalidSignal, match="content hash"):
        codec.decode(blob, "0" * 64)  # never seen: decoded and checked
    codec.decode(blob, sha)
    b = a.copy()
    b[17] = -1.0
    other, _ = codec.encode(b)
    hits = codec.VERIFIED.hits
    with pytest.raises(InvalidSignal, match="content hash"):
        codec.decode(other, sha)  # same expected hash, other bytes: no hit, the check fails
    assert codec.VERIFIED.hits == hits


def test_the_cache_keeps_to_its_limit():
    cache = codec.VerifiedCache(3 * 8000 + 3 * 8100)
    for k in range(10):
        a = np.full(1000, float(k))
        blob, sha = codec.encode(a)
        cache.put(blob, sha, a)
        assert cache.size <= cache.limit_bytes
    assert cache.get(blob, sha) is not None
