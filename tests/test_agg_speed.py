"""The main process of a many-configuration validation: the binary cached form of a section's
values (pack_values/unpack_values) and the bootstrap indices drawn once per run give the same
numbers as before, checked against independent computations (json, numpy)."""

from __future__ import annotations

import json
import math
import struct

import numpy as np
import pytest

from railval.core import bootstrap, en14363, validation
from railval.core.definitions import CHOSEN, READINGS
from railval.core.en14363 import SectionValues, pack_values, unpack_values
from railval.core.quantities import QUANTITY_IDS
from railval.core.types import BODY_POSITIONS, WHEEL_POSITIONS, SectionInfo, SignalSet


def _bits(x: float) -> bytes:
    return struct.pack("<d", x)


def _former_json(values: SectionValues) -> bytes:
    """The cached form before the binary one (JSON), written here independently."""
    return json.dumps({
        "values": [[q, p, float(v)] for (q, p), v in values.items()],
        "warnings": values.warnings,
        "alternatives": {rid: [[q, p, float(v) if np.isfinite(v) else None]
                               for (q, p), v in vals.items()]
                         for rid, vals in values.alternatives.items()},
        "supplementary": [[q, p, float(v)] for (q, p), v in values.supplementary.items()],
    }, allow_nan=False).encode()


def _same(a: SectionValues, b: SectionValues) -> None:
    assert list(a) == list(b)
    assert [_bits(v) for v in a.values()] == [_bits(v) for v in b.values()]
    assert a.warnings == b.warnings and a.section_id == b.section_id
    assert list(a.alternatives) == list(b.alternatives)
    for rid, vals in a.alternatives.items():
        assert list(vals) == list(b.alternatives[rid])
        for k, v in vals.items():
            w = b.alternatives[rid][k]
            assert (math.isnan(v) and math.isnan(w)) or _bits(v) == _bits(w)
    assert list(a.supplementary) == list(b.supplementary)
    assert [_bits(v) for v in a.supplementary.values()] == [
        _bits(v) for v in b.supplementary.values()]


@pytest.fixture(scope="module")
def evaluated() -> SectionValues:
    n, fs = 4000, 500.0
    t = np.arange(n) / fs
    rng = np.random.default_rng(3)
    channels = {f"{k}_{p}": rng.standard_normal(n) * 3 + (75.0 if k == "Q" else 0.0)
                for p in WHEEL_POSITIONS for k in ("Y", "Q")}
    channels |= {f"{k}_cb_{b}": 0.3 * rng.standard_normal(n)
                 for b in BODY_POSITIONS for k in ("ay", "az")}
    return en14363.evaluate_batch([SignalSet(fs, t, 25.0 * t, channels)],
                                  [SectionInfo("S7", 0.0, 0.0, 200.0, 2, 10.0, 190.0)])[0]


def test_binary_form_gives_the_values_of_the_former_json_form(evaluated):
    assert len(evaluated) > 10 and evaluated.supplementary
    back = unpack_values("S7", pack_values(evaluated))
    _same(back, en14363._unpack_json("S7", _former_json(evaluated)))
    assert not pack_values(evaluated).startswith(b"{")


def test_non_finite_alternatives_become_nan_and_former_form_is_read():
    rid = next(r.id for r in READINGS if r != CHOSEN)
    v = SectionValues("S1", {("SumY_max", "ws1"): 0.1 + 0.2, ("SumY_max", "ws2"): -3.5},
                      warnings=["run-in short", "ü"],
                      alternatives={rid: {("SumY_max", "ws1"): math.inf,
                                          ("SumY_max", "ws2"): 7.25}},
                      supplementary={("ay_bg_rms", "b1"): 1 / 3})
    back = unpack_values("S1", pack_values(v))
    assert math.isnan(back.value_under(rid, ("SumY_max", "ws1")))
    assert back.value_under(rid, ("SumY_max", "ws2")) == 7.25
    assert _bits(back[("SumY_max", "ws1")]) == _bits(0.1 + 0.2)
    _same(back, unpack_values("S1", _former_json(v)))
    assert back.warnings == ["run-in short", "ü"] and back.supplementary == v.supplementary


def test_non_finite_value_is_refused_as_before():
    v = SectionValues("S1", {("SumY_max", "ws1"): math.nan})
    with pytest.raises(ValueError):
        pack_values(v)
    with pytest.raises(ValueError):
        _former_json(v)


def test_cache_key_carries_the_cached_form(monkeypatch):
    sec = SectionInfo("S1", 0, 0, 100, 1, 10.0, 90.0)
    key = en14363.section_cache_key(sec, 200.0, 1000, "d" * 64, {"Y_w1L": "a"}, 4)
    monkeypatch.setattr(en14363, "CACHE_FORM", "json/1")
    assert en14363.section_cache_key(sec, 200.0, 1000, "d" * 64, {"Y_w1L": "a"}, 4) != key


