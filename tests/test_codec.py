"""Array codec: exact round trip, hash over values (not compression), corrupt input rejected."""

from __future__ import annotations

import hashlib
import zlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from railval.core.errors import InvalidSignal
from railval.db import codec


@pytest.mark.parametrize("dtype", ["<f8", "<f4", "<i8", "<i4", "<i2", "i1", "<u4", "u1", "?"])
def test_round_trip_is_exact(dtype):
    rng = np.random.default_rng(1)
    a = (rng.standard_normal(1000) * 100).astype(dtype)
    blob, sha = codec.encode(a)
    b = codec.decode(blob, expected_sha=sha)
    assert b.dtype == a.dtype and b.shape == a.shape
    assert a.tobytes() == b.tobytes()


def test_hash_is_sha256_of_canonical_header_and_bytes():
    a = np.linspace(0.0, 1.0, 7)
    expected = hashlib.sha256(b"dtype=<f8;shape=7;" + a.astype("<f8").tobytes()).hexdigest()
    assert codec.encode(a)[1] == expected
    assert codec.content_hash(a) == expected


def test_hash_does_not_depend_on_byte_order_layout_or_compression():
    a = np.random.default_rng(2).standard_normal((40, 3))
    sha = codec.encode(a)[1]
    assert codec.encode(a.astype(">f8"))[1] == sha  # big-endian input, same values
    assert codec.encode(np.asfortranarray(a))[1] == sha  # memory layout
    assert codec.encode(a, level=9)[1] == sha  # compression level
    assert codec.encode(a.astype("<f4"))[1] != sha  # dtype is part of the identity


def test_noise_planes_are_stored_raw_and_exponent_planes_compressed():
    a = 77.0 + np.random.default_rng(4).standard_normal(5000)
    blob, sha = codec.encode(a)
    assert blob[4] == codec.CODEC_PLANES
    assert len(blob) < 0.85 * a.nbytes  # sign/exponent/high mantissa planes shrink
    assert np.array_equal(codec.decode(blob, sha), a)


def test_incompressible_data_falls_back_to_raw_and_still_decodes():
    a = np.frombuffer(np.random.default_rng(3).bytes(8 * 500), dtype="<u8")
    blob, sha = codec.encode(a)
    assert blob[4] == codec.CODEC_RAW
    assert np.array_equal(codec.decode(blob, sha), a)


def test_smooth_signal_compresses():
    # a 16-bit ADC record scaled to physical units: few distinct exponent/mantissa bytes
    t = np.arange(20000) / 200.0
    a = np.round(np.sin(t) * 2**15) * (50.0 / 2**15)
    blob, _ = codec.encode(a)
    assert len(blob) < 0.5 * a.nbytes


def test_nan_and_inf_round_trip_bit_exact_unless_rejected():
    a = np.array([1.0, np.nan, np.inf, -np.inf, -0.0])
    blob, sha = codec.encode(a)
    assert codec.decode(blob, sha).tobytes() == a.tobytes()
    with pytest.raises(InvalidSignal, match="non-finite value at flat index 1"):
        codec.encode(a, allow_nonfinite=False)


@pytest.mark.parametrize("bad", [np.array(["a", "b"]), np.array([1, None], dtype=object),
                                 np.array([1 + 2j])])
def test_non_numeric_dtypes_rejected(bad):
    with pytest.raises(InvalidSignal, match="not storable"):
        codec.encode(bad)


def test_empty_and_multidimensional_arrays():
    for a in (np.zeros(0), np.arange(24, dtype=np.int32).reshape(2, 3, 4)):
        blob, sha = codec.encode(a)
        b = codec.decode(blob, sha)
        assert b.shape == a.shape and np.array_equal(a, b)


def test_decode_checks_hash_magic_and_length():
    a = np.arange(100.0)
    blob, sha = codec.encode(a)
    with pytest.raises(InvalidSignal, match="differs from the expected"):
        codec.decode(blob, expected_sha="0" * 64)
    with pytest.raises(InvalidSignal, match="magic"):
        codec.decode(b"XXXX" + blob[4:])
    with pytest.raises(InvalidSignal, match="truncated inside byte plane"):
        codec.decode(blob[:-5])
    corrupt = bytearray(blob)
    corrupt[-3] ^= 0xFF  # last plane holds zlib data for a smooth ramp
    with pytest.raises(InvalidSignal, match="does not decompress|differs from the expected"):
        codec.decode(bytes(corrupt), expected_sha=sha)
    with pytest.raises(InvalidSignal, match="shorter than"):
        codec.decode(blob[:3])
    # header of a 10-element float64 array, payload of only one element
    header = codec.encode(np.arange(10.0))[0][: 8 + 3 + 8]
    assert header.startswith(b"RVA1")
    fake = header[:4] + bytes([codec.CODEC_SHUFFLE_ZLIB]) + header[5:] + zlib.compress(bytes(8))
    with pytest.raises(InvalidSignal, match="holds 8 bytes"):
        codec.decode(fake)


def test_decoded_array_is_writable_and_independent():
    a = np.arange(10.0)
    blob, _ = codec.encode(a)
    b = codec.decode(blob)
    b[0] = 42.0  # must not raise (read-only buffers would)
    assert codec.decode(blob)[0] == 0.0


@settings(max_examples=60, deadline=None)
@given(hnp.arrays(dtype=st.sampled_from([np.float64, np.float32, np.int64, np.int16, np.uint8]),
                  shape=hnp.array_shapes(min_dims=1, max_dims=3, min_side=0, max_side=30)))
def test_property_round_trip(a):
    blob, sha = codec.encode(a)
    b = codec.decode(blob, sha)
    assert b.dtype == a.dtype.newbyteorder("<") or b.dtype == a.dtype
    assert b.shape == a.shape
    assert np.ascontiguousarray(a).tobytes() == b.tobytes()
    assert sha == codec.content_hash(b)


@pytest.mark.parametrize("backend", ["zlib", "isal"])
def test_both_inflate_backends_decode_identically(monkeypatch, backend):
    """ISA-L and zlib inflate the same streams to the same bytes, and both reject corruption."""
    if backend == "isal":
        pytest.importorskip("isal")
        monkeypatch.setattr(codec, "inflate", codec._isal_inflate)
    else:
        monkeypatch.setattr(codec, "inflate", codec._zlib_inflate)
    rng = np.random.default_rng(5)
    a = 80.0 + 5.0 * rng.standard_normal(5000)  # measured-like: compressed high planes
    blob, sha = codec.encode(a)
    assert codec.decode(blob, sha).tobytes() == a.tobytes()
    legacy = (b"RVA1" + bytes([codec.CODEC_SHUFFLE_ZLIB]) + blob[5:8 + 3 + 8]
              + zlib.compress(a.view(np.uint8).reshape(-1, 8).T.tobytes()))
    assert codec.decode(legacy, sha).tobytes() == a.tobytes()
    with pytest.raises(InvalidSignal, match="does not decompress"):
        codec.decode(legacy[:-40])
