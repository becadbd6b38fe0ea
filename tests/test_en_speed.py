"""The EN chain restructured for speed (core/en_section.py: one compiled step per section on
the cores; core/orderstat.py: range in four lanes, bucket index once; core/psd.welch_blocks:
all sections' PSD segments in one Welch pass; compiled checks) gives the values of an
independent reference built here from numpy/scipy alone, on the ``bench en`` sections and a
synthetic campaign, to a relative difference of at most 1e-12 — every value, every value
under the alternative readings (docs/validation.md, open definitions) and every
supplementary value — and raises the same errors in the same order.

Reference per section: ``filtfilt_rows`` (held to ``scipy.signal.sosfiltfilt`` by
tests/test_en_throughput.py), Y/Q and ΣY by numpy, the evaluated cut by a boolean mask,
``numpy.quantile`` (``inverted_cdf`` and ``linear``), ``sqrt(mean(x²))``, the interpolant
sliding mean (:func:`railval.core.en_statistics.sliding_mean_distance`), the sample-window
means (:func:`railval.core.definitions.sample_window_means` with its own cumsum), and
``scipy.signal.welch`` for the PSD bands.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.signal

from railval.core.definitions import (
    CHOSEN,
    READINGS,
    sample_window_means,
    window_centres,
)
from railval.core.diagnosis import DEFAULT_BANDS_HZ
from railval.core.en14363 import evaluate_batch
from railval.core.en_statistics import sliding_mean_distance
from railval.core.errors import InvalidSignal
from railval.core.filters import filtfilt_rows
from railval.core.orderstat import order_statistics
from railval.core.psd import detrend_linear, welch_blocks
from railval.core.types import BODY_POSITIONS, WHEEL_POSITIONS, SectionInfo, SignalSet
from tests import en_frozen

REL = 1e-12


def _pct(x, ps, method):
    return np.quantile(x, ps, method=method)


def _maxabs(x, method):
    lo, hi = _pct(x, [0.0015, 0.9985], method)
    return max(abs(lo), abs(hi))


def _sliding(sig, d, sec, grid, window):
    first = float(d[(d >= sec.eval_start_m) & (d <= sec.eval_end_m)][0])
    origin = sec.eval_start_m if grid == "section_start" else first
    if window == "interpolant":
        return sliding_mean_distance(sig, d, sec.eval_start_m, sec.eval_end_m,
                                     origin_m=origin)[1]
    centres = window_centres(sec.eval_start_m, sec.eval_end_m, origin, 2.0, 0.5)
    return sample_window_means(sig[np.newaxis, :], d, centres, 2.0,
                               closed=window == "samples_closed")[0]


def _force_reference(ss, sec, m, out):
    """(reading id or "", quantity, position) → value of the force quantities."""
    names = [c for c in ss.channels if c.startswith(("Y_", "Q_"))]
    lp = dict(zip(names, filtfilt_rows([ss.channels[c] for c in names], ss.fs, "lowpass"),
                  strict=True))
    d = ss.distance_m
    for p in WHEEL_POSITIONS:
        if f"Y_{p}" not in lp:
            continue
        y, q = lp[f"Y_{p}"], lp[f"Q_{p}"]
        for r in READINGS:
            rid = "" if r == CHOSEN else r.id
            if r.sliding == CHOSEN.sliding:
                out[(rid, "Y_qst", p)] = _pct(y[m], 0.5, r.percentile)
                out[(rid, "Y_max", p)] = _maxabs(y[m], r.percentile)
                out[(rid, "Q_qst", p)] = _pct(q[m], 0.5, r.percentile)
                out[(rid, "Q_max", p)] = _pct(q[m], 0.9985, r.percentile)
                out[(rid, "YQ_qst", p)] = _pct((y / q)[m], 0.5, r.percentile)
            means = _sliding(y / q, d, sec, r.grid, r.window)
            out[(rid, "YQ_max", p)] = (_maxabs(means, r.percentile)
                                       if np.all(np.isfinite(means)) else math.nan)
    for w in range(1, 5):
        if f"Y_w{w}L" not in lp:
            continue
        s = lp[f"Y_w{w}L"] + lp[f"Y_w{w}R"]
        for r in READINGS:
            rid = "" if r == CHOSEN else r.id
            if r.sliding == CHOSEN.sliding:
                out[(rid, "SumY_qst", f"ws{w}")] = _pct(s[m], 0.5, r.percentile)
            means = _sliding(s, d, sec, r.grid, r.window)
            out[(rid, "SumY_max", f"ws{w}")] = (_maxabs(means, r.percentile)
                                                if np.all(np.isfinite(means)) else math.nan)


def _acc_reference(ss, m, out):
    names = [c for c in ss.channels if c.startswith(("ay_", "az_"))]
    bp = filtfilt_rows([ss.channels[c] for c in names], ss.fs, "bandpass")
    for name, x in zip(names, bp, strict=True):
        kind, _, pos = name.rpartition("_")
        e = x[m]
        key = kind if kind.endswith("_bg") else kind.split("_")[0]
        out[("supp" if kind.endswith("_bg") else "", f"{key}_rms", pos)] = np.sqrt(np.mean(e * e))
        for method in ("inverted_cdf", "linear"):
            rid = "supp" if kind.endswith("_bg") else (
                "" if method == "inverted_cdf" else _linear_id())
            if kind.endswith("_bg") and method == "linear":
                continue
            out[(rid, f"{key}_max", pos)] = _maxabs(e, method)
        raw = np.asarray(ss.channels[name], dtype=np.float64)[m]
        nper = int(min(raw.size, max(8, round(10.0 * ss.fs))))
        f, g = scipy.signal.welch(raw, fs=ss.fs, nperseg=nper, detrend=detrend_linear)
        for lo, hi in DEFAULT_BANDS_HZ:
            inside = (f >= lo) & (f < hi)
            if inside.any():
                out[("supp", f"psd_{kind}_{lo:g}-{hi:g}Hz", pos)] = math.sqrt(
                    np.sum(g[inside]) * (f[1] - f[0]))


def _linear_id():
    return next(r.id for r in READINGS if r.percentile == "linear"
                and r.sliding == CHOSEN.sliding)


def reference(ss: SignalSet, sec: SectionInfo) -> dict:
    d = ss.distance_m
    m = (d >= sec.eval_start_m) & (d <= sec.eval_end_m)
    out: dict = {}
    _force_reference(ss, sec, m, out)
    _acc_reference(ss, m, out)
    return out


def _flatten(v) -> dict:
    out = {("", q, p): x for (q, p), x in v.items()}
    for (q, p), x in v.supplementary.items():
        out[("supp", q, p)] = x
    for rid in {r.id for r in READINGS if r != CHOSEN}:
        for (q, p) in v:
            if (q in ("YQ_max", "SumY_max") or not q.endswith("_rms")):
                out[(rid, q, p)] = v.value_under(rid, (q, p))
    return out


def _max_rel_diff(got: dict, ref: dict) -> float:
    worst = 0.0
    for key, want in ref.items():
        have = got[key]
        if math.isnan(want) or math.isnan(have):
            assert math.isnan(want) and math.isnan(have), key
            continue
        worst = max(worst, abs(have - want) / max(abs(want), 1e-300) if want else abs(have))
    return worst


def _inputs(kind):
    if kind == "bench":
        sets, infos = en_frozen.bench_inputs()
        return sets[:5], infos[:5]
    return en_frozen.campaign_inputs()


@pytest.mark.parametrize("kind", ["bench", "campaign"])
def test_batch_equals_the_independent_reference(kind):
    sets, infos = _inputs(kind)
    got = evaluate_batch(sets, infos)
    n_keys = 0
    for v, ss, sec in zip(got, sets, infos, strict=True):
        ref = reference(ss, sec)
        flat = _flatten(v)
        assert _max_rel_diff(flat, ref) <= REL, sec.id
        n_keys += len(ref)
    assert n_keys > 1000


def test_the_reference_comparison_can_fail():
    sets, infos = _inputs("bench")
    v = evaluate_batch(sets[:1], infos[:1])[0]
    ref = reference(sets[0], infos[0])
    flat = _flatten(v)
    key = next(k for k in ref if k[1] == "YQ_max" and k[0])
    flat[key] *= 1 + 1e-10
    assert _max_rel_diff(flat, ref) > REL


def _section(n=4000, fs=200.0):
    rng = np.random.default_rng(11)
    t = np.arange(n) / fs
    d = 20.0 * t
    ch = {f"Y_{p}": 10 + rng.standard_normal(n) for p in WHEEL_POSITIONS}
    ch |= {f"Q_{p}": 70 + rng.standard_normal(n) for p in WHEEL_POSITIONS}
    ch |= {f"{k}_cb_{b}": 0.3 * rng.standard_normal(n) for k in ("ay", "az")
           for b in BODY_POSITIONS}
    return SignalSet(fs, t, d, ch), SectionInfo("S1", 500.0, 120.0, 72.0, 1, 100.0, 300.0)


def _old_peak(arr):
    return max(float(np.max(arr)), -float(np.min(arr)))


@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf, 3e100, -2e101])
@pytest.mark.parametrize("layout", ["float64", "big-endian", "strided"])
def test_checks_give_the_former_messages(value, layout):
    ss, sec = _section()
    x = ss.channels["Q_w1L"].copy()
    x[1234] = value
    if layout == "big-endian":  # not the compiled path's dtype: numpy's reductions
        x = x.astype(">f8")
    elif layout == "strided":
        x = np.repeat(x, 2)[::2]
    ss.channels["Q_w1L"] = x
    peak = _old_peak(x)
    if not np.isfinite(peak):
        want = f"section S1: channel Q_w1L holds non-finite values ({peak:g})"
    else:
        want = f"section S1: channel Q_w1L holds {peak:g}; samples must be finite"
    with pytest.raises(InvalidSignal) as exc:
        evaluate_batch([ss], [sec])
    assert str(exc.value).startswith(want)


def test_first_failing_section_is_reported_in_order():
    """Filtered Q = 0 inside the range of the first section (a channel of zeros), a range of
    one sample in the second: the first section's error, whichever step finds it."""
    a, sec_a = _section()
    a.channels["Q_w2R"] = np.zeros_like(a.channels["Q_w2R"])
    b, _ = _section()
    sec_b = SectionInfo("S2", 500.0, 120.0, 72.0, 1, 150.0, 150.05)
    with pytest.raises(InvalidSignal, match=r"^section S1: Q_w2R is exactly 0 kN"):
        evaluate_batch([a, b], [sec_a, sec_b])
    with pytest.raises(InvalidSignal, match=r"^section S2: evaluated range .* holds 1 samples"):
        evaluate_batch([b, a], [sec_b, sec_a])