def _reference_ci(d, ml, sl, n_boot, seed, qi, chunk=2_000_000):
    """The bootstrap as written before the indices were kept: one generator per quantity,
    resamples drawn in chunks; percentiles by numpy."""
    rng = np.random.default_rng([seed, qi])
    n = d.size
    rows = max(1, chunk // n)
    means, stds = [], []
    for start in range(0, n_boot, rows):
        idx = rng.integers(0, n, size=(min(n_boot, start + rows) - start, n))
        means += list(d[idx].mean(axis=1))
        stds += list(d[idx].std(axis=1, ddof=1))
    a = (1.0 - 0.95) / 2.0  # the 95 % interval as validation writes it (2.5000000000000022)
    m = np.percentile(np.array(means) / ml, [100 * a, 100 * (1 - a)])
    s = np.percentile(np.array(stds) / sl, [100 * a, 100 * (1 - a)])
    return (float(m[0]), float(m[1])), (float(s[0]), float(s[1]))


@pytest.mark.parametrize("chunk", [2_000_000, 500])
def test_kept_indices_equal_a_fresh_generator(chunk):
    rng = np.random.default_rng(11)
    # n changes between calls: indices kept for one n must not serve another
    for n, seed, qi in [(40, 0, 1), (41, 0, 1), (40, 0, 1), (40, 5, 1), (40, 0, 2), (40, 0, 1)]:
        d = rng.standard_normal(n)
        got = validation.bootstrap_norm_ci(d, 1.5, 2.5, n_boot=200, seed_key=(seed, qi),
                                           chunk=chunk)
        assert got == _reference_ci(d, 1.5, 2.5, 200, seed, qi, chunk)
        assert got == validation.bootstrap_norm_ci(
            d, 1.5, 2.5, n_boot=200, rng=np.random.default_rng([seed, qi]), chunk=chunk)


def _config_values(rng, sections, gain):
    out = {}
    for s in sections:
        out[s.id] = {(q, p): float(gain * (1 + rng.standard_normal()))
                     for q in QUANTITY_IDS for p in ("ws1", "ws2", "ws3")}
    return out


def test_many_configurations_equal_the_fresh_generator_path(monkeypatch):
    rng = np.random.default_rng(5)
    sections = [SectionInfo(f"S{i:02d}", 0, 0, 100, 1 + i % 4, 10.0, 90.0) for i in range(13)]
    measured = _config_values(rng, sections, 1.0)
    configs = [_config_values(rng, sections, g) for g in (0.9, 1.0, 1.2)]
    veh = {"kind": "passenger", "secondary_suspension": True, "Q0_kN": 80.0}
    kept = [validation.validate(measured, c, sections, veh, n_boot=300, seed=4).to_dict()
            for c in configs]
    monkeypatch.setattr(bootstrap, "_CACHED_DRAW", 0)  # every resample from a fresh generator
    fresh = [validation.validate(measured, c, sections, veh, n_boot=300, seed=4).to_dict()
             for c in configs]
    assert kept == fresh
    q0 = kept[0]["quantities"][0]
    assert q0["n"] == 39 and all(v is not None for v in q0["mean_norm_ci"])


def _reference_alternative(m, s, ml, sl):
    """One reading at a time, written independently: D_v (eq. 4), mean, std (n − 1)."""
    d = np.where(m == 0.0, s, (s - m) * np.sign(m))
    if not np.all(np.isfinite(d)):
        return None, None, None
    mean = float(np.sum(d) / d.size) if d.size else None
    std = float(np.sqrt(np.sum((d - d.mean()) ** 2) / (d.size - 1))) if d.size >= 2 else None
    return mean, std, bool(d.size >= 2 and abs(mean) <= ml and std <= sl)


@pytest.mark.parametrize("n", [0, 1, 2, 37, 300])
def test_alternatives_of_all_readings_at_once_equal_one_at_a_time(n):
    from railval.core.definitions import alternatives_for
    from railval.core.pairing import QuantityPairs
    from railval.core.quantities import QUANTITIES

    qid = next(q for q in QUANTITY_IDS if len(alternatives_for(QUANTITIES[q])) > 2)
    readings = alternatives_for(QUANTITIES[qid])
    rng = np.random.default_rng(n)
    total = n + 5  # the quantity's pairs are a subset of the gathered table
    index = np.sort(rng.choice(total, size=n, replace=False))
    m0, s0 = rng.standard_normal(total) * 10, rng.standard_normal(total) * 10
    m_under, s_under = {}, {}
    for k, r in enumerate(readings):
        m_under[r.id] = np.where(rng.random(total) < 0.3, m0 * 1.01, m0)
        s_under[r.id] = s0 + (k % 3) * 0.5
    if n:
        s_under[readings[1].id][index[0]] = np.nan  # this reading is undefined
    pairs = QuantityPairs(["S"] * n, [1] * n, ["p"] * n, m0[index], s0[index], index)
    res = validation.QuantityResult(qid, "kN", n, 1, 1, 0.1, 5.0, 4.0, 12.0, (0, 0), (0, 0))
    got = validation._alternatives(qid, res, pairs, m_under, s_under)
    assert [a["reading"]["id"] for a in got] == [r.id for r in readings]
    for a, r in zip(got, readings, strict=True):
        m, s = m_under[r.id][index], s_under[r.id][index]
        mean, std, passed = _reference_alternative(m, s, 4.0, 12.0)
        assert a["values_changed"] == int(np.sum((m != m0[index]) | (s != s0[index])))
        assert a["pass"] == passed
        for key, want in (("mean", mean), ("std", std)):
            if want is None:
                assert a[key] is None
            else:
                assert abs(a[key] - want) <= 1e-12 * max(1.0, abs(want))
        if std is not None:  # the same sums as numpy one reading at a time: bit for bit
            d = validation.difference(s, m)
            assert a["mean"] == float(d.mean()) and a["std"] == float(d.std(ddof=1))
