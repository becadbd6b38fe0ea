"""The batched Welch of the supplementary PSD bands (core/psd.welch_blocks) gives the SAME float
bits as one ``welch_rows`` (= ``scipy.signal.welch``) call per block, and the supplementary band
values of many sections at once (core/supplementary.psd_band_values_batch) are the SAME floats,
in the same key order, as the former one-section-at-a-time computation. ``numpy.array_equal``,
not a tolerance: a sign-off binds the evidence hash of every value (tests/test_upgrade.py).

Random blocks cover: lengths odd and even (8, 9, 10, up to 30 000), rates, segment lengths,
1–9 rows (the BLAS product of the detrend differs with the row count of the call), one
segment, 2–7 segments (numpy's sequential sum), 8–128 (eight partial sums) and more than 128
segments (numpy's pairwise split), blocks given as 2-D arrays and as lists of rows.
"""

from __future__ import annotations

import math
from collections import defaultdict

import numpy as np
import pytest
import scipy.signal

from railval.core.diagnosis import DEFAULT_BANDS_HZ
from railval.core.errors import InvalidParameter, InvalidSignal
from railval.core.psd import detrend_linear, welch_blocks, welch_rows
from railval.core.supplementary import PSD_KINDS, PSD_SEGMENT_S, psd_band_values_batch

RATES = (200.0, 250.0, 500.0, 1000.0, 128.0, 333.3, 97.5)
SEGMENTS_S = (10.0, 3.7, 2.0, 0.5, 0.01)


def _random_block(rng, n):
    rows = int(rng.integers(1, 10))
    x = rng.standard_normal((rows, n)) * 10.0 ** rng.uniform(-3, 2)
    x += rng.uniform(-5, 5, (rows, 1)) * np.linspace(0.0, 1.0, n) + rng.uniform(-50, 50, (rows, 1))
    if rng.random() < 0.2:
        x[0, : n // 3] = 0.0  # exact zeros: zero power bins
    return x


def _segments(n, fs, segment_s):
    m = int(min(n, max(8, round(segment_s * fs))))
    return (n - m // 2) // (m - m // 2)


def test_welch_blocks_bit_for_bit_welch_rows_and_scipy():
    rng = np.random.default_rng(2026)
    seen = set()
    for _ in range(70):
        segment_s = float(rng.choice(SEGMENTS_S))
        blocks, rates = [], []
        for _ in range(int(rng.integers(1, 9))):
            n = int(rng.choice([8, 9, 10, 11, int(rng.integers(12, 400)),
                                int(rng.integers(400, 30_000))]))
            x = _random_block(rng, n)
            blocks.append(x if rng.random() < 0.5 else list(x))
            rates.append(float(rng.choice(RATES)))
        if rng.random() < 0.3:  # one rate for all blocks
            rates = [rates[0]] * len(rates)
            got = welch_blocks(blocks, rates[0], segment_s)
        else:
            got = welch_blocks(blocks, rates, segment_s)
        for b, fs, (f, g) in zip(blocks, rates, got, strict=True):
            x = np.vstack(b) if isinstance(b, list) else b
            f0, g0, _ = welch_rows(x, fs, segment_s)
            assert g.shape == g0.shape
            assert np.array_equal(f, f0) and np.array_equal(g, g0), (x.shape, fs, segment_s)
            m = int(min(x.shape[1], max(8, round(segment_s * fs))))
            f1, g1 = scipy.signal.welch(x, fs=fs, nperseg=m, detrend=detrend_linear, axis=-1)
            assert np.array_equal(f, f1) and np.array_equal(g, g1)
            k = _segments(x.shape[1], fs, segment_s)
            seen.add("1" if k == 1 else "2-7" if k < 8 else "8-128" if k <= 128 else ">128")
            seen.add(f"rows {x.shape[0]}")
            seen.add("odd" if m % 2 else "even")
    assert {"1", "2-7", "8-128", ">128", "odd", "even"} <= seen
    assert {f"rows {r}" for r in range(1, 10)} <= seen


def test_welch_blocks_same_bits_whatever_the_other_blocks():
    """A block's result does not depend on the blocks batched with it (the bench shape: 4 rows,
    10 s segments at 500 Hz, 2 or 3 segments)."""
    rng = np.random.default_rng(7)
    blocks = [rng.standard_normal((4, int(rng.integers(9800, 10200)))) for _ in range(17)]
    alone = [welch_blocks([b], 500.0)[0][1] for b in blocks]
    together = welch_blocks(blocks, 500.0)
    reordered = welch_blocks(blocks[::-1], 500.0)[::-1]
    for a, (_, t), (_, r) in zip(alone, together, reordered, strict=True):
        assert np.array_equal(a, t) and np.array_equal(a, r)


def test_welch_blocks_same_bits_in_chunks_of_any_size(monkeypatch):
    from railval.core import psd

    rng = np.random.default_rng(9)
    blocks = [rng.standard_normal((int(rng.integers(1, 5)), int(rng.integers(2000, 9000))))
              for _ in range(12)]
    want = [welch_rows(b, 200.0, 3.0)[1] for b in blocks]
    for size in (1, 1 << 16, 1 << 20, 1 << 40):
        monkeypatch.setattr(psd, "CHUNK_BYTES", size)
        for w, (_, g) in zip(want, welch_blocks(blocks, 200.0, 3.0), strict=True):
            assert np.array_equal(w, g)


@pytest.mark.parametrize("where", [5, 99, 4_000, 4_099])  # in a segment / after the last one
@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf])
def test_welch_blocks_raises_as_welch_rows_first_failing_block(where, value):
    x = np.ones((2, 4_100)) + np.linspace(0, 1, 4_100)
    bad = x.copy()
    bad[1, where] = value
    with pytest.raises(InvalidSignal, match="values contain NaN or inf"):
        welch_rows(bad, 100.0)
    for b in (bad, list(bad)):
        with pytest.raises(InvalidSignal, match="values contain NaN or inf"):
            welch_blocks([x, b, x[:, :5]], 100.0)
        with pytest.raises(InvalidSignal, match="values contain NaN or inf"):
            welch_blocks([x, b, x], [100.0, 100.0, float("nan")])
        with pytest.raises(InvalidSignal, match="at least 8 samples, got 5"):
            welch_blocks([x, x[:, :5], b], 100.0)
        with pytest.raises(InvalidParameter, match="fs must be a positive finite"):
            welch_blocks([x, x, b], [100.0, -1.0, 100.0])
    with pytest.raises(InvalidParameter, match="2 blocks but 1 rates"):
        welch_blocks([x, x], [100.0])


