"""The compiled readings of the EN statistics (window ends, percentile recipes, the order
statistics at the ends of a row, the sliding percentiles of every reading) give the same
numbers, bit for bit, as the numpy code they replace (which stays as the path of the
sections the compiled one does not take)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from railval.core import en_section
from railval.core.definitions import (
    PERCENTILE_METHODS,
    percentile_recipe,
    sorted_percentiles,
    window_centres,
)
from railval.core.en14363 import evaluate_batch
from railval.core.en_kernels import _row_extremes, _rows_percentiles, _window_bounds
from railval.core.en_statistics import PERCENTILES, _window_ends
from railval.core.types import SignalSet
from tests import en_frozen


@pytest.mark.parametrize("n", [*range(1, 40), 97, 256, 1000, 1011, 9999, 10114])
def test_percentile_recipe_reads_what_sorted_percentiles_reads(n):
    rng = np.random.default_rng(n)
    rows = np.sort(rng.normal(size=(5, n)) * 10.0 ** rng.integers(-3, 4, size=(5, 1)), axis=1)
    rows[0] = np.sort(rng.integers(-3, 3, size=n).astype(np.float64))  # ties
    for methods in (("inverted_cdf",), PERCENTILE_METHODS):
        ranks, cols, mode, g, omg = percentile_recipe(n, PERCENTILES, methods)
        out = np.empty((len(methods), rows.shape[0], len(PERCENTILES)))
        _rows_percentiles(np.ascontiguousarray(rows[:, ranks]), cols, mode, g, omg, out)
        for m, method in enumerate(methods):
            want = sorted_percentiles(rows, PERCENTILES, method)
            assert out[m].tobytes() == want.tobytes(), (n, method)


@pytest.mark.parametrize("n", [1, 2, 3, 5, 8, 40, 1011, 5000])
def test_row_extremes_are_the_ends_of_the_sorted_row(n):
    rng = np.random.default_rng(n)
    rows = [rng.normal(size=n), np.arange(n, dtype=np.float64), np.arange(n, 0, -1.0),
            rng.integers(-2, 3, size=n).astype(np.float64), np.full(n, 1.5)]
    for x in rows:
        srt = np.sort(x)
        for n_lo, n_hi in ((0, 1), (1, 0), (1, 1), (min(3, n), min(4, n)), (n, n),
                           (n // 2, n - n // 2)):
            lo, hi = np.empty(max(n_lo, 1)), np.empty(max(n_hi, 1))
            _row_extremes(x, n_lo, n_hi, lo, hi)
            assert lo[:n_lo].tobytes() == srt[:n_lo].tobytes()
            assert hi[:n_hi].tobytes() == srt[n - n_hi:].tobytes()


def _axis(rng, n, spacing, lattice):
    steps = rng.uniform(0.2, 1.8, size=n - 1) * spacing
    d = np.concatenate([[3.0], 3.0 + np.cumsum(steps)])
    if lattice:  # samples exactly on window ends: searchsorted's side decides
        d = np.unique(np.round(d * 4.0) / 4.0)
    return d


@pytest.mark.parametrize("seed,spacing,lattice", [(0, 0.02, False), (1, 0.25, True),
                                                  (2, 1.3, False), (3, 0.5, True),
                                                  (4, 3.0, False)])
def test_window_bounds_equal_searchsorted(seed, spacing, lattice):
    rng = np.random.default_rng(seed)
    d = _axis(rng, 4000, spacing, lattice)
    start, end = float(d[3]) + 0.13, float(d[-4]) - 0.07
    first = float(d[np.searchsorted(d, start)])
    origins = [start, first]
    n_cs = [window_centres(start, end, o, 2.0, 0.5).size for o in origins]
    total = sum(n_cs)
    j, u = np.empty(2 * total, np.int64), np.empty(2 * total)
    lo, hi = np.empty(2 * total, np.int64), np.empty(2 * total, np.int64)
    _window_bounds(d, np.array(origins), np.array(n_cs, np.int64), 1.0, 0.5, j, u, lo, hi)
    _grids, j_ref, u_ref = _window_ends(d, start, end, 2.0, 0.5, origins)
    sec = dataclasses.make_dataclass("S", ["eval_start_m", "eval_end_m"])(start, end)
    _sizes, lo_ref, hi_ref = en_section._sample_bounds(d, sec, first)
    assert np.array_equal(j, j_ref) and u.tobytes() == u_ref.tobytes()
    assert np.array_equal(lo, lo_ref) and np.array_equal(hi, hi_ref)


def _through_numpy_path(monkeypatch):
    """Route every section through the numpy sliding path."""
    def numpy_path(st, keys, lp_label):
        en_section._sliding_values(st, st.derived, st.d[st.wide], keys, lp_label)

    monkeypatch.setattr(en_section, "_sliding_values_compiled", numpy_path)


def _sparse(ss: SignalSet, info, factor: float):
    """The same section driven ``factor`` times faster: sample windows of 2 m may hold no
    sample (NaN under those readings)."""
    return (dataclasses.replace(ss, distance_m=np.asarray(ss.distance_m) * factor),
            dataclasses.replace(info, eval_start_m=info.eval_start_m * factor,
                                eval_end_m=info.eval_end_m * factor))


def _lattice(ss: SignalSet, info, offset: float):
    """The section on a distance axis of 1/16 m steps (exact in binary): with ``offset`` 0
    samples lie exactly on window ends (closed and half-open windows differ), else none."""
    n = len(ss)
    d = np.arange(n) / 16.0
    start, end = float(np.floor(d[n // 4])) + offset, float(np.floor(d[3 * n // 4]))
    return (dataclasses.replace(ss, distance_m=d),
            dataclasses.replace(info, eval_start_m=start, eval_end_m=end))


@pytest.mark.parametrize("alternatives", [True, False])
def test_compiled_sliding_path_equals_the_numpy_path(monkeypatch, alternatives):
    sets, infos = en_frozen.campaign_inputs()
    sets, infos = list(sets[:4]), list(infos[:4])
    for factor in (40.0, 150.0):
        ss, info = _sparse(sets[0], infos[0], factor)
        sets.append(ss)
        infos.append(info)
    for offset in (0.0, 0.03):
        ss, info = _lattice(sets[1], infos[1], offset)
        sets.append(ss)
        infos.append(info)
    got = evaluate_batch(sets, infos, alternatives=alternatives)
    assert any(np.isnan(v) for sv in got for vals in sv.alternatives.values()
               for v in vals.values()) == alternatives  # empty windows were met
    with monkeypatch.context() as m:
        _through_numpy_path(m)
        want = evaluate_batch(sets, infos, alternatives=alternatives)
    for a, b in zip(got, want, strict=True):
        assert repr(a.to_dict()) == repr(b.to_dict())
    if alternatives:  # on the lattice the closed and half-open windows differ
        lat = got[-2].alternatives
        closed = [r for r in lat if "samples_closed" in r]
        half = [r for r in lat if "samples_half_open" in r]
        assert [lat[r] for r in closed] != [lat[r] for r in half]
