"""Fast decode (db/codec.py, issue 26): the compiled plane join, the preallocated output
blocks and :func:`decode_many` on the row threads give exactly what an independent decoder
(``struct`` + :mod:`zlib` + :mod:`hashlib`, written here from the blob layout of the codec's
module docstring) gives; forged blobs are refused on every path; the verified-array cache
marks a first read, keeps the array at the second and answers the third."""

from __future__ import annotations

import hashlib
import struct
import zlib

import numpy as np
import pytest

from railval.core.errors import InvalidSignal
from railval.db import codec


@pytest.fixture(autouse=True)
def _fresh_cache():
    codec.VERIFIED.clear()
    yield
    codec.VERIFIED.clear()


def reference_decode(blob: bytes) -> tuple[np.ndarray, str]:
    """Independent decoder of codecs 0, 1 and 2 and the content hash (module docstring of
    db/codec.py): plain zlib, a Python loop over the planes, numpy transposes."""
    magic, kind, _level, dlen, ndim = struct.unpack_from("<4sBBBB", blob, 0)
    assert magic == b"RVA1"
    pos = 8
    dtype = np.dtype(blob[pos:pos + dlen].decode("ascii"))
    pos += dlen
    shape = struct.unpack_from(f"<{ndim}Q", blob, pos)
    pos += 8 * ndim
    size = int(np.prod(shape, dtype=np.int64))
    if kind == 0:
        raw = blob[pos:]
    elif kind == 1:
        raw = np.frombuffer(zlib.decompress(blob[pos:]), np.uint8).reshape(
            dtype.itemsize, size).T.tobytes()
    else:
        planes = []
        for _ in range(dtype.itemsize):
            flag, length = struct.unpack_from("<BI", blob, pos)
            pos += 5
            data = blob[pos:pos + length]
            pos += length
            planes.append(zlib.decompress(data) if flag else data)
        raw = np.array([np.frombuffer(p, np.uint8) for p in planes]).T.tobytes() if size else b""
    sha = hashlib.sha256(f"dtype={dtype.str};shape={'x'.join(map(str, shape))};".encode()
                         + raw).hexdigest()
    return np.frombuffer(raw, dtype).reshape(shape), sha


def measured_like(n: int, seed: int) -> np.ndarray:
    """A measured-like signal: compressible sign/exponent planes, noise in the low ones."""
    rng = np.random.default_rng(seed)
    return 40.0 + 5.0 * np.sin(np.arange(n) / 50.0) + rng.standard_normal(n)


def sample_items() -> list[tuple[bytes, str]]:
    arrays = [measured_like(3000, k) for k in range(9)]
    arrays += [np.arange(24, dtype=np.int64).reshape(2, 3, 4),  # 8-byte integers, 3-D
               np.linspace(0.0, 1.0, 500).astype("<f4"),  # 4-byte planes: numpy join
               np.zeros(0), np.array([np.nan, -0.0, np.inf]),
               np.frombuffer(np.random.default_rng(3).bytes(8 * 400), "<u8")]  # raw codec
    items = [codec.encode(a) for a in arrays]
    legacy = np.random.default_rng(7).standard_normal(700)  # codec 1, still decoded
    header = codec.encode(legacy)[0][:8 + 3 + 8]
    blob = (header[:4] + bytes([codec.CODEC_SHUFFLE_ZLIB]) + header[5:]
            + zlib.compress(legacy.view(np.uint8).reshape(-1, 8).T.tobytes()))
    return items + [(blob, codec.content_hash(legacy))]


@pytest.mark.parametrize("threads", ["1", "2"])
def test_decode_many_equals_the_independent_decoder(monkeypatch, threads):
    monkeypatch.setenv("RAILVAL_THREADS", threads)
    items = sample_items()
    assert {blob[4] for blob, _ in items} == {0, 1, 2}
    for verify in (True, False):
        got = codec.decode_many([(b, h if verify else None) for b, h in items])
        for (blob, sha), a in zip(items, got, strict=True):
            ref, ref_sha = reference_decode(blob)
            assert ref_sha == sha
            assert a.dtype == ref.dtype and a.shape == ref.shape
            assert a.tobytes() == ref.tobytes()
            assert a.flags.writeable and a.flags.c_contiguous


def test_plane_join_kernel_matches_numpy_on_every_byte():
    """Random bytes in every plane (not only float-like values), raw and inflated planes
    mixed: the compiled join must put byte k of element i where numpy's column copy does."""
    rng = np.random.default_rng(11)
    n = 1537
    planes = [rng.integers(0, 256, n, dtype=np.uint8).tobytes() for _ in range(8)]
    src = np.frombuffer(b"".join(planes[:5]), np.uint8)  # planes 0-4 "raw in the blob"
    inflated = planes[5:]
    offsets = [k * n for k in range(5)] + [-1 - k * n for k in range(3)]
    out = np.empty(n, "<f8")
    codec._fill_planes(out, src, inflated, offsets)
    expected = np.empty(n, "<f8")
    expected.view(np.uint8).reshape(n, 8)[:] = np.array(
        [np.frombuffer(p, np.uint8) for p in planes]).T
    assert out.tobytes() == expected.tobytes()
    swapped = offsets[:6] + [offsets[7], offsets[6]]  # a join that mixed up two planes
    codec._fill_planes(out, src, inflated, swapped)
    assert out.tobytes() != expected.tobytes()