def _former_band_values(evaluated, fs):
    """The band values of one section as computed before (one welch_rows call per channel
    length of the section, bins by mask)."""
    out = {}
    names = [ch for ch, x in evaluated.items()
             if ch.rpartition("_")[0] in PSD_KINDS and np.asarray(x).size >= 8]
    by_length = defaultdict(list)
    for ch in names:
        by_length[np.asarray(evaluated[ch]).size].append(ch)
    for chans in by_length.values():
        f, g, _ = welch_rows(np.vstack([np.asarray(evaluated[c], dtype=np.float64) for c in chans]),
                             fs, PSD_SEGMENT_S)
        df = f[1] - f[0]
        for lo, hi in DEFAULT_BANDS_HZ:
            inside = (f >= lo) & (f < hi)
            if not inside.any():
                continue
            power = np.sum(g[:, inside], axis=1) * df
            for ch, pw in zip(chans, power, strict=True):
                kind, _, pos = ch.rpartition("_")
                out[(f"psd_{kind}_{lo:g}-{hi:g}Hz", pos)] = float(math.sqrt(pw))
    return out


def test_band_values_batch_equal_former_per_section_values():
    rng = np.random.default_rng(14363)
    sections, rates = [], []
    channels = [f"{k}_{p}" for k in PSD_KINDS for p in ("b1", "b2")]
    for _ in range(40):
        fs = float(rng.choice([200.0, 250.0, 500.0, 1000.0, 50.0]))
        n = int(rng.integers(5, 40_000 if fs < 1000 else 60_000))
        ev = {"qy_w1R": rng.standard_normal(n)}  # not a PSD channel
        for ch in rng.permutation(channels)[: int(rng.integers(0, 9))]:
            m = n if rng.random() < 0.8 else int(rng.integers(5, n + 10))  # other lengths
            ev[str(ch)] = (rng.standard_normal(m) * rng.uniform(0.01, 3)
                           + rng.uniform(-1, 1) * np.linspace(0, 1, m))
        sections.append(ev)
        rates.append(fs)
    got = psd_band_values_batch(sections, rates)
    n_values = 0
    for ev, fs, values in zip(sections, rates, got, strict=True):
        want = _former_band_values(ev, fs)
        assert list(values) == list(want)  # same keys in the same order
        for key, v in want.items():
            assert type(values[key]) is float and values[key] == v, key
        n_values += len(want)
    assert n_values > 500
    # both sums of the former expression occur, each with bands of 8 bins or more (where
    # numpy's in-order and pairwise sums differ): blocks of one row and of several rows
    shapes = set()
    for ev, fs in zip(sections, rates, strict=True):
        lengths = defaultdict(int)
        for ch, x in ev.items():
            if ch.rpartition("_")[0] in PSD_KINDS and x.size >= 8:
                lengths[x.size] += 1
        for n, rows in lengths.items():
            m = int(min(n, max(8, round(PSD_SEGMENT_S * fs))))
            if 5.0 * m / fs >= 8:  # the 5-10 Hz band holds at least 8 bins
                shapes.add(min(rows, 2))
    assert shapes == {1, 2}


def test_welch_blocks_finite_values_whose_mean_overflows_as_welch_rows():
    x = np.full((2, 300), 1.7e308) * np.linspace(0.5, 1.0, 300)
    with np.errstate(all="ignore"):
        want = welch_rows(x, 100.0, 1.0)[1]
        got = welch_blocks([x, list(x)], 100.0, 1.0)
    for _, g in got:
        assert np.array_equal(g, want, equal_nan=True)


def test_welch_blocks_strided_and_fortran_inputs():
    rng = np.random.default_rng(3)
    x = rng.standard_normal((6, 9001))
    want = welch_rows(x[::2, ::3], 50.0, 10.0)[1]
    for b in (x[::2, ::3], np.asfortranarray(x[::2, ::3]), list(x[::2, ::3])):
        assert np.array_equal(welch_blocks([b], 50.0)[0][1], want)
