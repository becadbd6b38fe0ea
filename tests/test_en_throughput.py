"""The EN chain restructured for throughput gives today's values: filtering in lockstep blocks
on both cores, percentiles from selected order statistics instead of sorted rows
(core/filters.py, core/orderstat.py, core/en14363.py; docs/validation.md, Throughput).

Held to the values the chain gave before the restructuring (tests/data/en_frozen.json.gz,
written by ``python -m tests.en_frozen``), on the ``bench en`` sections and a synthetic
campaign, to a relative difference of at most 1e-12; the order statistics are held to
``numpy.sort`` exactly and the filter to ``scipy.signal.sosfiltfilt``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.signal

from railval.core.en14363 import evaluate_batch
from railval.core.filters import design, filtfilt_rows
from railval.core.orderstat import order_statistics

from tests import en_frozen

REL = 1e-12


def _max_rel_diff(now: list[dict], frozen: list[dict]) -> float:
    worst = 0.0
    assert len(now) == len(frozen)
    for a, b in zip(now, frozen, strict=True):
        assert a.keys() == b.keys()
        for key, ref in b.items():
            got = a[key]
            if ref is None or got is None:
                assert ref is None and got is None, key
                continue
            worst = max(worst, abs(got - ref) / max(abs(ref), 1e-300) if ref else abs(got))
    return worst


@pytest.mark.parametrize("threads", ["1", "2"])
@pytest.mark.parametrize("inputs", ["bench", "campaign"])
def test_values_equal_the_frozen_values(inputs, threads, monkeypatch):
    monkeypatch.setenv("RAILVAL_THREADS", threads)
    sets, infos = (en_frozen.bench_inputs() if inputs == "bench"
                   else en_frozen.campaign_inputs())
    now = [en_frozen.flatten(v) for v in evaluate_batch(sets, infos)]
    frozen = en_frozen.load()[inputs]
    assert sum(len(x) for x in frozen) > 3000
    assert _max_rel_diff(now, frozen) <= REL


def test_the_frozen_comparison_can_fail():
    frozen = en_frozen.load()["bench"]
    changed = [dict(x) for x in frozen]
    key = next(k for k in changed[3] if k.startswith("value||Y_max"))
    changed[3][key] *= 1 + 1e-9
    assert _max_rel_diff(changed, frozen) > REL


def _ranks(n: int) -> list[int]:
    ps = (0.0015, 0.5, 0.9985)
    inv = {min(max(math.ceil(n * p - 1e-12) - 1, 0), n - 1) for p in ps}
    lin = {min(math.floor((n - 1) * p) + d, n - 1) for p in ps for d in (0, 1)}
    return sorted(inv | lin)


@pytest.mark.parametrize("threads", ["1", "2"])
def test_order_statistics_equal_a_full_sort(threads, monkeypatch):
    """Exact on awkward rows: ties, a constant row, ±0, one huge outlier crowding a bucket,
    values near ±1e100, tiny ranges, short rows (sorted) and long ones (selected)."""
    monkeypatch.setenv("RAILVAL_THREADS", threads)
    rng = np.random.default_rng(5)
    for n in (2, 3, 255, 256, 257, 4001, 15000):
        x = rng.standard_normal((12, n))
        x[1] = 7.0
        x[2] = np.round(x[2], 1)
        x[3, ::2] = -0.0
        x[3, 1::2] = 0.0
        x[4, n // 2] = 1e100
        x[5] = 1e100 * np.sign(x[5])
        x[6] = 1.0 + 1e-15 * rng.integers(0, 5, n)
        x[7] = np.cumsum(x[7])
        x[8] = 5e-324 * rng.integers(0, 3, n)
        x[9] = -np.abs(x[9]) ** 5
        ranks = _ranks(n)
        got = order_statistics(x, ranks)
        np.testing.assert_array_equal(got, np.sort(x, axis=-1)[:, ranks])
        # any order of ranks, repeated ranks
        mixed = [ranks[-1], 0, ranks[-1], n - 1]
        np.testing.assert_array_equal(order_statistics(x, mixed), np.sort(x, axis=-1)[:, mixed])


@pytest.mark.parametrize("threads", ["1", "2"])
@pytest.mark.parametrize("kind", ["lowpass", "bandpass"])
def test_lockstep_filter_equals_scipy(kind, threads, monkeypatch):
    """Row counts that fill no, one and several lockstep blocks and a partial last block."""
    monkeypatch.setenv("RAILVAL_THREADS", threads)
    rng = np.random.default_rng(9)
    for rows in (1, 15, 16, 17, 50):
        x = 70 + 5 * rng.standard_normal((rows, 3000))
        ref = scipy.signal.sosfiltfilt(design(500.0, kind, 4).sos, x, axis=-1)
        np.testing.assert_allclose(filtfilt_rows(x, 500.0, kind), ref, rtol=1e-13, atol=1e-12)


def test_a_forked_child_filters_with_its_own_threads(monkeypatch):
    """A process forked after the row threads exist (a process pool under ``fork``) must not
    use the parent's pool, whose threads it does not have (it waited forever before)."""
    import multiprocessing as mp

    monkeypatch.setenv("RAILVAL_THREADS", "2")
    x = 70 + 5 * np.random.default_rng(3).standard_normal((64, 2000))
    ref = filtfilt_rows(x, 500.0, "lowpass")  # creates the parent's pool (64 rows: 2 parts)
    with mp.get_context("fork").Pool(1) as pool:
        got = pool.apply_async(filtfilt_rows, (x, 500.0, "lowpass")).get(timeout=120)
    np.testing.assert_array_equal(got, ref)