def test_arrays_from_one_block_are_independent_and_writable():
    items = [codec.encode(measured_like(2000, k)) for k in range(6)]
    got = codec.decode_many(items)
    assert got[0].base is not None and got[0].base is got[5].base  # rows of one block
    got[0][:] = -1.0
    for (blob, _), a in zip(items[1:], got[1:], strict=True):
        assert a.tobytes() == reference_decode(blob)[0].tobytes()


def test_a_pooled_buffer_is_reused_only_when_no_array_refers_to_it(monkeypatch):
    monkeypatch.setattr(codec, "BLOCK_BYTES", 6 * 2000 * 8)
    monkeypatch.setattr(codec, "_BLOCKS", codec._BlockPool(2))
    items = [codec.encode(measured_like(2000, k)) for k in range(6)]
    others = [codec.encode(measured_like(2000, 10 + k)) for k in range(6)]
    first = codec.decode_many(items)
    second = codec.decode_many(others)
    assert not np.shares_memory(first[0].base, second[0].base)
    keep = first[3][100:200]  # a slice of one row still refers to the first buffer
    del first
    third = codec.decode_many(items)  # the first buffer is still in use: a fresh block
    assert not np.shares_memory(third[0].base, keep) and len(codec._BLOCKS._buffers) == 2
    assert keep.tobytes() == reference_decode(items[3][0])[0][100:200].tobytes()
    del keep, third
    fourth = codec.decode_many(others)  # now a pooled buffer is free again
    assert any(fourth[0].base is b for b in codec._BLOCKS._buffers)
    for (blob, _), a in zip(others, fourth, strict=True):
        assert a.tobytes() == reference_decode(blob)[0].tobytes()
    for (blob, _), a in zip(others, second, strict=True):  # untouched by the reuse
        assert a.tobytes() == reference_decode(blob)[0].tobytes()


@pytest.mark.parametrize("threads", ["1", "2"])
def test_decode_many_refuses_a_forged_blob_and_names_the_first(monkeypatch, threads):
    monkeypatch.setenv("RAILVAL_THREADS", threads)
    items = [codec.encode(measured_like(2000, k)) for k in range(12)]
    forged = codec.encode(measured_like(2000, 99) * 0.5)[0]  # valid blob, other samples
    bad = list(items)
    bad[7] = (forged, items[7][1])
    bad[9] = (items[9][0][:-3], items[9][1])  # truncated
    with pytest.raises(codec.BlobError, match="differs from the expected") as err:
        codec.decode_many(bad)
    assert err.value.index == 7 and isinstance(err.value, InvalidSignal)
    codec.decode_many(items)  # verified once: the forged blob is still refused
    with pytest.raises(codec.BlobError, match="differs from the expected"):
        codec.decode_many(bad)
    with pytest.raises(codec.BlobError, match="truncated") as err:
        codec.decode_many(bad[8:])
    assert err.value.index == 1


def test_cache_marks_the_first_read_keeps_the_second_answers_the_third(monkeypatch):
    a = measured_like(4000, 5)
    blob, sha = codec.encode(a)
    calls = []
    real = codec._hash_canonical
    monkeypatch.setattr(codec, "_hash_canonical", lambda x: calls.append(1) or real(x))
    first = codec.decode(blob, sha)
    assert calls == [1] and codec.VERIFIED.get(blob, sha) is None  # verified, array not kept
    assert codec.VERIFIED.size == len(blob)
    second = codec.decode(bytes(blob), sha)  # same bytes: not hashed again, array kept
    assert calls == [1] and codec.VERIFIED.size == len(blob) + a.nbytes
    second[0] = 1e9  # the caller's array, not the cache's
    third = codec.decode(blob, sha)
    assert calls == [1]
    for x in (first, third):
        assert x.tobytes() == a.tobytes()
    other = a.copy()
    other[3] += 1.0
    with pytest.raises(InvalidSignal, match="differs from the expected"):
        codec.decode(codec.encode(other)[0], sha)  # another blob under the verified hash


@pytest.mark.parametrize("backend", ["_libdeflate_inflate", "_isal_inflate", "_zlib_inflate"])
def test_every_inflate_backend_gives_the_same_arrays_and_refuses_corruption(monkeypatch,
                                                                               backend):
    if backend == "_libdeflate_inflate":
        pytest.importorskip("deflate")
    if backend == "_isal_inflate":
        pytest.importorskip("isal")
    monkeypatch.setattr(codec, "inflate", getattr(codec, backend))
    items = sample_items()
    for (blob, _), a in zip(items, codec.decode_many(items), strict=True):
        assert a.tobytes() == reference_decode(blob)[0].tobytes()
    blob, sha = items[0]
    corrupt = bytearray(blob)
    corrupt[-30] ^= 0xFF  # inside the last (zlib) plane
    with pytest.raises(InvalidSignal, match="decompress|differs from the expected|holds"):
        codec.decode(bytes(corrupt), sha)


def test_decode_many_of_nothing_and_of_one():
    assert codec.decode_many([]) == []
    blob, sha = codec.encode(np.arange(5.0))
    assert codec.decode_many([(blob, sha)])[0].tolist() == [0.0, 1.0, 2.0, 3.0, 4.0]
