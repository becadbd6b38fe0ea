"""Compiled codec-2 join (db/codec_planes.py): the same arrays as the interpreted plane loop
of db/codec.py on every layout of raw and zlib planes, and every irregular payload left to
that loop, which raises its usual errors."""

from __future__ import annotations

import struct
import zlib

import numpy as np
import pytest

from railval.core.errors import InvalidSignal
from railval.db import codec

pytest.importorskip("deflate")
codec_planes = pytest.importorskip("railval.db.codec_planes")
pytestmark = pytest.mark.skipif(not codec_planes.AVAILABLE, reason="libdeflate symbols not found")


def blob_of(planes: list[bytes], flags: list[int], n: int, dtype: str = "<f8") -> bytes:
    """A codec-2 blob of ``n`` elements built by hand from the module docstring's layout."""
    dstr = dtype.encode()
    out = struct.pack("<4sBBBB", b"RVA1", 2, 1, len(dstr), 1) + dstr + struct.pack("<Q", n)
    for p, f in zip(planes, flags, strict=True):
        data = zlib.compress(p, 1) if f == 1 else p
        out += struct.pack("<BI", f, len(data)) + data
    return out


def interpreted(blob: bytes, monkeypatch) -> np.ndarray:
    with monkeypatch.context() as m:
        m.setattr(codec, "_planes_module", lambda: None)
        return codec.decode(blob)


@pytest.mark.parametrize("dtype", ["<f8", "<i8", "<u8"])
@pytest.mark.parametrize("seed", range(4))
def test_every_mix_of_raw_and_zlib_planes_gives_the_interpreted_array(monkeypatch, dtype, seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 3000))
    planes = [rng.integers(0, 256 if k % 2 else 4, n, dtype=np.uint8).tobytes() for k in range(8)]
    flags = [int(f) for f in rng.integers(0, 2, 8)]
    blob = blob_of(planes, flags, n, dtype)
    out = np.empty(n, dtype)
    assert codec_planes.join8(out, np.frombuffer(blob, np.uint8), 8 + 3 + 8)
    expected = np.array([np.frombuffer(p, np.uint8) for p in planes]).T.copy().view(dtype)
    assert out.tobytes() == expected.tobytes() == interpreted(blob, monkeypatch).tobytes()
    assert codec.decode(blob).tobytes() == expected.tobytes()
    assert codec.decode(bytearray(blob)).tobytes() == expected.tobytes()  # writable source


def test_stored_signals_decode_as_before(monkeypatch):
    rng = np.random.default_rng(5)
    for a in (40.0 + rng.standard_normal(20000), np.cumsum(rng.standard_normal(7001)),
              np.zeros(10), np.arange(3.0)):
        blob, sha = codec.encode(a)
        assert codec.decode(blob, sha).tobytes() == a.tobytes()
        assert interpreted(blob, monkeypatch).tobytes() == a.tobytes()


def irregular() -> list[tuple[str, bytes]]:
    n = 600
    rng = np.random.default_rng(9)
    planes = [rng.integers(0, 3, n, dtype=np.uint8).tobytes() for _ in range(8)]
    good = blob_of(planes, [0, 0, 0, 0, 0, 0, 1, 1], n)
    short = blob_of(planes[:7] + [planes[7][:-1]], [0] * 7 + [1], n)
    long_ = blob_of(planes[:7] + [planes[7] + b"\0"], [0] * 7 + [1], n)
    raw_short = blob_of([planes[0][:-1]] + planes[1:], [0] * 8, n)
    bad_flag = bytearray(good)
    bad_flag[19] = 7
    corrupt = bytearray(good)
    corrupt[-20] ^= 0xFF
    return [("holds", short), ("decompress|holds", long_), ("truncated", good[:-1]),
            ("trailing", good + b"\0"), ("unknown flag", bytes(bad_flag)),
            ("decompress|holds", bytes(corrupt)), ("holds 599 bytes", raw_short),
            ("truncated", good[:19 + 3])]


@pytest.mark.parametrize("match,blob", irregular())
def test_an_irregular_payload_is_left_to_the_interpreted_loop_and_refused(monkeypatch,
                                                                          match, blob):
    out = np.empty(600)
    assert not codec_planes.join8(out, np.frombuffer(blob, np.uint8), 19)
    with pytest.raises(InvalidSignal, match=match) as fast:
        codec.decode(blob)
    with pytest.raises(InvalidSignal, match=match) as slow:
        interpreted(blob, monkeypatch)
    assert str(fast.value) == str(slow.value)