def test_order_statistics_lanes_and_numpy_sort_path():
    """Extremes in the last lanes and in the tail after the lanes, ties, ±0, rows sorted by
    numpy (≤ 3000 samples) and selected (longer)."""
    rng = np.random.default_rng(2)
    for n in (257, 2999, 3000, 3001, 4002, 4003, 10_001):
        x = rng.standard_normal((6, n))
        x[0, -1], x[0, -2] = -50.0, 50.0
        x[1, -3], x[1, 0] = 40.0, -40.0
        x[2] = np.round(x[2], 1)
        x[3, ::2], x[3, 1::2] = -0.0, 0.0
        x[4] = -x[4] ** 3
        ranks = sorted({0, 1, 5, n // 2 - 1, n // 2, n - 6, n - 2, n - 1})
        np.testing.assert_array_equal(order_statistics(x, ranks), np.sort(x, axis=-1)[:, ranks])


def test_welch_blocks_equal_scipy_welch():
    """Bit for bit (tests/test_supp_exact.py tries many more shapes)."""
    rng = np.random.default_rng(4)
    blocks = [rng.standard_normal((3, n)) + 0.02 * np.arange(n) + 5.0
              for n in (8, 9, 999, 2000, 2001, 4999, 5000, 12_345)]
    for b, (f, g) in zip(blocks, welch_blocks(blocks, 200.0, 10.0), strict=True):
        nper = int(min(b.shape[-1], 2000))
        f0, g0 = scipy.signal.welch(b, fs=200.0, nperseg=nper, detrend=detrend_linear, axis=-1)
        np.testing.assert_array_equal(f, f0)
        np.testing.assert_array_equal(g, g0)


def test_pairwise_sum_is_numpys_sum():
    """The compiled rms sums as numpy does (bit for bit), across its block and split sizes."""
    from railval.core.en_statistics import pairwise_sum

    rng = np.random.default_rng(8)
    for n in [*range(140), 255, 256, 257, 8191, 8192, 8193, 10_000, 65_537]:
        x = rng.standard_normal(n + 3) ** 2 * 10.0 ** rng.uniform(-3, 3)
        assert pairwise_sum(x, 3, n) == np.add.reduce(x[3:])
        assert pairwise_sum(x, 0, n) == np.add.reduce(x[:n])
